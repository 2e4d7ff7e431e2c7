"""Several noisy captures of one static frame, averaged: the checkerboard baselines' input

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.simulate.captures import averaged_captures, lit_box
    >>> E = np.full((4, 6), 0.02); E[1:3, 2:5] = 0.5          # a lit patch in a dark room
    >>> expose = lambda img: img * 1000.0                      # a noiseless stand-in
    >>> averaged_captures(E, expose, 8).dtype, float(averaged_captures(E, expose, 8)[1, 2])
    (dtype('float32'), 500.0)
    >>> lit_box(E, margin=1)
    ((0, 4), (1, 6))

The paper's fairness rule (4.1): the checkerboard methods get as many
captures of their frame as rotstar has rotating-star frames (8), averaged
(detect.baselines.average_frames), which divides the noise by sqrt(8).
expose(stack) turns irradiance (any leading shape) into recorded values with
fresh noise per call, e.g. simulate.expose with a seeded generator; the
generator's draws follow the calls, so the order below is part of the
result. With roi ((y0, y1), (x0, x1)), only that box (the screen, see
lit_box) is averaged, the rest is one capture: the same result where it
matters for less memory and time.
"""

from __future__ import annotations

import numpy as np

from rotstar_mrcal.peers.checkerboard import average_frames


def averaged_captures(irradiance: np.ndarray, expose, n: int = 8, roi=None) -> np.ndarray:
    """(H, W) float32: the mean of n exposures of irradiance (inside roi only, if given)"""
    E = np.asarray(irradiance)
    if roi is None:
        return average_frames(expose(np.repeat(E[None], n, axis=0)))
    out = expose(E).astype(np.float32)
    (y0, y1), (x0, x1) = roi
    out[y0:y1, x0:x1] = average_frames(expose(np.repeat(E[None, y0:y1, x0:x1], n, axis=0)))
    return out


def lit_box(irradiance: np.ndarray, room: float = 0.02, margin: int = 8):
    """((y0, y1), (x0, x1)): the pixels brighter or darker than the room level, grown by margin"""
    img = np.asarray(irradiance)
    ys, xs = np.nonzero(np.abs(img - room) > 1e-4)
    H, W = img.shape
    if len(ys) == 0:
        return (0, H), (0, W)
    return ((int(max(ys.min() - margin, 0)), int(min(ys.max() + margin + 1, H))),
            (int(max(xs.min() - margin, 0)), int(min(xs.max() + margin + 1, W))))

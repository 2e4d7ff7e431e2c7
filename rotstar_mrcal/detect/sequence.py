"""Is this the rotating-star sequence, in order? The border bands' colour, frame by frame

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.detect.sequence import check_band_parity
    >>> band = np.zeros((40, 40), bool); band[::10] = band[:, ::10] = True
    >>> frames = np.stack([np.where(band, 1.0 - k % 2, 0.5) for k in range(8)])
    >>> check_band_parity(frames)
    ''
    >>> check_band_parity(frames[[0, 2, 1, 3, 4, 5, 6, 7]])
    'frames out of order: frame 1 shows the border bands white, as an even frame does (2 of 8 frames; record the sequence in the order of pattern.json)'

The border band is white in even frames and black in odd ones, and covers a
good part of the board, so every frame, less the mean of all frames,
correlates positively with frame 0 when it is even and negatively when it is
odd. A frame whose sign is wrong was recorded out of order (or repeated):
named here, before the response map, which such frames would break in ways
that point to the wrong cause.
"""

from __future__ import annotations

import numpy as np

MIN_CORRELATION = 0.2  # |correlation| below which a frame's band colour is not decided


def band_signs(frames: np.ndarray, step: int = 2) -> np.ndarray:
    """(nframes,) correlation of each frame, less the mean frame, with frame 0 (frame 0 itself: 1)"""
    f = np.asarray(frames[:, ::step, ::step], np.float64)
    d = (f - f.mean(axis=0)).reshape(len(f), -1)
    n = np.linalg.norm(d, axis=1)
    n[n == 0] = np.inf
    return d @ d[0] / (n * n[0])


def check_band_parity(frames: np.ndarray) -> str:
    """'' or which frames show the border bands in the wrong colour for their place"""
    if len(frames) < 3:
        return ""
    c = band_signs(frames)
    k = np.arange(len(frames))
    # independent noise alone correlates by -1/(n-1) in every frame; the bands alternate
    if abs(np.mean(np.where(k % 2 == 0, 1.0, -1.0)[1:] * c[1:])) < MIN_CORRELATION / 2:
        return ("no border bands that flip between frames: the frames do not show the rotating-star "
                "sequence, or noise hides it")
    want = np.where(k % 2 == 0, 1.0, -1.0)
    wrong = np.flatnonzero((np.sign(c) != want) & (np.abs(c) > MIN_CORRELATION))
    if not len(wrong):
        return ""
    f = int(wrong[0])
    colour = "white, as an even frame does" if c[f] > 0 else "black, as an odd frame does"
    return (f"frames out of order: frame {f} shows the border bands {colour} ({len(wrong)} of {len(frames)} "
            "frames; record the sequence in the order of pattern.json)")

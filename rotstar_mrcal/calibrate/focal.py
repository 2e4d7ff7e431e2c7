"""A focal-length seed for mrcal from the detected boards

SYNOPSIS

    >>> import numpy as np, mrcal
    >>> from rotstar_mrcal.calibrate.focal import estimate_focal
    >>> obj = np.stack(np.meshgrid(np.arange(10.), np.arange(7.)), -1) * 0.02
    >>> boards = []
    >>> for r in ([0.3, 0.1, 0.05], [-0.2, 0.35, 0.0], [0.1, -0.3, 0.4]):
    ...     p = mrcal.transform_point_rt(np.array(r + [-0.1, -0.06, 0.5]),
    ...                                  np.concatenate((obj, np.zeros((7, 10, 1))), -1))
    ...     boards.append(mrcal.project(p, "LENSMODEL_PINHOLE", np.array([650., 650., 640., 400.])))
    >>> abs(estimate_focal(boards, obj, (1280, 800)) - 650) < 5   # a seed, within 1%
    True

Zhang's constraints on the image of the absolute conic, with square pixels
and the principal point at the image centre, leave one unknown, 1/f^2; each
board's homography gives two linear equations in it. The median over boards
is returned, or a 90-degree field of view when no board constrains it.
focal_estimates returns the per-board values, to judge whether the boards
agree (one or two boards can be far off: 3275 px for a 640 px camera).
focal_seed is the seed of a corner set, checked: the boards must agree.
"""

from __future__ import annotations

import cv2
import numpy as np

from rotstar_mrcal.calibrate.command import InputError

FOCAL_MIN_BOARDS = 3
FOCAL_MAX_SPREAD = 0.15
"""The focal seed needs this many boards whose estimates agree to this (median absolute deviation / median)"""


def estimate_focal(boards, board_xy: np.ndarray, imagersize) -> float:
    """Focal length (pixels) from (ny, nx, 2) image corners of several boards

    board_xy: (ny, nx, 2) board coordinates of the corners (metres).
    """
    W = imagersize[0]
    fallback = W / 2  # 90-degree horizontal field of view
    est = focal_estimates(boards, board_xy, imagersize)
    f = float(np.median(est)) if len(est) else fallback
    return f if 0.1 * W < f < 20 * W else fallback


def focal_estimates(boards, board_xy: np.ndarray, imagersize) -> np.ndarray:
    """One focal length (pixels) per board that constrains it (see estimate_focal)"""
    W, H = imagersize
    c = np.array([(W - 1) / 2, (H - 1) / 2])
    est = []
    for q in boards:
        if q is None:
            continue
        q = np.asarray(q, float).reshape(-1, 2)
        ok = np.isfinite(q).all(axis=1)
        if ok.sum() < 8:
            continue
        Hm, _ = cv2.findHomography(board_xy.reshape(-1, 2)[ok], q[ok] - c)
        if Hm is None:
            continue
        h1, h2 = Hm[:, 0], Hm[:, 1]
        # omega = diag(1/f^2, 1/f^2, 1): a * s + b = 0 with s = 1/f^2
        a1, b1 = h1[0] * h2[0] + h1[1] * h2[1], h1[2] * h2[2]
        a2, b2 = (h1[0] ** 2 + h1[1] ** 2) - (h2[0] ** 2 + h2[1] ** 2), h1[2] ** 2 - h2[2] ** 2
        A = np.array([a1, a2])
        s = -np.dot(A, [b1, b2]) / max(np.dot(A, A), 1e-300)
        if s > 0:
            est.append(1 / np.sqrt(s))
    return np.array(est, float)


def focal_seed(cs, check: bool = True) -> float:
    """The focal seed (pixels) of a corner set: the median of its boards' estimates

    With check, an InputError unless at least FOCAL_MIN_BOARDS boards give an
    estimate and they agree to FOCAL_MAX_SPREAD (median absolute deviation
    over the median): a seed the boards do not support makes mrcal start
    (and a splined model size its field of view) from a wrong focal length.
    """
    est = focal_estimates(list(cs.corners), cs.layout.board_points()[..., :2], cs.imagersize)
    W = cs.imagersize[0]
    if not len(est):
        if check:
            raise InputError("no board constrains the focal length (give --focal)")
        return W / 2
    f = float(np.median(est))
    spread = float(np.median(np.abs(est - f)) / f)
    if check and (len(est) < FOCAL_MIN_BOARDS or spread > FOCAL_MAX_SPREAD or not 0.1 * W < f < 20 * W):
        raise InputError(f"the boards do not support a focal seed ({len(est)} estimates, median {f:.0f} px, "
                         f"spread {100 * spread:.0f}%; need >= {FOCAL_MIN_BOARDS} agreeing within "
                         f"{100 * FOCAL_MAX_SPREAD:.0f}%): give --focal, or record more poses")
    return f

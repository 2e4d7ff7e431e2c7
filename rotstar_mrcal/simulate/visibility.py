"""Which corners of a pose a detector can report: the true refinement windows and the in-view mask

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.pattern.layout import make_layout
    >>> from rotstar_mrcal.simulate.camera import preset_model
    >>> from rotstar_mrcal.simulate.visibility import in_view, true_windows
    >>> layout = make_layout(screen=(800, 600), pitch=100, band=24)       # 6 x 4 corners
    >>> model = preset_model("pinhole-small")                            # 640 x 400, f = 320
    >>> rt = np.array((0, 0, 0, -0.0385, -0.0289, 0.12))                 # head-on, 12 cm away
    >>> true_windows(model, layout, rt)[0, :3].round(2)   # 0.65 x the element's 9.75 px half-side
    array([6.34, 6.34, 6.34])
    >>> in_view(model, layout, rt).sum()                                 # the whole board
    np.int64(24)
    >>> in_view(model, layout, rt + (0, 0, 0, 0.13125, 0, 0)).sum(axis=0)   # 350 px to the right
    array([4, 4, 4, 0, 0, 0])

A corner is *in view* when the window the detector would refine it in lies
inside the image, so that counting the in-view corners neither rewards nor
punishes a detector for the corners it must not report. The window is the
rotating-star detector's (detect/pipeline.py): a half-size of
WINDOW_FRACTION (0.65) times the half-side of the largest axis-aligned
square about the corner inside its element, between MIN_WINDOW (2 px) and
the cap `window` (10 px, the detector's default). Here the element is the
true one: its square, of half-side layout.half_element display pixels about
the corner, projected through the true camera (POINTS_PER_SIDE points per
side, so the lens's curvature of its edges counts). The window [q - w, q + w]
must lie in [0, W - 1] x [0, H - 1] (every sample of the symmetric
refinement interpolable).

A corner is never in view when the camera cannot see it: behind the camera,
off the part of the lens's field that maps into the image (the round trip
mrcal.project -> mrcal.unproject does not give the same ray back: beyond the
fold of a distortion polynomial, a point far outside the field can project
into the image), or on a board seen from behind.
"""

from __future__ import annotations

import math

import mrcal
import numpy as np

from rotstar_mrcal.detect.elements import MIN_WINDOW, WINDOW_FRACTION
from rotstar_mrcal.pattern.layout import Layout

POINTS_PER_SIDE = 8  # points per side of an element's square, projected to find its inscribed square
DEFAULT_WINDOW = 10.0  # the detector's default cap, px (detect_pose(window=))


def element_square(layout: Layout, n: int = POINTS_PER_SIDE) -> np.ndarray:
    """(4 n, 3) board-frame offsets (metres) of the outline of an element's square about its corner"""
    h = layout.half_element * layout.pixel_pitch_m
    t = (np.arange(n) / n * 2 - 1) * h
    side = [np.stack((t, np.full(n, -h)), -1), np.stack((np.full(n, h), t), -1),
            np.stack((-t, np.full(n, h)), -1), np.stack((np.full(n, -h), -t), -1)]
    out = np.concatenate(side)
    return np.concatenate((out, np.zeros((len(out), 1))), axis=-1)


def seen(model: mrcal.cameramodel, p_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(projections (..., 2), visible (...)): camera-frame points the camera really sees where projected

    visible: in front of the camera and the projection unprojects to the
    same ray (to 1e-6 rad); the projection is NaN where not visible.
    """
    p = np.asarray(p_cam, float)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        q = mrcal.project(p, *model.intrinsics())
        v = mrcal.unproject(q, *model.intrinsics(), normalize=True)
        pn = p / np.linalg.norm(p, axis=-1, keepdims=True)
        ok = (p[..., 2] > 0) & np.isfinite(q).all(axis=-1) & (np.sum(v * pn, axis=-1) > math.cos(1e-6))
    return np.where(ok[..., None], q, np.nan), ok


def true_windows(model: mrcal.cameramodel, layout: Layout, rt_cam_board, window: float = DEFAULT_WINDOW) -> np.ndarray:
    """(ny, nx) the detector's refinement half-window about each true corner, px; NaN where not seen

    NaN also where any point of the corner's element is not seen (the
    element's inscribed square is then unknown).
    """
    rt = np.asarray(rt_cam_board, float)
    pts = layout.board_points()[..., None, :] + element_square(layout)  # (ny, nx, 4n, 3)
    pts = np.concatenate((layout.board_points()[..., None, :], pts), axis=-2)
    q, ok = seen(model, mrcal.transform_point_rt(rt, pts))
    d = np.abs(q[..., 1:, :] - q[..., :1, :])
    inscribed = np.min(np.max(d, axis=-1), axis=-1)  # detect.boundaries.inscribed_square, about the corner
    w = np.clip(WINDOW_FRACTION * inscribed, MIN_WINDOW, window)
    front = _front(rt)
    return np.where(ok.all(axis=-1) & front, w, np.nan)


def _front(rt: np.ndarray) -> bool:
    """The camera is on the screen's front side (board z < 0)"""
    R = mrcal.R_from_r(rt[:3])
    return bool((R.T @ rt[3:])[2] > 0)


def in_view(model: mrcal.cameramodel, layout: Layout, rt_cam_board, window: float = DEFAULT_WINDOW) -> np.ndarray:
    """(ny, nx) bool: the corner's refinement window lies inside the image (see the module doc)"""
    rt = np.asarray(rt_cam_board, float)
    w = true_windows(model, layout, rt, window)
    q, _ = seen(model, mrcal.transform_point_rt(rt, layout.board_points()))
    W, H = (float(v) for v in model.imagersize())
    with np.errstate(invalid="ignore"):
        return ((q[..., 0] - w >= 0) & (q[..., 1] - w >= 0) & (q[..., 0] + w <= W - 1)
                & (q[..., 1] + w <= H - 1))


def half_spacing(truth: np.ndarray) -> np.ndarray:
    """(ny, nx) half the distance from each true corner to its nearest grid neighbour (4-neighbourhood), px

    The limit of a right label: a reported corner farther than this from the
    true corner of its label is nearer another corner's place. NaN where no
    neighbour is known.

    >>> t = np.stack(np.meshgrid(np.arange(3.0) * 20, np.arange(2.0) * 10), axis=-1)   # 20 px across, 10 down
    >>> half_spacing(t)
    array([[5., 5., 5.],
           [5., 5., 5.]])
    """
    t = np.asarray(truth, float)
    d = np.full(t.shape[:2] + (4,), np.nan)
    dx = np.linalg.norm(np.diff(t, axis=1), axis=-1)  # (ny, nx-1)
    dy = np.linalg.norm(np.diff(t, axis=0), axis=-1)  # (ny-1, nx)
    d[:, 1:, 0], d[:, :-1, 1], d[1:, :, 2], d[:-1, :, 3] = dx, dx, dy, dy
    have = np.isfinite(d).any(axis=-1)
    return np.where(have, np.nanmin(np.where(np.isfinite(d), d, np.inf), axis=-1), np.nan) / 2

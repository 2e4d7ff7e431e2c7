"""The corners of one pose by each detector: rotstar and the checkerboard baselines

SYNOPSIS

    from rotstar_mrcal import dataset
    from rotstar_mrcal.validate.cornersets import detect_methods, METHODS
    _, layout = dataset.read_pattern("seq")
    pose = dataset.load_pose("seq", "pose000", layout)
    found = detect_methods(pose.rotstar, layout, pose.full_scale, pose.checkerboard)
    found["rotstar"].corners          # (ny, nx, 2) mrcal order, NaN = missing; or None
    found["opencv-sb"].corners        # the same poses seen as a checkerboard

The methods (METHODS), the paper's comparison on the same poses:

    rotstar           detect_pose on the rotating-star frames (symmetric refinement)
    rotstar-weighted  the same corners with rotstar-detect --weights' weights
                      (1/sigma from the refinement covariance, median 1): does
                      weighting help the calibration?
    opencv-sb         cv2.findChessboardCornersSB (with CALIB_CB_ACCURACY) on the
                      checkerboard frame: a complete checkerboard detector
    cornersubpix      cv2.cornerSubPix (Forstner) on the checkerboard frame,
                      started from rotstar's corners
    saddle            the Lucchese-Mitra saddle fit on the checkerboard frame,
                      started from rotstar's corners

cornersubpix and saddle are refinements only, started (as in the paper,
4.2) from rotstar's labelled corners, each with rotstar's per-corner window
(at most the requested half-window, capped inside the element; floored to
whole pixels); they have no board where rotstar found none. opencv-sb numbers
its board its own way; it is relabelled to rotstar's numbering when rotstar
found the board (every corner within MATCH_PX), and kept as OpenCV numbered
it otherwise (any symmetry of the grid is a valid labelling for one camera).

The checkerboard frame should hold as many photons as the rotating-star
sequence: the paper averages 8 captures (baselines.average_frames), and so
does the demo. mrgingham, the fourth baseline, only finds square N x N boards
and runs as its own program on images of one (mrgingham_corners).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..detect import baselines
from ..detect.pipeline import detect_pose

METHODS = ("rotstar", "rotstar-weighted", "opencv-sb", "cornersubpix", "saddle")
MATCH_PX = 3.0

DESCRIPTIONS = {
    "rotstar": "rotating-star frames, symmetric refinement (rotstar-detect)",
    "rotstar-weighted": "the same, with per-corner weights 1/sigma (rotstar-detect --weights)",
    "opencv-sb": "checkerboard frame, cv2.findChessboardCornersSB + CALIB_CB_ACCURACY",
    "cornersubpix": "checkerboard frame, cv2.cornerSubPix from rotstar's corners",
    "saddle": "checkerboard frame, Lucchese-Mitra saddle fit from rotstar's corners",
    "mrgingham": "square checkerboard, mrgingham",
}


@dataclasses.dataclass
class Found:
    """One method's corners of one pose"""

    corners: np.ndarray | None  # (ny, nx, 2) or None: no board
    weights: np.ndarray | None = None  # (ny, nx) or None
    why: str = ""  # why there is no board


def detect_methods(frames, layout, full_scale: float, checkerboard=None, methods=METHODS,
                   window: float = 10.0) -> dict[str, Found]:
    """Every requested method's corners of one pose; see the module doc

    frames: (nframes, H, W) rotating-star frames; checkerboard: (H, W) (the
    averaged captures) or None, in which case the checkerboard methods find
    nothing.
    """
    unknown = set(methods) - set(METHODS)
    if unknown:
        raise ValueError(f"unknown methods {sorted(unknown)}; known: {', '.join(METHODS)}")
    out: dict[str, Found] = {}
    r = detect_pose(np.asarray(frames, np.float32), layout, full_scale=full_scale, window=window)
    ref = r.corners if r.found else None
    if "rotstar" in methods:
        out["rotstar"] = Found(ref, None, r.error)
    if "rotstar-weighted" in methods:
        out["rotstar-weighted"] = Found(ref, r.weights() if r.found else None, r.error)
    cb = None if checkerboard is None else np.asarray(checkerboard, np.float32)
    no_cb = "no checkerboard frame"
    if "opencv-sb" in methods:
        if cb is None:
            out["opencv-sb"] = Found(None, None, no_cb)
        else:
            c = baselines.opencv_find_chessboard(cb, layout.nx, layout.ny, full_scale, "sb")
            if c is None:
                out["opencv-sb"] = Found(None, None, "findChessboardCornersSB found no board")
            else:
                m = baselines.match_to_reference(c, ref, MATCH_PX) if ref is not None else None
                out["opencv-sb"] = Found(c if m is None else m)
    for name, refine in (("cornersubpix", lambda im, p, w: baselines.opencv_subpix(im, p, win=w)),
                         ("saddle", lambda im, p, w: baselines.saddle_refine(im, p, win=w))):
        if name not in methods:
            continue
        if cb is None or ref is None:
            out[name] = Found(None, None, no_cb if cb is None else f"no start (rotstar: {r.error})")
            continue
        out[name] = Found(baselines.refine_by_window(refine, cb, ref, r.window))
    return out


def mrgingham_corners(paths, gridn: int, jobs: int = 1) -> dict:
    """{path: (gridn, gridn, 2) or None} by the mrgingham program (baselines.mrgingham_detect)"""
    return baselines.mrgingham_detect(list(paths), gridn, jobs=jobs)

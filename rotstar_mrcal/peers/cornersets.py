"""The corners of one pose by each detector: rotstar and the checkerboard baselines

SYNOPSIS

    from rotstar_mrcal import dataset
    from rotstar_mrcal.peers.cornersets import detect_methods
    _, layout = dataset.read_pattern("seq")
    pose = dataset.load_pose("seq", "pose000", layout)
    found = detect_methods(pose.rotstar, layout, pose.full_scale, pose.checkerboard)
    found["rotstar"].corners          # (ny, nx, 2) mrcal order, NaN = missing; or None
    found["opencv-sb"].corners        # the same poses seen as a checkerboard
    dataset_methods()                 # the methods a dataset allows (all, by default)

The methods (rotstar_mrcal.peers.registry.METHODS; here those that need the
rotating-star or the checkerboard frame), the paper's comparison on the same poses:

    rotstar           detect_pose on the rotating-star frames (symmetric refinement)
    rotstar-weighted  the same corners with rotstar-detect --weights' weights
                      (1/sigma from the refinement covariance, median 1): does
                      weighting help the calibration?
    opencv-sb         cv2.findChessboardCornersSB (with CALIB_CB_ACCURACY) on the
                      checkerboard frame: a complete checkerboard detector
    opencv-classic    cv2.findChessboardCorners + cornerSubPix (win 5), the same
    cornersubpix      cv2.cornerSubPix (Forstner) on the checkerboard frame,
                      started from rotstar's corners
    saddle            the Lucchese-Mitra saddle fit on the checkerboard frame,
                      started from rotstar's corners

cornersubpix and saddle are refinements only, started (as in the paper,
4.2) from rotstar's labelled corners, each with rotstar's per-corner window
(at most the requested half-window, capped inside the element; floored to
whole pixels); they have no board where rotstar found none. opencv-sb and
opencv-classic number their board their own way; it is relabelled to rotstar's numbering when rotstar
found the board (every corner within MATCH_PX), and kept as OpenCV numbered
it otherwise (any symmetry of the grid is a valid labelling for one camera).

The checkerboard frame should hold as many photons as the rotating-star
sequence: the paper averages 8 captures (baselines.average_frames), and so
does the demo. mrgingham, the fourth baseline, only finds square N x N boards
and runs as its own program on images of one (baselines.mrgingham_detect).
"""

from __future__ import annotations

import numpy as np

from rotstar_mrcal.peers import checkerboard as baselines
from rotstar_mrcal.peers.registry import Found, PoseImages, method, method_names, rotstar_detection

MATCH_PX = 3.0


def dataset_methods() -> list[str]:
    """The methods a dataset's frames allow (the rotating-star and the checkerboard frames)"""
    return method_names(needs=("rotstar", "checkerboard"))


def detect_methods(frames, layout, full_scale: float, checkerboard=None, methods=None,
                   window: float = 10.0, identity=None, phase=None, star=None) -> dict[str, Found]:
    """Every requested method's corners of one pose (rotstar_mrcal.peers.registry); see the module doc

    frames: (nframes, H, W) rotating-star frames; checkerboard: (H, W) (the
    averaged captures) or None, in which case the checkerboard methods find
    nothing; identity: (nidentity, H, W) identity frames or None; phase:
    (2, 4, H, W) the phase shifts along x then y, and star: (H, W) the star
    frame (rotstar-pattern --paper-sequence), each or None: given, the
    methods that need them may be asked for. rotstar is detected once and
    starts the methods that start from it.
    """
    allowed = method_names(needs=("rotstar", "checkerboard") + ("phase",) * (phase is not None)
                           + ("star",) * (star is not None))
    ms = [method(m) for m in (dataset_methods() if methods is None else methods)]
    bad = [m.name for m in ms if m.name not in allowed]
    if bad:
        raise ValueError(f"methods {bad} need other images; known here: {', '.join(allowed)}")
    p = PoseImages(layout, full_scale, frames=np.asarray(frames, np.float32), checkerboard=checkerboard,
                   window=window, identity=identity, phase=phase, star=star)
    r = rotstar_detection(p)
    ref = r.corners if r.found else None
    out: dict[str, Found] = {}
    for m in ms:
        f = m(p)
        if m.relabel and f.corners is not None and ref is not None:  # rotstar's numbering where it found the board
            q = baselines.match_to_reference(f.corners, ref, MATCH_PX)
            f = Found(f.corners if q is None else q, f.weights, f.why)
        out[m.name] = f
    return out

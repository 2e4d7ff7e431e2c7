"""A multi-camera dataset: the boards' labelling checked across cameras

SYNOPSIS

    from rotstar_mrcal.detect.rig import check_labelling
    det.disagree = check_labelling({k: found_k, ...})   # what detect.run.detect_dataset does with >1 cameras

Each camera is detected alike, its pose folders 'poseNNN/camera-K'
(run.detect_dataset, with its display and motion check per camera: the
screen's offsets show in each camera's own pixels). Every
camera labels a board the same way by construction: the identity frames name
each element and the orientation marker fixes which corner is (0, 0), in
every camera alike. labelling_agrees checks it anyway, per pose and pair of
cameras, without the cameras' geometry (unknown before calibration): the
affine fit of each camera's corners to their board indices, q ~ A (i, j) + b,
must have the same handedness (sign of det A: a board seen from the front
is never mirrored in one camera only) and its board-x direction A[:, 0]
must point the same way in both images within MAX_TURN_DEG (the cameras of a
D435 look the same way to within a degree; perspective between cameras 50 mm
apart turns the board's image by a few degrees at most). This catches a
board turned by 180 degrees or mirrored in one camera, the errors a wrong
orientation reading would make; it cannot catch a board shifted by whole
elements in one camera (which the identity frames rule out), and it assumes
cameras that look roughly the same way (rigs of cameras turned against each
other by more than MAX_TURN_DEG about their axes are flagged). A pose whose
boards disagree is dropped from every camera (a missing board only weakens
a calibration; a mislabelled one corrupts it). After calibration, a
mislabelled board shows as a board whose corners mrcal mostly rejects
(calibrate/rig.py reports it per camera).
"""

from __future__ import annotations

import math

import numpy as np


MAX_TURN_DEG = 30.0
"""Largest angle between the board-x directions of one board in two cameras' images"""


def board_axes(corners: np.ndarray) -> np.ndarray | None:
    """The affine fit q ~ A (i, j) + b of a board's (ny, nx, 2) corners: A (2, 2), or None (< 3 corners)

    SYNOPSIS

        >>> j, i = np.mgrid[0:3, 0:4].astype(float)
        >>> q = np.stack((10 + 5 * i, 20 + 5 * j), -1)           # upright, 5 px per element
        >>> (board_axes(q).round(6) + 0).tolist()
        [[5.0, 0.0], [0.0, 5.0]]
    """
    ny, nx = corners.shape[:2]
    j, i = np.mgrid[0:ny, 0:nx]
    ok = np.isfinite(corners).all(axis=-1)
    if ok.sum() < 3:
        return None
    X = np.column_stack((i[ok], j[ok], np.ones(ok.sum())))
    sol, _, rank, _ = np.linalg.lstsq(X, corners[ok], rcond=None)
    return sol[:2].T if rank == 3 else None


def labelling_agrees(a: np.ndarray, b: np.ndarray, max_turn_deg: float = MAX_TURN_DEG) -> str:
    """'' when boards a and b ((ny, nx, 2), two cameras, one pose) are labelled alike, else why not (module doc)

    SYNOPSIS

        >>> j, i = np.mgrid[0:3, 0:4].astype(float)
        >>> a = np.stack((10 + 5 * i, 20 + 5 * j), -1)
        >>> labelling_agrees(a, a + (40, 1))                       # the same board, seen 40 px further right
        ''
        >>> labelling_agrees(a, a[::-1, ::-1])                     # turned by 180 degrees in one camera
        'the board-x direction differs by 180 degrees between the cameras (limit 30)'
        >>> labelling_agrees(a, a[:, ::-1])                        # mirrored
        'the board is mirrored in one camera only'
    """
    A, B = board_axes(a), board_axes(b)
    if A is None or B is None:
        return ""
    if np.sign(np.linalg.det(A)) != np.sign(np.linalg.det(B)):
        return "the board is mirrored in one camera only"
    ca, cb = A[:, 0], B[:, 0]
    turn = math.degrees(math.acos(np.clip(ca @ cb / (np.linalg.norm(ca) * np.linalg.norm(cb)), -1, 1)))
    if turn > max_turn_deg:
        return (f"the board-x direction differs by {turn:.0f} degrees between the cameras "
                f"(limit {max_turn_deg:g})")
    return ""


def check_labelling(found: dict, max_turn_deg: float = MAX_TURN_DEG) -> dict[str, str]:
    """{pose: why} for the poses whose boards are labelled differently in two cameras (labelling_agrees)

    found: {camera: [its PoseResults that gave a board]} (detect.run), pose
    'poseNNN/camera-K'.
    """
    by_pose: dict[str, list] = {}
    for k, rs in found.items():
        for r in rs:
            by_pose.setdefault(r.pose.split("/")[0], []).append((k, r))
    out = {}
    for pose, rs in sorted(by_pose.items()):
        (k0, r0), rest = rs[0], rs[1:]
        for k, r in rest:
            why = labelling_agrees(r0.corners.corners, r.corners.corners, max_turn_deg)
            if why:
                out[pose] = f"labelled differently in camera-{k0} and camera-{k}: {why}"
                break
    return out

"""On simulated data: how far a calibrated model is from the true one

SYNOPSIS

    import mrcal
    from rotstar_mrcal.simulate import load_truth
    from rotstar_mrcal.evaluate.truth import truth_error, truth_poses_of
    truth = load_truth("seq")
    model = mrcal.cameramodel("cal/camera-0.cameramodel")
    e = truth_error(model, truth.model, truth_poses_of(model, truth.rt_cam_board))
    e.median, e.p95     # px, over the imager, at infinity

The two camera frames are related by a rotation (and a translation) that the
calibration cannot know: mrcal fixes it through the board poses, and so does
this comparison. The solved board poses of every frame are put next to the
true ones and a Procrustes fit (mrcal.align_procrustes_points_Rt01 over all
board corners) gives the transform from the calibrated camera frame to the
true one; the gauge of mrcal's own uncertainty. Then every pixel q of a grid
over the imager is unprojected with the calibrated model, moved into the true
camera frame and projected with the true model; the error is the distance
from q. At infinity only the rotation matters.

A detector may number a board from another corner (any symmetry of the grid
is a valid labelling for a one-camera solve); each frame is matched to its
true pose under the labelling that brings the points closest.

Without the true poses the comparison falls back to mrcal.projection_diff
with a rotation fitted over the central region (focus_radius), which hides
part of the error.

The true model here is the true geometry of the rays (the chief ray, or the
PSF's centroid when the simulator makes it so); a detector whose corners are
consistently offset from it (e.g. by an asymmetric PSF) calibrates a model
that differs from it even if its held-out error is small.
"""

from __future__ import annotations

import dataclasses
import os

import mrcal
import numpy as np

from rotstar_mrcal.peers.checkerboard import relabelled_boards
from rotstar_mrcal.evaluate.uncertainty import imager_grid


@dataclasses.dataclass
class TruthError:
    q: np.ndarray  # (Ny, Nx, 2) pixels
    error: np.ndarray  # (Ny, Nx) px
    rotation_deg: float  # calibrated camera frame -> true camera frame
    method: str  # 'procrustes' or 'projection_diff'

    @property
    def median(self) -> float:
        return float(np.nanmedian(self.error))

    @property
    def p95(self) -> float:
        return float(np.nanpercentile(self.error, 95))

    @property
    def max(self) -> float:
        return float(np.nanmax(self.error))

    def summary(self) -> dict:
        return {"median_px": self.median, "p95_px": self.p95, "max_px": self.max,
                "rotation_deg": self.rotation_deg, "method": self.method}


def truth_poses_of(model: mrcal.cameramodel, rt_cam_board: dict) -> np.ndarray:
    """(Nframes, 6) true pose of each frame of a calibration, NaN if unknown

    Frames are matched by their image path: seq/<pose>/<file> -> <pose>.
    """
    oi = model.optimization_inputs()
    paths = oi.get("imagepaths")
    nframes = len(oi["rt_ref_frame"])
    out = np.full((nframes, 6), np.nan)
    if paths is None:
        return out
    iframe = oi["indices_frame_camintrinsics_camextrinsics"][:, 0]
    for i, p in zip(iframe, paths):
        name = os.path.basename(os.path.dirname(str(p)))
        rt = rt_cam_board.get(name)
        if rt is not None and np.ndim(rt) == 1:
            out[i] = rt
    return out


def _align(model: mrcal.cameramodel, rt_true: np.ndarray) -> np.ndarray | None:
    """Rt (4, 3) from the calibrated camera frame to the true one, or None"""
    oi = model.optimization_inputs()
    obs = oi["observations_board"]
    ny, nx = obs.shape[1:3]
    spacing = oi["calibration_object_spacing"]
    solved = mrcal.transform_point_rt(
        oi["rt_ref_frame"][:, None, None, :],
        mrcal.ref_calibration_object(nx, ny, spacing, calobject_warp=oi.get("calobject_warp")))
    flat = mrcal.ref_calibration_object(nx, ny, spacing)
    p0, p1 = [], []
    for k in range(len(solved)):
        if not np.all(np.isfinite(rt_true[k])):
            continue
        true = mrcal.transform_point_rt(rt_true[k], flat)
        best = min((g for _, g in relabelled_boards(true) if g.shape == solved[k].shape),
                   key=lambda g: np.mean(np.linalg.norm(g - solved[k], axis=-1)))
        p0.append(best.reshape(-1, 3))
        p1.append(solved[k].reshape(-1, 3))
    if len(p0) < 2:
        return None
    return mrcal.align_procrustes_points_Rt01(np.concatenate(p0), np.concatenate(p1))


def truth_error(model: mrcal.cameramodel, truth_model: mrcal.cameramodel, rt_true=None,
                gridn_width: int = 40, distance: float | None = None, q=None) -> TruthError:
    """Projection error of a calibrated model against the true model over the imager

    rt_true: (Nframes, 6) true rt_cam_board of each of the calibration's
    frames (truth_poses_of), NaN rows for unknown ones; None: fall back to
    mrcal.projection_diff. distance None: at infinity. q: the pixels (..., 2)
    to compare at instead of a grid gridn_width wide (needs rt_true).
    """
    Rt = None if rt_true is None else _align(model, np.asarray(rt_true, float))
    if Rt is None and q is not None:
        raise ValueError("the error at given pixels needs the true poses (rt_true) of at least two frames")
    if Rt is None:
        W, H = model.imagersize()
        difflen, _, q, Rt10 = mrcal.projection_diff((model, truth_model), gridn_width=gridn_width,
                                                    distance=distance, use_uncertainties=False,
                                                    focus_radius=min(W, H) / 2)
        angle = float(np.degrees(np.linalg.norm(mrcal.r_from_R(Rt10[:3]))))
        return TruthError(q, difflen, angle, "projection_diff")
    q = imager_grid(model.imagersize(), gridn_width) if q is None else np.asarray(q, float)
    v = mrcal.unproject(q, *model.intrinsics(), normalize=True)
    if distance is None:
        p = mrcal.rotate_point_R(Rt[:3], v)
    else:
        p = mrcal.transform_point_Rt(Rt, v * distance)
    err = np.linalg.norm(mrcal.project(p, *truth_model.intrinsics()) - q, axis=-1)
    angle = float(np.degrees(np.linalg.norm(mrcal.r_from_R(Rt[:3]))))
    return TruthError(q, err, angle, "procrustes")

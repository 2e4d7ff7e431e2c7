"""A stereo calibration against the truth and against another calibration of the same pair

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.simulate.camera import preset_model
    >>> from rotstar_mrcal.evaluate.stereo import shifted_pair, extrinsics_error
    >>> true = shifted_pair(preset_model("d435"), 0.050)
    >>> cal = shifted_pair(preset_model("d435"), 0.0502, r=(0, np.radians(0.01), 0))
    >>> e = extrinsics_error(cal, true)
    >>> round(e.baseline_mm, 2), round(e.baseline_error_mm, 3), round(e.rotation_error_deg, 4)
    (50.2, 0.2, 0.01)
    >>> np.round(e.rotation_error_xyz_deg, 4).tolist()       # about camera 0's x, y (vertical), z axes
    [0.0, 0.01, 0.0]

A pair is (model 0, model 1), each with its extrinsics, camera 0 at the
origin: mrcal's reference frame in a joint calibration (mrcal-calibrate-cameras
with two camera globs) and in the truth of a simulated rig. The extrinsics
compared are those of camera 1 relative to camera 0 (rt_10 = rt_cam1_cam0):

    baseline       |t| of camera 1's centre in camera 0's frame, mm; its error
    direction      the angle between the two baselines' directions, degrees
    rotation       the angle of R_10(calibrated) R_10(true)^T, degrees, and its
                   components about camera 0's x, y, z axes: a turn about y
                   (vertical, for a horizontal pair) shifts the disparity
                   and biases depth as Z^2 (depth.py); one about x or z
                   breaks the rectified rows

Both sides' camera 0 frames are their own camera 0's, each defined through
its own intrinsics; a calibration cannot pin that frame's rotation better
than its intrinsics, and that part of the error is in the per-camera
comparison (camera_truth_error), not here.

Per camera, camera_truth_error is truth.py's measure for one camera of a
joint solve: the solved boards, in that camera's calibrated frame, are
aligned (Procrustes) with the true boards in the true camera's frame, and
every pixel of a grid over the imager is moved through that alignment into
the true camera and projected with the true lens.

pair_crossval is mrcal's cross-validation of two calibrations of the pair
(pose groups A and B): per camera crossval.cross_validate (projection diff
against the two uncertainties), the extrinsics of one against the other
(mrcal gives no extrinsics uncertainty: the plain difference), and
mrcal.stereo_pair_diff (camera 0's pixels reprojected into camera 1 through
each calibration, intrinsics and extrinsics together) at the held-out depths.
"""

from __future__ import annotations

import dataclasses
import os
import re

import mrcal
import numpy as np

from rotstar_mrcal.evaluate.crossval import cross_validate
from rotstar_mrcal.evaluate.truth import TruthError
from rotstar_mrcal.evaluate.uncertainty import imager_grid
from rotstar_mrcal.evaluate import depth as dp
from rotstar_mrcal.evaluate.truth import truth_error
from rotstar_mrcal.peers.checkerboard import relabelled_boards


def shifted_pair(model, baseline: float, r=(0.0, 0.0, 0.0), model1=None) -> tuple:
    """(model 0 at the origin, model 1 at +baseline metres along x, turned by rt r), copies of the lenses

    SYNOPSIS

        >>> from rotstar_mrcal.simulate.camera import preset_model
        >>> m0, m1 = shifted_pair(preset_model("d435"), 0.05)
        >>> m1.rt_cam_ref().tolist()        # camera 1's centre at x = +0.05 in camera 0's frame
        [0.0, 0.0, 0.0, -0.05, 0.0, 0.0]
    """
    m1src = model if model1 is None else model1
    R10 = mrcal.R_from_r(np.asarray(r, float))
    t10 = -R10 @ np.array((baseline, 0.0, 0.0))
    m0 = mrcal.cameramodel(intrinsics=model.intrinsics(), imagersize=model.imagersize(), rt_cam_ref=np.zeros(6))
    m1 = mrcal.cameramodel(intrinsics=m1src.intrinsics(), imagersize=m1src.imagersize(),
                           rt_cam_ref=np.concatenate((mrcal.r_from_R(R10), t10)))
    return m0, m1


def rt_10(models) -> np.ndarray:
    """(6,) rt_cam1_cam0 of a pair"""
    return mrcal.compose_rt(models[1].rt_cam_ref(), models[0].rt_ref_cam())


@dataclasses.dataclass
class ExtrinsicsError:
    """Camera 1 relative to camera 0, calibrated (or one calibration) against the truth (or another)"""

    baseline_mm: float
    baseline_true_mm: float
    direction_error_deg: float
    rotation_error_deg: float
    rotation_error_xyz_deg: np.ndarray  # (3,) rotation vector of R_cal R_true^T in camera 0's axes

    @property
    def baseline_error_mm(self) -> float:
        return self.baseline_mm - self.baseline_true_mm

    def summary(self) -> dict:
        return {"baseline_mm": self.baseline_mm, "baseline_true_mm": self.baseline_true_mm,
                "baseline_error_mm": self.baseline_error_mm, "direction_error_deg": self.direction_error_deg,
                "rotation_error_deg": self.rotation_error_deg,
                "rotation_error_xyz_deg": [float(v) for v in self.rotation_error_xyz_deg]}


def extrinsics_error(models, models_ref) -> ExtrinsicsError:
    """The extrinsics of the pair `models` against those of `models_ref` (the truth, or another calibration)"""
    rt, rt_ref = rt_10(models), rt_10(models_ref)
    c = mrcal.rotate_point_r(-rt[:3], -rt[3:])  # camera 1's centre in camera 0's frame: -R^T t
    c_ref = mrcal.rotate_point_r(-rt_ref[:3], -rt_ref[3:])
    cosang = np.dot(c, c_ref) / (np.linalg.norm(c) * np.linalg.norm(c_ref))
    # R_10 R_10ref^T, expressed in camera 0's axes: R_10ref^T (R_10 R_10ref^T) R_10ref = R_10ref^T R_10
    dR = mrcal.R_from_r(rt_ref[:3]).T @ mrcal.R_from_r(rt[:3])
    r = mrcal.r_from_R(dR)
    return ExtrinsicsError(float(np.linalg.norm(c) * 1e3), float(np.linalg.norm(c_ref) * 1e3),
                           float(np.degrees(np.arccos(np.clip(cosang, -1, 1)))),
                           float(np.degrees(np.linalg.norm(r))), np.degrees(r))


def frame_names(model, names) -> list:
    """The pose name (one of `names`) of each frame of a calibration, None where unknown

    A frame's name is the component of its image paths that is one of names
    (seq/pose003/camera-1/rotstar_00.png -> 'pose003').

    SYNOPSIS

        >>> pose_of_path("seq/pose003/camera-1/rotstar_00.png", {"pose003", "pose004"})
        'pose003'
    """
    oi = model.optimization_inputs()
    out = [None] * len(oi["rt_ref_frame"])
    paths = oi.get("imagepaths")
    if paths is None:
        return out
    names = set(names)
    for iframe, p in zip(oi["indices_frame_camintrinsics_camextrinsics"][:, 0], paths):
        out[iframe] = out[iframe] or pose_of_path(str(p), names)
    return out


def pose_of_path(path: str, names) -> str | None:
    """The component of an image path that is one of names (its pose), None if none is"""
    return next((c for c in reversed(re.split(r"[/\\]", os.path.normpath(path))) if c in names), None)


def camera_alignment(model, true_model, rt_ref_board: dict) -> np.ndarray | None:
    """Rt (4, 3) from the calibrated camera's frame to the true camera's, from the boards; None if < 2 known

    model: one camera of a joint calibration (with its optimization_inputs);
    rt_ref_board: {pose name: true rt_ref_board} (ref = the true camera 0).
    """
    oi = model.optimization_inputs()
    if oi is None:
        return None
    ny, nx = oi["observations_board"].shape[1:3]
    spacing = oi["calibration_object_spacing"]
    board = mrcal.ref_calibration_object(nx, ny, spacing, calobject_warp=oi.get("calobject_warp"))
    flat = mrcal.ref_calibration_object(nx, ny, spacing)
    rt_cam_ref = model.rt_cam_ref()
    rt_cam_ref_true = true_model.rt_cam_ref()
    p0, p1 = [], []
    for k, name in enumerate(frame_names(model, rt_ref_board)):
        if name is None:
            continue
        solved = mrcal.transform_point_rt(mrcal.compose_rt(rt_cam_ref, oi["rt_ref_frame"][k]), board)
        true = mrcal.transform_point_rt(mrcal.compose_rt(rt_cam_ref_true, np.asarray(rt_ref_board[name], float)),
                                        flat)
        best = min((g for _, g in relabelled_boards(true) if g.shape == solved.shape),
                   key=lambda g: np.mean(np.linalg.norm(g - solved, axis=-1)))
        p0.append(best.reshape(-1, 3))
        p1.append(solved.reshape(-1, 3))
    if len(p0) < 2:
        return None
    return mrcal.align_procrustes_points_Rt01(np.concatenate(p0), np.concatenate(p1))


def camera_truth_error(model, true_model, rt_ref_board: dict, gridn_width: int = 40) -> TruthError:
    """One camera of a joint calibration against the true camera: projection error over its imager, at infinity

    Falls back to truth.truth_error's mrcal.projection_diff when fewer than
    two frames have a known true pose (or the model has no
    optimization_inputs).
    """
    Rt = camera_alignment(model, true_model, rt_ref_board)
    if Rt is None:
        return truth_error(model, true_model, None, gridn_width=gridn_width)
    q = imager_grid(model.imagersize(), gridn_width)
    v = mrcal.unproject(q, *model.intrinsics(), normalize=True)
    err = np.linalg.norm(mrcal.project(mrcal.rotate_point_R(Rt[:3], v), *true_model.intrinsics()) - q, axis=-1)
    return TruthError(q, err, float(np.degrees(np.linalg.norm(mrcal.r_from_R(Rt[:3])))), "procrustes")


def pair_diff(pair_a, pair_b, distances, gridn_width: int = 40) -> dict:
    """{distance: median and 95th percentile (px) of mrcal.stereo_pair_diff of two pairs}

    SYNOPSIS

        >>> from rotstar_mrcal.simulate.camera import preset_model
        >>> a = shifted_pair(preset_model("d435"), 0.050)
        >>> b = shifted_pair(preset_model("d435"), 0.051)
        >>> round(pair_diff(a, b, [1.0])["1"]["median_px"], 2)   # f dB / Z = 0.64 px on the axis, more off it
        0.75

    The distance is a range from camera 0: off the axis the point is nearer
    in z, and its disparity larger.
    """
    out = {}
    for z in distances:
        d, _, _, _ = mrcal.stereo_pair_diff([list(pair_a), list(pair_b)], gridn_width=gridn_width,
                                            distance=float(z))
        out[f"{z:g}"] = {"median_px": float(np.nanmedian(d)), "p95_px": float(np.nanpercentile(d, 95))}
    return out


def pair_crossval(pair_a, pair_b, distances, gridn_width: int = 40) -> dict:
    """mrcal's cross-validation of two calibrations of one pair (JSON-able)

    {"cameras": [crossval summary of camera 0, of camera 1],
     "extrinsics": extrinsics of A against B, "pair_diff": pair_diff at the distances}
    A camera whose uncertainty mrcal cannot compute gets {"error": ...}.
    """
    cams = []
    for a, b in zip(pair_a, pair_b):
        try:
            cams.append(cross_validate(a, b, gridn_width=gridn_width).summary())
        except Exception as e:  # mrcal refuses models without usable uncertainties
            cams.append({"error": f"{type(e).__name__}: {e}"})
    return {"cameras": cams, "extrinsics": extrinsics_error(pair_a, pair_b).summary(),
            "pair_diff": pair_diff(pair_a, pair_b, distances, gridn_width)}


def pair_stats(models) -> list[dict]:
    """Per camera of a joint calibration: boards it saw, points used, RMS and worst residual (px, 2-D, unweighted)"""
    oi = models[0].optimization_inputs()
    obs = oi["observations_board"]
    ny, nx = obs.shape[1:3]
    idx = oi["indices_frame_camintrinsics_camextrinsics"]
    board = mrcal.ref_calibration_object(nx, ny, oi["calibration_object_spacing"],
                                         calobject_warp=oi.get("calobject_warp"))
    out = []
    for m in models:
        ic = m.icam_intrinsics()
        sel = idx[:, 1] == ic
        rt = mrcal.compose_rt(m.rt_cam_ref(), oi["rt_ref_frame"][idx[sel, 0]])
        q = mrcal.project(mrcal.transform_point_rt(rt[:, None, None, :], board), *m.intrinsics())
        e = np.linalg.norm(q - obs[sel, ..., :2], axis=-1)[obs[sel, ..., 2] > 0]
        out.append({"boards": int(sel.sum()), "points": int(e.size),
                    "rms_px": float(np.sqrt(np.mean(e**2))) if e.size else None,
                    "max_px": float(np.max(e)) if e.size else None})
    return out


def pair_truth_error(pair, true_pair, rt_ref_board: dict, gridn_width: int = 40) -> dict:
    """{"cameras": [camera_truth_error summary per camera], "extrinsics": extrinsics_error summary}: a calibrated
    pair against the true one"""
    return {"cameras": [camera_truth_error(m, tm, rt_ref_board, gridn_width).summary()
                        for m, tm in zip(pair, true_pair)],
            "extrinsics": extrinsics_error(pair, true_pair).summary()}


def evaluate(method: str, pairs: dict, truth=None, rt_ref_board: dict | None = None, heldout: dict | None = None,
             noise_px: float = 0.0, seed: int = 0, gridn_width: int = 40) -> dict:
    """Every number of the stereo calibrations of one corner set (JSON-able)

    pairs: {"A": (model 0, model 1), "B": ...} (joint calibrations of two
    pose groups, with their optimization_inputs); truth: the true pair or
    None; rt_ref_board: {pose: true rt_ref_board} (camera_truth_error's
    alignment); heldout: depth.heldout_points of the true pair (the depth
    table). noise_px: the corner noise of the method, added to the held-out
    pixels in a second depth table ("depth_noisy").

        {"method", "calibration": {g: [per camera stats]},
         "truth": {g: {"cameras": [camera_truth_error summaries], "extrinsics": ...,
                       "depth": ..., "depth_noisy": ...}},
         "crossval": {"cameras", "extrinsics", "pair_diff", "depth"}}
    """
    out = {"method": method, "calibration": {g: pair_stats(p) for g, p in pairs.items()}}
    if truth is not None:
        out["truth"] = {}
        for g, p in pairs.items():
            t = pair_truth_error(p, truth, rt_ref_board or {}, gridn_width)
            if heldout:
                t["depth"] = dp.depth_error(heldout, truth, p).summary()
                if noise_px:
                    t["depth_noisy"] = dp.depth_error(heldout, truth, p, noise_px, rng=seed).summary()
            out["truth"][g] = t
    if "A" in pairs and "B" in pairs:
        distances = sorted(heldout) if heldout else list(dp.DISTANCES)
        cv = pair_crossval(pairs["A"], pairs["B"], distances, gridn_width)
        cv["depth"] = dp.depth_crossval(pairs["A"], pairs["B"], distances)
        out["crossval"] = cv
    return out

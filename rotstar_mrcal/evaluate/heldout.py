"""The paper's held-out metric: test poses solved with the intrinsics fixed

SYNOPSIS

    >>> import numpy as np, mrcal
    >>> from rotstar_mrcal.pattern.layout import make_layout
    >>> from rotstar_mrcal.simulate.camera import preset_model
    >>> from rotstar_mrcal.simulate.poses import random_poses
    >>> from rotstar_mrcal.simulate.dataset import true_corners
    >>> from rotstar_mrcal.evaluate.heldout import heldout
    >>> model, layout = preset_model("d435"), make_layout()
    >>> corners = true_corners(model, layout, random_poses(model, layout, 3, 0))
    >>> corners = corners + np.random.default_rng(1).normal(0, 0.1, corners.shape)
    >>> h = heldout(model, corners, layout.spacing_m)
    >>> h.per_pose.shape, bool(0.1 < h.mean < 0.15)        # noise floor: 1.2533 sigma
    ((3,), True)
    >>> lens, intr = model.intrinsics(); intr = intr.copy(); intr[4] -= 0.05   # k1
    >>> wrong = mrcal.cameramodel(intrinsics=(lens, intr), imagersize=model.imagersize())
    >>> bool(heldout(wrong, corners, layout.spacing_m).mean > 0.5)
    True

"Calibrate on one group of poses, test on the other by solving each pose
with PnP and computing the mean reprojection error" (paper, 4.2). Each test
board's pose is solved alone (mrcal.optimize with only the frames free: the
intrinsics, the board shape and everything else fixed, no regularisation,
no outlier rejection), seeded by mrcal's PnP. The errors are the plain 2-D
distances between the detected corners and the projections of the solved
board, unweighted; the mean over all corners is the paper's MRE.

What it measures: how well the model predicts corners it has not seen, as
detected by the same detector. It mixes the model's error with the test
detector's noise: with a perfect model the MRE is the detection noise after
the 6-parameter pose fit, 1.2533 sigma for isotropic Gaussian noise of sigma
px per axis (a little less: each pose absorbs 6 of its 2n degrees of
freedom). Compare MREs of one detector across models, or of models from
different detectors on the same test poses, knowing that a noisier test
detector raises its own floor.

Boards with fewer than MIN_POINTS corners are not solved (NaN).

Through a screen's cover glass (glass: the one the model was corrected for,
calibrate.glass), the test corners are corrected as the calibration's were:
each moved to where the unrefracted pixel would have been seen from its
board's solved pose (calibrate.glass.observation_shift), the poses solved
again (calibrate.glass.solve_corrected), and the errors measured against the corrected
corners. Without it, a model corrected for the glass is tested on corners
that still carry it.
"""

from __future__ import annotations

import dataclasses

import mrcal
import numpy as np

from rotstar_mrcal.calibrate.glass import solve_corrected
from rotstar_mrcal.optics.refraction import Glass

MIN_POINTS = 6


@dataclasses.dataclass
class HeldOut:
    """Per-corner errors of a model on held-out boards"""

    errors: np.ndarray  # (N, ny, nx) px, NaN where no corner / board not solved
    rt_cam_frame: np.ndarray  # (N, 6) solved board poses, NaN rows for unsolved boards

    @property
    def per_pose(self) -> np.ndarray:
        """(N,) mean error of each board, NaN for boards not solved"""
        e = self.errors.reshape(len(self.errors), -1)
        n = np.isfinite(e).sum(axis=1)
        s = np.nansum(e, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(n > 0, s / np.maximum(n, 1), np.nan)

    @property
    def mean(self) -> float:
        """The paper's MRE: mean over every corner of every solved board"""
        e = self.errors[np.isfinite(self.errors)]
        return float(e.mean()) if e.size else float("nan")

    @property
    def rms(self) -> float:
        e = self.errors[np.isfinite(self.errors)]
        return float(np.sqrt(np.mean(e**2))) if e.size else float("nan")

    @property
    def points(self) -> int:
        return int(np.isfinite(self.errors).sum())

    @property
    def boards(self) -> int:
        return int(np.isfinite(self.per_pose).sum())


def mrcal_observations(corners, weights=None) -> np.ndarray:
    """(N, ny, nx, 2) corners with NaN -> mrcal's (N, ny, nx, 3) with weight (-1 = missing)"""
    c = np.asarray(corners, float)
    ok = np.isfinite(c).all(axis=-1)
    w = np.ones(c.shape[:-1]) if weights is None else np.asarray(weights, float)
    ok &= np.isfinite(w) & (w > 0)
    return np.concatenate((np.where(ok[..., None], c, 0.0), np.where(ok, w, -1.0)[..., None]), axis=-1)


def heldout(model: mrcal.cameramodel, corners, spacing: float, calobject_warp=None, weights=None,
            glass: Glass | None = None) -> HeldOut:
    """Solve each board of `corners` with `model`'s intrinsics fixed; see the module doc

    corners: (N, ny, nx, 2), mrcal order (record j*nx+i is board point (i,
    j) * spacing), NaN for missing corners. calobject_warp: the board's shape
    (mrcal's 2 numbers; None = flat), normally the one the model's own
    calibration solved for the same physical board. weights: optional (N,
    ny, nx) weights for the pose fit (the errors are reported unweighted).
    glass: the screen's cover glass the model was corrected for (module doc).
    """
    corners = np.asarray(corners, float)
    N, ny, nx = corners.shape[:3]
    obs = mrcal_observations(corners, weights)
    errors = np.full((N, ny, nx), np.nan)
    rt = np.full((N, 6), np.nan)
    use = np.flatnonzero((obs[..., 2] > 0).reshape(N, -1).sum(axis=1) >= MIN_POINTS)
    if len(use) == 0:
        return HeldOut(errors, rt)
    lensmodel, intrinsics = model.intrinsics()
    o = obs[use]
    n = len(use)
    ifc = np.column_stack((np.arange(n), np.zeros(n))).astype(np.int32)
    Rt = mrcal.estimate_monocular_calobject_poses_Rt_tocam(ifc, o, spacing, (model,))
    warp = None if calobject_warp is None else np.asarray(calobject_warp, float)
    oi = dict(
        lensmodel=lensmodel,
        intrinsics=np.asarray(intrinsics, float)[None].copy(),
        imagersizes=np.asarray(model.imagersize(), np.int32)[None],
        rt_cam_ref=np.zeros((0, 6)),
        rt_ref_frame=mrcal.rt_from_Rt(Rt),
        observations_board=o.copy(),
        indices_frame_camintrinsics_camextrinsics=np.column_stack(
            (np.arange(n), np.zeros(n), -np.ones(n))).astype(np.int32),
        calibration_object_spacing=spacing,
        calobject_warp=warp,
        do_optimize_intrinsics_core=False,
        do_optimize_intrinsics_distortions=False,
        do_optimize_extrinsics=False,
        do_optimize_frames=True,
        do_optimize_calobject_warp=False,
        do_apply_regularization=False,
        do_apply_outlier_rejection=False,
    )
    mrcal.optimize(**oi)
    if glass is not None and not glass.none:
        oi = solve_corrected(oi, glass)  # its observations: the corners corrected for the glass
    obj = mrcal.ref_calibration_object(nx, ny, spacing, calobject_warp=warp)
    q = mrcal.project(mrcal.transform_point_rt(oi["rt_ref_frame"][:, None, None, :], obj), lensmodel, intrinsics)
    e = np.linalg.norm(q - oi["observations_board"][..., :2], axis=-1)
    errors[use] = np.where(o[..., 2] > 0, e, np.nan)
    rt[use] = oi["rt_ref_frame"]
    return HeldOut(errors, rt)

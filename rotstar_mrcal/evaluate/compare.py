"""One corner set, two pose groups: every validation number of its pair of calibrations

SYNOPSIS

    import mrcal
    from rotstar_mrcal.evaluate.compare import evaluate
    a = mrcal.cameramodel("xval/rotstar/A/camera-0.cameramodel")
    b = mrcal.cameramodel("xval/rotstar/B/camera-0.cameramodel")
    r = evaluate("rotstar", a, b, test_a, test_b, spacing)
    r.summary["heldout"]["A->B"]["mean_px"]     # the paper's MRE, model A on B's poses
    r.summary["crossval"]["ratio_median"]       # mrcal's diff / (uA + uB)

The comparison mode of rotstar-crossval runs this for each corner set
(rotstar, the checkerboard baselines, ...) of the same two pose groups A and
B, so that their numbers can be tabulated side by side:

    calibration  each group's own fit: boards, points, RMS (2-D, unweighted)
    heldout      A's intrinsics on B's boards and the reverse (heldout.py),
                 each on that method's own corners of the test group
    crossval     mrcal's projection diff of A and B against uA + uB (crossval.py)
    truth        simulated data only: each model against the true one (truth.py),
                 and the true tilt of every test pose (tilts.py)

The arrays behind the numbers (grids for the figures, per-pose errors) come
back with them.
"""

from __future__ import annotations

import dataclasses

import mrcal
import numpy as np

from rotstar_mrcal.calibrate.cornerset import TestSet, TrueCamera
from rotstar_mrcal.calibrate.solve import calibration_stats
from rotstar_mrcal.evaluate.crossval import CrossVal, cross_validate
from rotstar_mrcal.evaluate.heldout import HeldOut, heldout
from rotstar_mrcal.evaluate.tilts import tilts_of
from rotstar_mrcal.evaluate.truth import TruthError, truth_error, truth_poses_of
from rotstar_mrcal.optics.refraction import Glass


@dataclasses.dataclass
class Evaluation:
    method: str
    summary: dict  # JSON-able numbers
    heldout: dict[str, HeldOut]  # 'A->B', 'B->A'
    crossval: CrossVal | None
    truth: dict[str, TruthError]  # 'A', 'B' (simulated data)


def _heldout_summary(h: HeldOut, test: TestSet, truth: TrueCamera | None) -> dict:
    out = {
        "mean_px": h.mean,
        "rms_px": h.rms,
        "boards": h.boards,
        "points": h.points,
        "per_pose": {n: (None if not np.isfinite(v) else float(v)) for n, v in zip(test.names, h.per_pose)},
    }
    if truth is not None:  # the true tilt of each test pose (the error by tilt, tilts.by_tilt)
        ny, nx = test.corners.shape[1:3]
        out["tilt_deg"] = tilts_of(truth.rt_cam_board, test.names,
                                   ((nx - 1) * test.spacing / 2, (ny - 1) * test.spacing / 2, 0.0))
    return out


def evaluate(method: str, model_a: mrcal.cameramodel, model_b: mrcal.cameramodel, test_a: TestSet,
             test_b: TestSet, truth_a: TrueCamera | None = None, truth_b: TrueCamera | None = None,
             gridn_width: int = 40, distance: float | None = None, glass_a: Glass | None = None,
             glass_b: Glass | None = None) -> Evaluation:
    """All validation numbers of the calibrations A and B of one corner set

    glass_a, glass_b: the screen's cover glass each model was corrected for (calibrate.glass; None: not
    corrected); the held-out corners it is tested on are corrected for the same (evaluate.heldout).
    """
    held = {}
    for key, model, test, glass in (("A->B", model_a, test_b, glass_a), ("B->A", model_b, test_a, glass_b)):
        warp = model.optimization_inputs().get("calobject_warp")
        held[key] = heldout(model, test.corners, test.spacing, calobject_warp=warp, glass=glass)
    try:
        cv = cross_validate(model_a, model_b, gridn_width=gridn_width, distance=distance)
        cv_summary = cv.summary()
    except Exception as e:  # mrcal refuses models without usable uncertainties
        cv, cv_summary = None, {"error": f"{type(e).__name__}: {e}"}
    terr = {}
    for key, model, t in (("A", model_a, truth_a), ("B", model_b, truth_b)):
        if t is not None:
            terr[key] = truth_error(model, t.model, truth_poses_of(model, t.rt_cam_board),
                                    gridn_width=gridn_width, distance=distance)
    summary = {
        "method": method,
        "calibration": {"A": calibration_stats(model_a), "B": calibration_stats(model_b)},
        "heldout": {"A->B": _heldout_summary(held["A->B"], test_b, truth_b),
                    "B->A": _heldout_summary(held["B->A"], test_a, truth_a)},
        "crossval": cv_summary,
        "truth": {k: v.summary() for k, v in terr.items()} or None,
    }
    return Evaluation(method, summary, held, cv, terr)

"""The rendered glass rows (rotstar_lab.benchmark.glassrender): the refracted truth, the same-noise reference"""

from __future__ import annotations

import mrcal
import numpy as np
import pytest

from rotstar_lab.benchmark.glass import observed_corners
from rotstar_lab.benchmark.glassrender import (rendered_failures, rendered_rig_row, rendered_rig_table, rendered_table,
                                                same_noise_reference, true_grids)
from rotstar_mrcal.evaluate.truth import truth_error
from rotstar_mrcal.optics.refraction import Glass
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.simulate.camera import preset_model
from rotstar_mrcal.simulate.poses import random_poses

MODEL, LAYOUT = preset_model("d435"), make_layout()


def solved_inputs(q: np.ndarray, rts: np.ndarray) -> dict:
    """One camera's problem on corners q (N, ny, nx, 2) of poses rts, solved from near the truth"""
    n = len(rts)
    oi = dict(intrinsics=MODEL.intrinsics()[1][None] * (1 + 1e-3), rt_cam_ref=np.zeros((0, 6)),
              rt_ref_frame=rts.copy(), points=None,
              observations_board=np.concatenate((q, np.ones(q.shape[:-1] + (1,))), -1),
              indices_frame_camintrinsics_camextrinsics=np.array([(i, 0, -1) for i in range(n)], np.int32),
              observations_point=None, indices_point_camintrinsics_camextrinsics=None,
              lensmodel=MODEL.intrinsics()[0], imagersizes=np.array([MODEL.imagersize()], np.int32),
              calobject_warp=np.zeros(2), do_optimize_intrinsics_core=True, do_optimize_intrinsics_distortions=True,
              do_optimize_extrinsics=False, do_optimize_frames=True, do_optimize_calobject_warp=True,
              calibration_object_spacing=LAYOUT.spacing_m, do_apply_outlier_rejection=False,
              do_apply_regularization=True, verbose=False,
              imagepaths=np.array([f"seq/pose{i:03d}/rotstar_00.png" for i in range(n)]))
    mrcal.optimize(**oi)
    return oi


def median_error(oi: dict, rts: np.ndarray) -> float:
    return truth_error(mrcal.cameramodel(optimization_inputs=oi, icam_intrinsics=0), MODEL, rts).median


def test_the_reference_is_the_glass_free_solve_with_the_same_corner_errors():
    rts = random_poses(MODEL, LAYOUT, 12, np.random.default_rng([1, 12]), max_tilt_deg=60.0)
    glass = Glass.mm(1.0)
    noise = np.random.default_rng(3).normal(0, 0.004, (12, LAYOUT.ny, LAYOUT.nx, 2))
    seen = observed_corners(MODEL, LAYOUT, rts, glass) + noise
    seen[5] = seen[5, ::-1, ::-1]  # one board labelled from the other corner, as a detector may
    oi = solved_inputs(seen, rts)
    truth = {(f"pose{i:03d}", 0): rt for i, rt in enumerate(rts)}
    refracted, straight = true_grids([MODEL], LAYOUT, truth, glass, oi)
    assert np.sqrt(np.mean((oi["observations_board"][..., :2] - refracted) ** 2)) == pytest.approx(0.004, rel=0.1)
    assert 0.05 < np.max(np.abs(refracted - straight)) < 2
    ref, rms = same_noise_reference(oi, refracted, straight)
    assert rms == pytest.approx(0.004, rel=0.1)
    free = solved_inputs(observed_corners(MODEL, LAYOUT, rts, Glass()) + noise, rts)
    assert median_error(ref, rts) == pytest.approx(median_error(free, rts), rel=0.05)
    assert median_error(oi, rts) > 3 * median_error(ref, rts)  # the glass is in the plain solve, not in the reference


@pytest.mark.slow
def test_a_rendered_rig_row(tmp_path):
    """(1-2 min) rotstar-simulate --rig d435-small --glass 1.0 and rotstar-calibrate: the glass found and taken out"""
    row = rendered_rig_row(str(tmp_path), 8, 1.0, seed=2, jobs=2, log=lambda s: None, rig="d435-small")
    assert row["applied"] and abs(row["estimate_mm"] - 1.0) < max(0.15, 3 * row["sigma_mm"])
    assert row["corrected"]["camera0_median_px"] < row["plain"]["camera0_median_px"] / 2
    assert row["corrected"]["camera0_median_px"] < 1.5 * row["reference"]["camera0_median_px"]
    assert 0 < row["noise_px"] < 0.05


def test_the_rendered_tables_and_their_verdict():
    one = {"poses": 20, "glass_mm": 1.0, "noise_px": 0.0035, "plain": (0.1, 0.24), "corrected": (0.023, 0.06),
           "reference": (0.021, 0.044), "estimate_mm": 1.065, "sigma_mm": 0.053, "applied": True, "reason": "x"}
    pair = {"baseline_error_mm": 0.026, "direction_error_deg": 0.05, "rotation_error_deg": 0.003,
            "camera0_median_px": 0.12}
    rig = {**one, "plain": pair, "corrected": dict(pair, camera0_median_px=0.018),
           "reference": dict(pair, camera0_median_px=0.0178)}
    assert rendered_failures([one], [rig]) == []
    assert "| 20 | 1 mm |" in rendered_table([one]) and "1.10x" in rendered_table([one])
    assert "+0.0260 -> +0.0260 (+0.0260) mm" in rendered_rig_table([rig])
    worse = dict(one, corrected=(0.03, 0.06))
    assert any("> 1.2x its same-noise reference" in b for b in rendered_failures([worse], []))
    assert rendered_failures([dict(one, estimate_mm=1.3)], [])  # 0.3 mm off, 4 sigma
    assert rendered_failures([], [dict(rig, applied=False)])
    assert rendered_failures([dict(one, glass_mm=0.0, estimate_mm=0.3)], [])  # a glass-free capture corrected
    assert not rendered_failures([dict(one, glass_mm=0.0, estimate_mm=0.1, applied=False)], [])

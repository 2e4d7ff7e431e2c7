"""The lab's capture benchmark against the truth (scripts/capture_calib_bench.py)"""

from __future__ import annotations

import os

import mrcal
import numpy as np
import pytest

from rotstar_mrcal.capture.pose import ensure_pattern
from rotstar_mrcal.capture.session import OutputDataset
from rotstar_mrcal.simulate.camera import preset_model
from rotstar_mrcal.simulate.dataset import load_truth
from rotstar_mrcal.simulate.poses import random_poses
from rotstar_mrcal.vnl import write_corners

from conftest import lab_script


B = lab_script("capture_calib_bench")


def test_the_half_size_d435_sees_what_the_d435_sees_at_half_scale():
    full, half = preset_model("d435"), B.half_d435()
    assert tuple(half.imagersize()) == (640, 400) and half.intrinsics()[0] == full.intrinsics()[0]
    p = np.array([[0.1, -0.05, 1.0], [-0.4, 0.3, 1.0]])
    q_full = mrcal.project(p, *full.intrinsics())
    assert np.allclose(mrcal.project(p, *half.intrinsics()), (q_full + 0.5) / 2 - 0.5)


def test_corner_error_is_the_median_distance_from_the_truth(tmp_path):
    model = B.half_d435()
    rts = random_poses(model, B.LAYOUT, 2, np.random.default_rng(3))
    ensure_pattern(str(tmp_path), B.PATTERN)
    B.write_truth_of(str(tmp_path), model, {"pose000": rts[0], "pose001": rts[1]})
    truth = load_truth(str(tmp_path))
    vnl = tmp_path / "corners.vnl"
    with open(vnl, "w") as f:
        write_corners(f, [(f"seq/pose{k:03d}/rotstar_00.png", truth.corners[f"pose{k:03d}"] + [0.003 * (k + 1), 0])
                          for k in range(2)])
    assert B.corner_error(str(vnl), truth) == pytest.approx(0.0045, abs=1e-6)


def row(median, sigma, poses=10):
    return {"poses": poses, "kept": poses, "boards": poses, "seconds_median": 2.7, "seconds_max": 3.0, "total_s": 37,
            "corner_px": 0.002, "median_px": median, "worst_px": 2 * median, "sigma_px": sigma}


def test_the_table_says_which_target_is_met():
    text = B.table({"today": row(0.02, 0.02), "short-same": row(0.024, 0.025), "short-more": row(0.03, 0.007, 58)},
                   1.0, 0)
    assert "| 58 (58 / 58) |" in text and "| 1.50x | 0.0070 (0.35x) |" in text and "control" not in text
    control = B.table({"today": row(0.02, 0.02), "short-same": row(0.024, 0.025), "short-more": row(0.03, 0.007, 58),
                       "today-more": row(0.015, 0.006, 58)}, 1.0, 0)
    assert "| control: hold 30, 2.2 loops, on the poses of the row above | 58 (58 / 58) |" in control
    assert "(a) the same poses: 1.20x today's median (target <= 1.25x): met" in text
    assert "(b) the same time on more poses: 1.50x today's median (target < 1): NOT met" in text
    failed = B.table({"today": row(0.02, 0.02), "short-same": {**row(0, 0), "median_px": np.nan} | {"error": "x"},
                      "short-more": row(0.01, 0.007, 58)}, 1.0, 0)
    assert "(a) the same poses: nanx" in failed and "NOT met" in failed.splitlines()[-2]
    assert "(b) the same time on more poses: 0.50x today's median (target < 1): met" in failed


@pytest.mark.slow
def test_one_pose_both_ways(tmp_path):
    """(10-30 s) one pose through capture_one both ways: 22 s at hold 30, under 6 s with the short holds"""
    model = B.half_d435()
    E = B.render(model, random_poses(model, B.LAYOUT, 1, np.random.default_rng(5))[0])
    secs = {}
    for name, hold in B.SETTINGS.items():
        ds = OutputDataset(str(tmp_path / name), None)
        e = B.capture_pose(E, hold, ds, "pose000", str(tmp_path / "raw"), np.random.default_rng(1))
        assert e["ok"] and os.path.exists(tmp_path / name / "pose000" / "rotstar_00.png")
        secs[name] = e["seconds"]
    assert 21.5 < secs["today"] < 23 and secs["short"] < 6

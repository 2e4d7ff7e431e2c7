"""The lab's glass benchmark (scripts/glass_bench.py, rotstar_lab.benchmark.glass)"""

from __future__ import annotations


import numpy as np
import pytest

from rotstar_lab.benchmark.glass import observed_corners, rig_row, rig_table, run_one, table
from rotstar_mrcal.optics.refraction import Glass
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.simulate.camera import preset_model
from rotstar_mrcal.simulate.dataset import true_corners
from rotstar_mrcal.simulate.poses import random_poses

from conftest import lab_script

MODEL, LAYOUT = preset_model("d435"), make_layout()


def bench_script():
    return lab_script("glass_bench")


def test_observed_corners_without_glass_or_pupil_are_the_true_ones():
    rts = random_poses(MODEL, LAYOUT, 3, np.random.default_rng(1))
    q = observed_corners(MODEL, LAYOUT, rts, Glass(0.0))
    assert np.max(np.abs(q - true_corners(MODEL, LAYOUT, rts))) < 1e-9
    moved = observed_corners(MODEL, LAYOUT, rts, Glass.mm(1.0))
    pupil = observed_corners(MODEL, LAYOUT, rts, Glass(0.0), pupil_mm=2.0)
    assert 0.05 < np.max(np.abs(moved - q)) < 2 and 0.01 < np.max(np.abs(pupil - q)) < 5


def test_one_row_and_the_verdict(tmp_path):
    row = run_one(str(tmp_path), 12, 1.0, seed=3)
    assert row["applied"] and row["corrected"][0] < row["plain"][0]
    worse_free = dict(row, glass_mm=0.0, estimate_mm=0.0, corrected=row["plain"], plain=(row["corrected"][0] / 2, 0.1))
    text = table([worse_free, row])
    assert text.count("\n") == 3 and "| 12 | 1 mm |" in text
    script = bench_script()
    assert any("> 1.2x the glass-free" in b for b in script.failures([worse_free, row]))
    same_free = dict(worse_free, plain=row["corrected"])
    assert script.failures([same_free, row]) == []
    assert script.failures([same_free, dict(row, estimate_mm=1.5)])  # 0.5 mm off, 10 sigma
    assert script.failures([same_free, dict(row, glass_mm=0.0, pupil_mm=2.0)])  # a moving pupil's estimate applied


@pytest.mark.slow
def test_the_stereo_pair_row():
    """(5-12 s) the D435 pair through 1 mm: one estimate, camera 1's pose put back"""
    row = rig_row(10, 1.0, seed=1)
    assert row["applied"] and abs(row["estimate_mm"] - 1.0) < max(0.1, 2 * row["sigma_mm"])
    p, c = row["plain"], row["corrected"]
    assert c["centre_mm"] < p["centre_mm"] / 3 and c["rotation_deg"] < p["rotation_deg"] / 3
    assert "| 10 | 1 mm |" in rig_table([row])
    assert bench_script().rig_failures([row]) == []
    assert bench_script().rig_failures([dict(row, applied=False)])

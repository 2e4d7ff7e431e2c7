"""rotstar-crossval --glass: every corner set's calibrations corrected for the screen's cover glass

The corner sets are the exact projections of the default board's corners
through 0.7 mm of glass (optics.refraction: where each emitting pixel is
seen through it; the simulator's renders put the detected corners there,
tests/simulate/test_cover_glass.py) plus 0.005 px of noise, two groups of
poses with their truth, as make demo writes them (pattern.json, truth.json,
truth.cameramodel and the method's corners.vnl in one folder). Not rendered:
the calibrations, not the detector, are under test, and a render of 20 poses
takes ~30 s here.
"""

from __future__ import annotations

import json
import os

import mrcal
import numpy as np
import pytest

from rotstar_mrcal import dataset as ds
from rotstar_mrcal.optics.refraction import Glass, apparent_points
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.simulate.camera import preset_model
from rotstar_mrcal.simulate.dataset import Truth, write_truth
from rotstar_mrcal.simulate.poses import random_poses
from rotstar_mrcal.vnl import write_corners

MODEL, LAYOUT = preset_model("d435"), make_layout()
GLASS_MM = 0.7
N = 12  # poses per group


def write_group(folder: str, seed: int, t_mm: float) -> str:
    """A group of N poses seen through t_mm of glass: its folder with the truth and rotstar.vnl (returned)"""
    rts = random_poses(MODEL, LAYOUT, N, np.random.default_rng([0, seed]), max_tilt_deg=60)
    c = mrcal.transform_point_rt(mrcal.invert_rt(rts), np.zeros(3))  # camera centres, board frames
    a = apparent_points(c[:, None, None, :], LAYOUT.board_points()[None], Glass.mm(t_mm))
    q = mrcal.project(mrcal.transform_point_rt(rts[:, None, None, :], a), *MODEL.intrinsics())
    q += np.random.default_rng([1, seed]).normal(0, 0.005, q.shape)
    os.makedirs(folder)
    ds.write_pattern(folder, LAYOUT)
    MODEL.write(os.path.join(folder, "truth.cameramodel"))
    names = [f"pose{i:03d}" for i in range(N)]
    true = mrcal.project(mrcal.transform_point_rt(rts[:, None, None, :], LAYOUT.board_points()), *MODEL.intrinsics())
    write_truth(folder, Truth(MODEL, LAYOUT, dict(zip(names, rts)), dict(zip(names, true)), {"glass_mm": t_mm}))
    vnl = os.path.join(folder, "rotstar.vnl")
    with open(vnl, "w") as f:
        write_corners(f, [(f"{n}/rotstar_00.png", v) for n, v in zip(names, q)])
    return vnl


@pytest.fixture(scope="module")
def glass_sets(tmp_path_factory):
    d = tmp_path_factory.mktemp("glass-sets")
    return [write_group(str(d / g), seed, GLASS_MM) for g, seed in (("A", 11), ("B", 12))]


def crossval(run_cli, vnls, xdir, *extra) -> dict:
    sets = ["--set", "rotstar", *vnls] if vnls else []
    r = run_cli("rotstar-crossval", *sets, "--lensmodel", "opencv8", "--outdir", xdir,
                "--gridn", "10", *extra)
    assert r.returncode == 0, r.stderr
    return json.load(open(os.path.join(xdir, "results.json"))), r


@pytest.fixture(scope="module")
def runs(glass_sets, run_cli, tmp_path_factory):
    """(results without --glass, with --glass 0.7 and its CompletedProcess)"""
    d = tmp_path_factory.mktemp("xval")
    plain, _ = crossval(run_cli, glass_sets, str(d / "plain"))
    given, r = crossval(run_cli, glass_sets, str(d / "given"), "--glass", f"{GLASS_MM}", "--jobs", "2")
    return plain, given, r, d


def test_the_known_glass_is_applied_recorded_and_moves_the_calibration_to_the_truth(runs):
    plain, given, r, d = runs
    m = given["methods"][0]
    assert given["glass"] == {"mm": GLASS_MM, "index": 1.5}
    for s in "AB":
        g = m["glass"][s]
        assert g["given"] and g["applied"] and g["thickness_mm"] == GLASS_MM and g["reason"] == "as given"
        assert os.path.exists(d / "given" / g["model"]) and m["models"][s] == g["model"]
        before, after = g["truth_plain"]["median_px"], m["truth"][s]["median_px"]
        assert after < 0.5 * before, (s, before, after)  # measured: A 0.192 -> 0.0083, B 0.282 -> 0.0205 px
    for d in ("A->B", "B->A"):  # the held-out corners corrected for the same glass: at the noise floor
        h, h_plain = m["heldout"][d]["mean_px"], plain["methods"][0]["heldout"][d]["mean_px"]
        assert h < 0.009 and h < h_plain, (d, h, h_plain)  # 0.005 px noise: 1.25 x 0.005 = 0.0063
    assert "cover glass (index 1.5): 0.700 mm (given); applied" in r.stderr
    assert "| rotstar | A | 0.7 mm given, applied |" in r.stdout  # the glass table after the results table


def test_without_glass_the_plain_calibration_is_evaluated_unchanged(runs):
    plain, given, _, _ = runs
    assert plain["glass"] is None and plain["methods"][0]["glass"] is None
    for s in "AB":  # the plain models of the --glass run are the default run's
        assert plain["methods"][0]["truth"][s]["median_px"] == pytest.approx(
            given["methods"][0]["glass"][s]["truth_plain"]["median_px"], rel=1e-6)


@pytest.mark.parametrize("bad", [["--glass", "-0.5"], ["--glass", "5.5"], ["--glass", "thin"], ["--glass", "nan"],
                                 ["--glass-index", "0.9"], ["--glass-index", "x"]])
def test_bad_glass_values_give_one_line_and_exit_2(bad, run_cli, tmp_path):
    r = run_cli("rotstar-crossval", "--set", "rotstar", "a.vnl", "b.vnl", "--outdir", tmp_path, *bad)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    err = [line for line in r.stderr.splitlines() if "error" in line]
    assert len(err) == 1 and bad[0] in err[0] and bad[1] in err[0], r.stderr


@pytest.mark.slow  # make test-slow: four more corner sets calibrated; tests/calibrate/test_glass.py keeps the estimate and
# the clear screen in make test
def test_the_estimate_is_applied_through_glass_and_leaves_a_clear_screen_unchanged(glass_sets, run_cli, tmp_path):
    """--glass estimate: one corner set through 0.7 mm, one of the same kind of poses without glass"""
    clear = [write_group(str(tmp_path / g), seed, 0.0) for g, seed in (("A", 21), ("B", 22))]
    res, r = crossval(run_cli, [], str(tmp_path / "xval"), "--set", "glass", *glass_sets, "--set", "clear", *clear,
                      "--glass", "estimate", "--jobs", "2")
    m = {x["method"]: x for x in res["methods"]}
    assert res["glass"] == {"mm": None, "index": 1.5}
    for s in "AB":
        g = m["glass"]["glass"][s]
        assert g["applied"] and not g["given"] and abs(g["thickness_mm"] - GLASS_MM) < max(0.1, 2 * g["sigma_mm"])
        c = m["clear"]["glass"][s]
        assert not c["applied"] and c["model"] is None and "no glass" in c["reason"], c
        assert m["clear"]["models"][s] == c["plain_model"] and m["clear"]["glass"][s]["truth_plain"] is None

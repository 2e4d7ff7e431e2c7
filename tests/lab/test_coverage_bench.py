"""The coverage experiment's machinery (rotstar_lab.benchmark.coverage); the full run is `make coverage-bench`"""

from __future__ import annotations

import os
import subprocess
import sys

import mrcal
import numpy as np
import pytest

from rotstar_lab.benchmark import coverage as cb
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.simulate import Settings, preset_model, true_corners
from rotstar_mrcal.simulate.poses import pose_ok
from rotstar_mrcal.evaluate.truth import truth_error

D435, LAYOUT = preset_model("d435"), make_layout()
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


@pytest.fixture(scope="module")
def plan():
    return cb.plan_captures(D435, LAYOUT, n=12, hanging=8, seed=1)


def test_two_captures_of_the_same_size_sharing_their_whole_boards(plan):
    whole, edges = plan.captures["whole"], plan.captures["edges"]
    assert len(whole) == len(edges) == 12 and edges[:4] == whole[:4]
    assert [plan.kinds[i] for i in edges[4:]] == list(cb.ZONES)  # the four corners, then the four edges
    assert all(pose_ok(D435, LAYOUT, plan.rts[i]) for i in whole)  # whole boards in view


@pytest.mark.parametrize("k", range(8))
def test_hanging_boards_hang_over_their_zone(plan, k):
    i = 12 + k
    zone, rt = plan.kinds[i], plan.rts[i]
    seen = cb.corners_in_view(D435, LAYOUT, rt)
    assert cb.HANGING_IN_VIEW[0] <= seen.mean() <= cb.HANGING_IN_VIEW[1]
    q = true_corners(D435, LAYOUT, rt)
    x0, y0, x1, y1 = cb.zone_box(zone, D435.imagersize())
    inside = seen & (q[..., 0] >= x0) & (q[..., 0] < x1) & (q[..., 1] >= y0) & (q[..., 1] < y1)
    assert inside.sum() >= 3, zone  # corners seen in the zone's outer 10 %
    anchor = cb._anchor(zone, D435.imagersize(), inset=20)[0]
    if "-" in zone:  # a corner zone: the board covers the image's corner
        assert cb.covers(D435, LAYOUT, rt, anchor)
    tilt = np.degrees(np.arccos(mrcal.rotate_point_r(rt[:3], np.array((0, 0, 1.0)))[2]))
    assert tilt > 5  # tilted (against the optical axis; 20-60 deg against the line of sight)


def test_covers_and_in_view_agree_with_the_projection():
    rt = cb.hanging_pose(D435, LAYOUT, "bottom-right", 3)
    q = true_corners(D435, LAYOUT, rt)
    seen = cb.corners_in_view(D435, LAYOUT, rt)
    W, H = D435.imagersize()
    assert np.all((q[seen] >= 10) & (q[seen] <= np.array((W - 11, H - 11))))
    assert not np.any(np.isfinite(q[~seen]).all(-1) & (q[~seen] >= 10).all(-1) & (q[~seen] <= (W - 11, H - 11)).all(-1))
    # a seen corner's pixel is covered by the board; the pixel at the far image corner is not
    assert cb.covers(D435, LAYOUT, rt, q[seen][:5]).all() and not cb.covers(D435, LAYOUT, rt, (5.0, 5.0))


def test_regions():
    r = cb.regions((1280, 800))
    assert r["corners"].tolist() == [[5, 5], [1274, 5], [5, 794], [1274, 794]]
    x, y = r["ring"].T
    assert np.all((x < 128) | (x > 1152) | (y < 80) | (y > 720)) and len(r["ring"]) > 500
    x, y = r["centre"].T
    assert np.all((abs(x - 640) < 128) & (abs(y - 400) < 80))


@pytest.fixture(scope="module")
def machinery(tmp_path_factory):
    """truth+noise corners (the machinery check), 10 poses of which 4 hang over the corners"""
    work = tmp_path_factory.mktemp("cov")
    return cb.run(str(work), n=10, hanging=4, seed=0, corners="truth+noise"), work


def test_machinery_end_to_end(machinery):
    r, work = machinery
    a, b = r.captures["whole"], r.captures["edges"]
    assert (a.poses, a.hanging, b.poses, b.hanging, b.hanging_used) == (10, 0, 10, 4, 4)
    assert a.lensmodel == b.lensmodel == "LENSMODEL_OPENCV8"
    assert b.ring_corners > a.ring_corners  # hanging boards put corners into the outer 10 %
    for c in (a, b):
        assert 0.005 < c.rms_px < 0.03  # noise 0.01 px per axis
        u, e = c.uncertainty, c.error
        assert u["centre_median"] < u["ring_median"] < max(u["corners"])  # worst where least was seen
        assert max(e["corners"]) < 0.5 and e["centre_median"] < 0.05  # an OPENCV8 fit of an OPENCV8 camera
    # the uncertainty is mrcal's, at the pixels named
    m = mrcal.cameramodel(b.model)
    q = cb.regions(m.imagersize())["corners"]
    v = mrcal.unproject(q, *m.intrinsics(), normalize=True)
    direct = mrcal.projection_uncertainty(v, model=m, atinfinity=True, what="worstdirection-stdev")
    assert np.allclose(direct, b.uncertainty["corners"], rtol=1e-6)
    ra = r.ratios()
    assert ra["uncertainty"]["ring_rms"] == pytest.approx(a.uncertainty["ring_rms"] / b.uncertainty["ring_rms"])
    assert ra["error"]["corners"][2] == pytest.approx(a.error["corners"][2] / b.error["corners"][2])


def test_truth_error_at_pixels_is_the_grid_comparison(machinery):
    """validate.truth.truth_error at given pixels: the same numbers as on its own grid"""
    from rotstar_mrcal.simulate import load_truth
    from rotstar_mrcal.evaluate.truth import truth_poses_of

    r, work = machinery
    m = mrcal.cameramodel(r.captures["edges"].model)
    t = load_truth(str(work / "seq"))
    rt = truth_poses_of(m, t.rt_cam_board)
    grid = truth_error(m, t.model, rt, gridn_width=16)
    at = truth_error(m, t.model, rt, q=grid.q[::3, ::5])
    assert np.allclose(at.error, grid.error[::3, ::5], rtol=1e-9) and at.rotation_deg == grid.rotation_deg
    with pytest.raises(ValueError, match="true poses"):
        truth_error(m, t.model, None, q=grid.q)


def test_machinery_table_says_it_is_no_result(machinery):
    r, work = machinery
    t = cb.table(r)
    assert t.splitlines()[0] == cb.MACHINERY_NOTE
    assert "| boards mrcal used (hanging) | 10 (0) | 10 (4) |  |" in t
    ok, line = cb.verdict(r)
    assert line.startswith("uncertainty at the imager corners") and ("NOT" in line) != ok
    assert "over 2 captures" in cb.verdict([r, r])[1]
    rows = cb.seeds_table([r, r]).splitlines()
    u = r.ratios()["uncertainty"]
    assert len(rows) == 4 and rows[2] == rows[3] and f"| {u['corners_mean']:.1f}x | {min(u['corners']):.1f}x |" in rows[2]
    fn = cb.figure(r, str(work / "fig.png"))
    assert os.path.getsize(fn) > 10_000


@pytest.mark.slow  # make test-slow: the coverage benchmark's driver, which make coverage-bench runs
def test_doc_refused_for_the_machinery_check(tmp_path):
    doc = os.path.join(ROOT, "doc", "uncertainty.md")
    before = open(doc).read()
    r = subprocess.run([sys.executable, os.path.join(ROOT, "scripts", "coverage_bench.py"), "--corners", "truth+noise",
                        "--poses", "6", "--hanging", "2", "--seeds", "0", "--work", str(tmp_path), "--doc"],
                       capture_output=True, text=True)
    assert r.returncode == 1 and "--doc refused: truth+noise" in r.stderr, r.stderr
    assert r.stdout.startswith(cb.MACHINERY_NOTE)
    assert open(doc).read() == before and (tmp_path / "results.json").exists()


@pytest.mark.slow  # make test-slow: an end-to-end run, left out of make test
def test_detected_on_a_small_camera(tmp_path):
    """rotstar's detection on rendered frames (640 x 400, a 6 x 4 board): every pose accounted for"""
    layout = make_layout(screen=(800, 600), pitch=100, band=24)
    r = cb.run(str(tmp_path), n=6, hanging=2, seed=0, corners="detect", camera="pinhole-small", layout=layout,
               lensmodel="LENSMODEL_PINHOLE", settings=Settings(bits=16, seed=0), jobs=2)
    a, b = r.captures["whole"], r.captures["edges"]
    assert a.boards == 6 and not a.missing and not a.sparse  # whole boards: all detected
    assert not b.missing and b.hanging_used + len(b.sparse) == 2  # each hanging pose: a board (maybe too few corners)
    assert b.boards == 4 + b.hanging_used
    assert np.isfinite(b.uncertainty["corners_mean"]) and a.error["centre_median"] < 0.1
    assert "MACHINERY" not in cb.table(r)

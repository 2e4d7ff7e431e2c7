"""validate.stereo and validate.depth: a stereo calibration against the truth, cross-validated, in depth terms"""

import mrcal
import numpy as np
import pytest

from rotstar_mrcal.simulate import preset_model
from rotstar_mrcal.evaluate import depth, stereo
from rotstar_mrcal.evaluate.stereo import shifted_pair

B = 0.050  # the D435's baseline
NX, NY, SPACING = 14, 9, 0.0144318182


def _true_pair():
    m = preset_model("d435")
    lens, intr = m.intrinsics()
    intr1 = intr.copy()
    intr1[:4] += (2.0, -1.5, 3.0, -2.0)
    m1 = mrcal.cameramodel(intrinsics=(lens, intr1), imagersize=m.imagersize())
    return shifted_pair(m, B, r=np.radians((0.1, -0.2, 0.05)), model1=m1)


def solve_pair(true, nframes=16, noise=0.02, seed=0, names=None):
    """A joint calibration of both cameras with mrcal.optimize on synthesized board observations

    What mrcal-calibrate-cameras does after corner detection, here on
    mrcal.synthesize_board_observations (boards both cameras see whole)
    with Gaussian corner noise; the models carry their optimization_inputs
    and image paths seq/poseNNN/camera-K/rotstar_00.png.
    """
    rng = np.random.default_rng(seed)
    np.random.seed(seed)  # mrcal draws the board poses from numpy's global generator
    q, Rt_ref_board = mrcal.synthesize_board_observations(
        list(true), object_width_n=NX, object_height_n=NY, object_spacing=SPACING, calobject_warp=None,
        rt_ref_boardcenter=np.array((0, 0, 0, 0, 0, 0.4)),
        rt_ref_boardcenter__noiseradius=np.array((*np.radians((30, 30, 20)), 0.2, 0.12, 0.1)),
        Nframes=nframes, which="all-cameras-must-see-full-board")
    n = len(q)
    obs = np.concatenate((q + rng.normal(0, noise, q.shape), np.ones(q.shape[:-1] + (1,))), axis=-1)
    intr = np.array([m.intrinsics()[1] for m in true])
    intr[:, :4] *= 1.01  # seeds off the truth
    intr[:, 4:] = 0
    oi = dict(intrinsics=intr, rt_cam_ref=np.array([[0, 0, 0, -B, 0, 0]], float),
              rt_ref_frame=mrcal.rt_from_Rt(Rt_ref_board) + 1e-3, points=None,
              observations_board=obs.reshape(n * 2, NY, NX, 3),
              indices_frame_camintrinsics_camextrinsics=np.array([(f, c, c - 1) for f in range(n) for c in range(2)],
                                                                 dtype=np.int32),
              observations_point=None, indices_point_camintrinsics_camextrinsics=None,
              lensmodel="LENSMODEL_OPENCV8", imagersizes=np.array([m.imagersize() for m in true]),
              calibration_object_spacing=SPACING, do_optimize_intrinsics_core=True,
              do_optimize_intrinsics_distortions=True, do_optimize_extrinsics=True, do_optimize_frames=True,
              do_optimize_calobject_warp=False, do_apply_regularization=True, do_apply_outlier_rejection=False)
    mrcal.optimize(**oi)
    names = names or [f"pose{f:03d}" for f in range(n)]
    oi["imagepaths"] = np.array([f"seq/{names[f]}/camera-{c}/rotstar_00.png" for f in range(n) for c in range(2)])
    models = tuple(mrcal.cameramodel(optimization_inputs=oi, icam_intrinsics=i) for i in range(2))
    return models, dict(zip(names, mrcal.rt_from_Rt(Rt_ref_board)))


@pytest.fixture(scope="module")
def solved():
    true = _true_pair()
    a, rt_a = solve_pair(true, seed=1)
    b, rt_b = solve_pair(true, seed=2, names=[f"pose{f:03d}" for f in range(100, 116)])
    return true, a, b, {**rt_a, **rt_b}


def test_extrinsics_error_components():
    true = shifted_pair(preset_model("d435"), B)
    cal = shifted_pair(preset_model("d435"), B, r=np.radians((0.02, 0, 0)))
    e = stereo.extrinsics_error(cal, true)
    assert e.baseline_error_mm == pytest.approx(0, abs=1e-9)
    assert e.rotation_error_xyz_deg == pytest.approx([0.02, 0, 0], abs=1e-9)
    # a baseline turned by 1 degree in the x-z plane: direction error 1 degree, length unchanged
    m0, m1 = shifted_pair(preset_model("d435"), B)
    c = B * np.array((np.cos(np.radians(1)), 0, np.sin(np.radians(1))))
    m1.rt_cam_ref(np.concatenate((np.zeros(3), -c)))
    e = stereo.extrinsics_error((m0, m1), true)
    assert e.direction_error_deg == pytest.approx(1.0, abs=1e-9)
    assert e.baseline_error_mm == pytest.approx(0, abs=1e-9)
    assert e.rotation_error_deg == pytest.approx(0, abs=1e-12)


def test_heldout_points_in_both_views():
    true = _true_pair()
    pts = depth.heldout_points(true, SPACING)
    assert sorted(pts) == [0.5, 1.0, 2.0]
    for z, p in pts.items():
        assert p.shape[1:] == (NY, NX, 3) and len(p) >= 5
        assert np.mean(p[..., 2]) == pytest.approx(z, rel=0.05)
        q = depth.project_pair(p, true)
        W, H = true[0].imagersize()
        assert np.all(q >= 0) and np.all(q[..., 0] < W) and np.all(q[..., 1] < H)


def test_perfect_calibration_has_no_depth_error():
    true = _true_pair()
    pts = depth.heldout_points(true, SPACING)
    for method in ("rectified", "triangulate"):
        e = depth.depth_error(pts, true, true, method=method)
        for z in pts:
            assert np.max(np.abs(e.error[z])) < 1e-6 * z
    e = depth.depth_error(pts, true, true)
    assert np.nanmax(np.abs(e.row_px[2.0])) < 1e-6  # the rectified rows agree


@pytest.mark.parametrize("dtheta_deg", [0.01, -0.02])
def test_yaw_error_gives_depth_error_growing_as_z_squared(dtheta_deg):
    """Camera 1 turned about the vertical axis by dtheta: disparity off by f dtheta, dZ = Z^2 dtheta / B"""
    true = shifted_pair(preset_model("d435"), B)
    cal = shifted_pair(preset_model("d435"), B, r=(0, np.radians(dtheta_deg), 0))
    pts = depth.heldout_points(true, SPACING)
    e = depth.depth_error(pts, true, cal)
    for z in pts:
        predicted = z**2 * np.radians(abs(dtheta_deg)) / B
        near_axis = np.all(np.abs(pts[z][..., :2] / pts[z][..., 2:]) < 0.1, axis=-1)  # off the axis: more
        assert np.mean(np.abs(e.error[z][near_axis])) == pytest.approx(predicted, rel=0.1), z
    # a turn about the vertical axis goes into the disparity (f dtheta), little into the rectified rows
    assert e.at(1.0)["row_rms_px"] < 0.3 * 640 * np.radians(abs(dtheta_deg))


def test_baseline_error_scales_depth():
    true = shifted_pair(preset_model("d435"), B)
    for dB in (0.0002, -0.0005):
        cal = shifted_pair(preset_model("d435"), B + dB)
        e = depth.depth_error(depth.heldout_points(true, SPACING), true, cal)
        for z in (0.5, 1.0, 2.0):
            assert e.at(z)["mean_pct"] == pytest.approx(100 * dB / B, rel=1e-3)
            assert e.at(z)["p95_pct"] == pytest.approx(100 * abs(dB) / B, rel=1e-3)


def test_pitch_error_breaks_the_rectified_rows():
    true = shifted_pair(preset_model("d435"), B)
    cal = shifted_pair(preset_model("d435"), B, r=(np.radians(0.05), 0, 0))
    e = depth.depth_error(depth.heldout_points(true, SPACING), true, cal)
    # about f * dtheta = 640 * 8.7e-4 = 0.56 px of row difference
    assert e.at(1.0)["row_rms_px"] == pytest.approx(640 * np.radians(0.05), rel=0.1)


def test_depth_noise_as_predicted():
    """Corner noise sigma on both pixels: depth noise ~ Z^2 sqrt(2) sigma / (f B)"""
    true = shifted_pair(preset_model("d435"), B)
    pts = depth.heldout_points(true, SPACING)
    e = depth.depth_error(pts, true, true, noise_px=0.1, rng=0)
    for z in pts:
        predicted = z**2 * np.sqrt(2) * 0.1 / (640 * B)
        assert np.sqrt(np.mean(e.error[z] ** 2)) == pytest.approx(predicted, rel=0.2)
    assert e.summary()["noise_px"] == 0.1


def test_triangulate_method_is_checked():
    true = shifted_pair(preset_model("d435"), B)
    with pytest.raises(ValueError, match="rectified"):
        depth.triangulate(np.zeros((1, 2, 2)), true, "sgbm")


def test_joint_calibration_against_truth(solved):
    true, a, _, rt = solved
    for k in (0, 1):
        e = stereo.camera_truth_error(a[k], true[k], rt)
        assert e.method == "procrustes"
        assert e.median < 0.15, k  # 0.02-0.07 px with these boards and 0.02 px of noise
    x = stereo.extrinsics_error(a, true)
    assert abs(x.baseline_error_mm) < 0.1 and x.rotation_error_deg < 0.01


def test_camera_truth_error_sees_a_wrong_lens(solved):
    """A model whose focal length is 0.3% off, with the solve's boards: the alignment keeps the boards, the error shows"""
    true, a, _, rt = solved
    oi = a[1].optimization_inputs()
    oi["intrinsics"][1, :2] *= 1.003
    bad = mrcal.cameramodel(optimization_inputs=oi, icam_intrinsics=1)
    assert stereo.camera_truth_error(bad, true[1], rt).median > 3 * stereo.camera_truth_error(a[1], true[1], rt).median


def test_frame_names(solved):
    _, a, _, rt = solved
    names = stereo.frame_names(a[0], rt)
    assert names[:3] == ["pose000", "pose001", "pose002"]
    assert stereo.frame_names(a[0], {"pose999": None}) == [None] * len(names)


def test_pair_crossval_and_depth_crossval(solved):
    true, a, b, _ = solved
    cv = stereo.pair_crossval(a, b, [0.5, 1.0, 2.0], gridn_width=20)
    assert [c["verdict"] for c in cv["cameras"]] != ["unknown", "unknown"]
    assert abs(cv["extrinsics"]["baseline_error_mm"]) < 0.2
    assert set(cv["pair_diff"]) == {"0.5", "1", "2"}
    d = depth.depth_crossval(a, b, [0.5, 2.0], gridn_width=5)
    for z in ("0.5", "2"):
        assert d[z]["unc_median_mm"] > 0 and np.isfinite(d[z]["ratio_median"])
    # depth differences grow with depth; so do their uncertainties
    assert d["2"]["diff_median_mm"] > d["0.5"]["diff_median_mm"]
    assert d["2"]["unc_median_mm"] > d["0.5"]["unc_median_mm"]
    # with noise only between them, the two calibrations are consistent (ratio ~ 1, not 10)
    assert d["0.5"]["ratio_median"] < 3


def test_depth_uncertainty_matches_the_spread_of_recalibrations():
    """mrcal's calibration-time depth uncertainty against the scatter of depth over independent recalibrations"""
    true = _true_pair()
    p = np.array(((0.0, 0.0, 1.0), (0.2, 0.1, 1.0)))
    z, sig = [], []
    for seed in range(6):
        m, _ = solve_pair(true, nframes=10, noise=0.05, seed=10 + seed)
        z.append(depth.triangulate(depth.project_pair(p, true), m, "triangulate").p[:, 2])
        sig.append(depth.depth_uncertainty(p, m))
    spread, predicted = np.std(z, axis=0, ddof=1), np.mean(sig, axis=0)
    assert np.all(spread < 3 * predicted) and np.all(spread > predicted / 3)


def test_evaluate_summary(solved):
    import json

    true, a, b, rt = solved
    pts = depth.heldout_points(true, SPACING, across=2)
    s = stereo.evaluate("rotstar", {"A": a, "B": b}, true, rt, pts, noise_px=0.02, gridn_width=10)
    json.dumps(s)  # JSON-able
    assert s["calibration"]["A"][0]["boards"] == 16 and s["calibration"]["A"][1]["rms_px"] < 0.05
    t = s["truth"]["A"]
    assert len(t["cameras"]) == 2 and t["cameras"][0]["median_px"] < 0.15
    assert set(t["depth"]["depths"]) == {"0.5", "1", "2"}
    assert t["depth_noisy"]["noise_px"] == 0.02
    assert set(s["crossval"]) == {"cameras", "extrinsics", "pair_diff", "depth"}


@pytest.fixture(scope="module")
def stereo_result(solved):
    true, a, b, rt = solved
    pts = depth.heldout_points(true, SPACING, across=2)
    m = stereo.evaluate("rotstar", {"A": a, "B": b}, true, rt, pts, noise_px=0.02, gridn_width=10)
    m["corner_rms_px"] = 0.02
    return {"format": "rotstar-stereo/1", "label": "synthetic pair", "distances": sorted(pts),
            "setup": "Two OPENCV8 cameras 50 mm apart.", "methods": [m]}


def test_stereo_report_section(stereo_result, tmp_path, capsys):
    import json
    import os

    from rotstar_mrcal.cli.report import main
    from rotstar_mrcal.report import stereo as stereoreport

    d = tmp_path / "stereo"
    os.makedirs(d)
    json.dump(stereo_result, open(d / "results.json", "w"))
    assert main([str(d), "--out", str(tmp_path / "r"), "--no-mrcal-figures"]) == 0
    md = open(tmp_path / "r" / "index.md").read()
    assert "## Stereo: synthetic pair" in md and "### Depth error" in md and "### Cross-validation (A against B)" in md
    row = next(r for r in stereoreport.headline(stereo_result).rows if r[0] == "rotstar")
    assert "| " + " | ".join(row) + " |" in md  # the numbers of the result, in the page
    assert "depth RMS at 2 m, mm" in capsys.readouterr().out  # the headline on stdout
    assert "<h2>Stereo: synthetic pair</h2>" in open(tmp_path / "r" / "index.html").read()
    assert json.load(open(tmp_path / "r" / "results.json"))["stereo"][0]["label"] == "synthetic pair"
    # a stereo results file without its methods is bad input, named
    json.dump({"format": "rotstar-stereo/1"}, open(d / "results.json", "w"))
    assert main([str(d), "--out", str(tmp_path / "r2")]) == 2
    assert "results.json: a rotstar-stereo results file without its methods" in capsys.readouterr().err


@pytest.mark.slow
def test_make_stereo_quick(tmp_path):
    """scripts/stereo.py --quick end to end: simulate the D435 rig, detect, calibrate, evaluate, report"""
    import json
    import os
    import subprocess
    import sys

    from conftest import cli_env

    script = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "scripts", "stereo.py")
    r = subprocess.run([sys.executable, script, "--quick", "--no-docs", "--out", str(tmp_path)], capture_output=True,
                       text=True, env=cli_env(), timeout=900)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "### Depth error" in r.stdout and "$ rotstar-simulate --rig d435" in r.stderr
    res = json.load(open(tmp_path / "stereo" / "results.json"))
    by = {m["method"]: m for m in res["methods"]}
    assert set(by) == {"rotstar", "saddle"}
    for g in "AB":
        t = by["rotstar"]["truth"][g]
        assert all(c["median_px"] < 0.1 for c in t["cameras"])
        assert abs(t["extrinsics"]["baseline_error_mm"]) < 0.1 and t["extrinsics"]["rotation_error_deg"] < 0.02
        assert t["depth"]["depths"]["2"]["rms_pct"] < 1.0  # far inside the D435's 2 % at 2 m
    assert by["rotstar"]["corner_rms_px"] < by["saddle"]["corner_rms_px"]
    assert "## Stereo: simulated D435 infrared pair" in open(tmp_path / "report" / "index.md").read()

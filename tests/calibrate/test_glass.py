"""calibrate.glass: a solved calibration corrected for a screen's cover glass, its thickness estimated"""

from __future__ import annotations

import json
import os

import mrcal
import numpy as np
import pytest

from rotstar_mrcal import dataset as ds
from rotstar_mrcal.calibrate.glass import MIN_SIGMAS, GlassResult, correct_glass, observation_shift
from rotstar_mrcal.cli.calibrate import main as calibrate_main
from rotstar_mrcal.cli.glass import main as glass_main
from rotstar_mrcal.evaluate.truth import truth_error
from rotstar_mrcal.optics.refraction import Glass, apparent_points
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.simulate.camera import preset_model
from rotstar_mrcal.simulate.poses import random_poses
from rotstar_mrcal.vnl import read_corners, write_corners

MODEL, LAYOUT = preset_model("d435"), make_layout()
N = 14
RTS = random_poses(MODEL, LAYOUT, N, np.random.default_rng([0, 5]), max_tilt_deg=60)


def seen_through(t_mm: float, noise: float = 0.005) -> np.ndarray:
    """Exact corners of every pose through t_mm of glass, plus noise: (N, ny, nx, 2)"""
    c = mrcal.transform_point_rt(mrcal.invert_rt(RTS), np.zeros(3))
    a = apparent_points(c[:, None, None, :], LAYOUT.board_points()[None], Glass.mm(t_mm))
    q = mrcal.project(mrcal.transform_point_rt(RTS[:, None, None, :], a), *MODEL.intrinsics())
    return q + np.random.default_rng(7).normal(0, noise, q.shape)


def problem(q: np.ndarray) -> dict:
    """mrcal's optimization inputs for corners q, the state seeded near the truth"""
    lm, intr = MODEL.intrinsics()
    idx = np.column_stack((np.arange(N), np.zeros(N), -np.ones(N))).astype(np.int32)
    return dict(intrinsics=intr[None] * (1 + 1e-3), rt_cam_ref=np.zeros((0, 6)), rt_ref_frame=RTS.copy(),
                points=None, observations_board=np.concatenate((q, np.ones(q.shape[:-1] + (1,))), axis=-1),
                indices_frame_camintrinsics_camextrinsics=idx, observations_point=None,
                indices_point_camintrinsics_camextrinsics=None, lensmodel=lm,
                imagersizes=MODEL.imagersize()[None].astype(np.int32), calobject_warp=np.zeros(2),
                do_optimize_intrinsics_core=True, do_optimize_intrinsics_distortions=True,
                do_optimize_extrinsics=True, do_optimize_frames=True, do_optimize_calobject_warp=True,
                calibration_object_spacing=LAYOUT.spacing_m, do_apply_outlier_rejection=False,
                do_apply_regularization=True, verbose=False)


def solved(t_mm: float) -> mrcal.cameramodel:
    """A plain calibration (mrcal.optimize) of the corners seen through t_mm of glass"""
    oi = problem(seen_through(t_mm))
    mrcal.optimize(**oi)
    return mrcal.cameramodel(optimization_inputs=oi, icam_intrinsics=0)


def error(model) -> float:
    return truth_error(model, MODEL, RTS).median


def test_the_shift_moves_observations_onto_the_emitting_points():
    """At the true state, raw observations through the glass plus the shift are the true projections"""
    oi = problem(seen_through(1.2, noise=0.0))
    oi["intrinsics"] = MODEL.intrinsics()[1][None].copy()
    shift = observation_shift(oi, Glass.mm(1.2))
    true = mrcal.project(mrcal.transform_point_rt(RTS[:, None, None, :], LAYOUT.board_points()),
                         *MODEL.intrinsics())
    assert np.max(np.abs(shift)) > 0.2  # the glass moves corners by tenths of a pixel at these tilts
    assert np.max(np.abs(oi["observations_board"][..., :2] + shift - true)) < 1e-9


@pytest.fixture(scope="module")
def glass1():
    m = solved(1.0)
    return m, correct_glass(m)


def test_a_glass_is_estimated_and_taken_out(glass1):
    plain, g = glass1
    assert g.applied and not g.given
    assert 0.01 < g.sigma_mm < 0.2
    assert abs(g.thickness_mm - 1.0) < max(0.1, 2 * g.sigma_mm)
    assert error(g.model) < 0.5 * error(plain)  # measured: 0.033 vs 0.204 px (14 poses)
    assert g.rms_after_px < g.rms_before_px
    assert "applied" in g.line() and g.to_json()["thickness_mm"] == g.thickness_mm


def test_no_glass_comes_out_as_none_and_the_model_unchanged():
    m = solved(0.0)
    g = correct_glass(m)
    assert not g.applied and abs(g.thickness_mm) < MIN_SIGMAS * g.sigma_mm and "no glass" in g.reason
    assert g.model is m


def test_a_given_thickness_is_applied_as_given(glass1):
    plain, _ = glass1
    g = correct_glass(plain, thickness_mm=1.0)
    assert g.applied and g.given and g.thickness_mm == 1.0
    assert error(g.model) < 0.5 * error(plain)
    off = correct_glass(plain, thickness_mm=0.0)
    assert not off.applied and off.model is plain


def test_an_implausible_thickness_is_reported_not_applied():
    m = solved(4.5)
    g = correct_glass(m)
    assert g.thickness_mm > 3 and not g.applied and g.model is m
    assert "another pose-dependent error" in g.reason


def _write_case(folder, q) -> str:
    """A folder with pattern.json, truth.cameramodel (for the imager size) and corners.vnl of corners q"""
    os.makedirs(folder, exist_ok=True)
    ds.write_pattern(folder, LAYOUT)
    MODEL.write(os.path.join(folder, "truth.cameramodel"))
    vnl = os.path.join(folder, "corners.vnl")
    with open(vnl, "w") as f:
        write_corners(f, [(f"pose{i:03d}/rotstar_00.png", c) for i, c in enumerate(q)])
    return vnl


def test_rotstar_calibrate_estimates_and_stores_the_glass(tmp_path, capsys):
    vnl = _write_case(str(tmp_path / "seq"), seen_through(1.0))
    out = str(tmp_path / "cal")
    rc = calibrate_main([str(tmp_path / "seq"), "--corners", vnl, "--outdir", out, "--lensmodel", "opencv8"])
    assert rc == 0
    d = json.load(open(os.path.join(out, "calibration.json")))["glass"]
    assert d["applied"] and abs(d["thickness_mm"] - 1.0) < max(0.1, 2 * d["sigma_mm"])
    assert d["model"].endswith(os.path.join("candidates", "glass", "camera-0.cameramodel"))
    assert "cover glass (index 1.5): " in capsys.readouterr().err
    m = mrcal.cameramodel(os.path.join(out, "camera-0.cameramodel"))
    assert np.array_equal(m.intrinsics()[1], mrcal.cameramodel(d["model"]).intrinsics()[1])


@pytest.mark.parametrize("bad", [["--glass", "-1"], ["--glass", "6"], ["--glass", "thick"], ["--glass-index", "0.5"]])
def test_rotstar_calibrate_bad_glass(bad, tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        calibrate_main([str(tmp_path), *bad])
    assert e.value.code == 2
    assert capsys.readouterr().err.strip().splitlines()[-1].startswith(f"rotstar-calibrate: error: argument {bad[0]}")


RT_CAM1_REF = np.array((0.0, 0.01, 0.0, -0.05, 0.0, 0.0))


@pytest.fixture(scope="module")
def rig_plain():
    """Two cameras 50 mm apart see the same boards through 1 mm of glass, calibrated plainly (mrcal.optimize)"""
    rt_cam1_ref = RT_CAM1_REF = np.array((0.0, 0.01, 0.0, -0.05, 0.0, 0.0))
    qs, idx = [], []
    for k, rt_ref in enumerate((np.zeros(6), rt_cam1_ref)):
        rts = mrcal.compose_rt(rt_ref, RTS)
        c = mrcal.transform_point_rt(mrcal.invert_rt(rts), np.zeros(3))
        a = apparent_points(c[:, None, None, :], LAYOUT.board_points()[None], Glass.mm(1.0))
        qs.append(mrcal.project(mrcal.transform_point_rt(rts[:, None, None, :], a), *MODEL.intrinsics()))
        idx.append(np.column_stack((np.arange(N), np.full(N, k), np.full(N, k - 1))))
    idx = np.concatenate(idx)
    order = np.argsort(idx[:, 0], kind="stable")  # mrcal wants the observations frame by frame
    q = np.concatenate(qs)[order] + np.random.default_rng(8).normal(0, 0.005, (2 * N, LAYOUT.ny, LAYOUT.nx, 2))
    oi = problem(q[:N])
    oi.update(observations_board=np.concatenate((q, np.ones(q.shape[:-1] + (1,))), axis=-1),
              indices_frame_camintrinsics_camextrinsics=idx[order].astype(np.int32),
              intrinsics=np.repeat(oi["intrinsics"], 2, axis=0), rt_cam_ref=(rt_cam1_ref * 1.01)[None],
              imagersizes=np.repeat(oi["imagersizes"], 2, axis=0))
    mrcal.optimize(**oi)
    return [mrcal.cameramodel(optimization_inputs=oi, icam_intrinsics=k) for k in (0, 1)]


def _rig_corrected(plain, g):
    fixed = g.models(plain)
    for k in (0, 1):
        assert error(fixed[k]) < 0.5 * error(plain[k])
    base = lambda m: m.extrinsics_rt_fromref()[3:]  # noqa: E731
    assert np.linalg.norm(base(fixed[1]) - RT_CAM1_REF[3:]) < np.linalg.norm(base(plain[1]) - RT_CAM1_REF[3:])


def test_a_rig_is_corrected_with_one_thickness(rig_plain):
    g = correct_glass(rig_plain[0], thickness_mm=1.0)
    assert g.applied and g.given
    _rig_corrected(rig_plain, g)


@pytest.mark.slow
def test_a_rigs_thickness_is_estimated(rig_plain):
    """(9 s) the estimate, its halves split by board pose, both cameras"""
    g = correct_glass(rig_plain[0])
    assert g.applied and abs(g.thickness_mm - 1.0) < max(0.1, 2 * g.sigma_mm) and g.halves is not None
    _rig_corrected(rig_plain, g)


def _model_file(tmp_path, t_mm: float) -> str:
    """A plain calibration through t_mm of glass, written with the image path of every board"""
    oi = problem(seen_through(t_mm))
    oi["imagepaths"] = np.array([f"pose{i:03d}/rotstar_00.png" for i in range(N)])
    mrcal.optimize(**oi)
    fn = str(tmp_path / f"first-{t_mm:g}.cameramodel")
    mrcal.cameramodel(optimization_inputs=oi, icam_intrinsics=0).write(fn)
    return fn


def _rms_vs_emitting(out: str) -> float:
    with open(out) as f:
        boards = read_corners(f, LAYOUT.nx, LAYOUT.ny)
    got = np.stack([boards[f"pose{i:03d}/rotstar_00.png"] for i in range(N)])
    true = mrcal.project(mrcal.transform_point_rt(RTS[:, None, None, :], LAYOUT.board_points()), *MODEL.intrinsics())
    return float(np.sqrt(np.mean((got - true) ** 2)))


def test_rotstar_glass_writes_the_corrected_corners(tmp_path, capsys):
    """The plain mrcal path: a first calibration's corners moved to where the emitting points are seen"""
    first, out = _model_file(tmp_path, 1.0), str(tmp_path / "corrected.vnl")
    true = mrcal.project(mrcal.transform_point_rt(RTS[:, None, None, :], LAYOUT.board_points()), *MODEL.intrinsics())
    raw = float(np.sqrt(np.mean((seen_through(1.0) - true) ** 2)))
    assert glass_main([first, "-o", out]) == 0
    io = capsys.readouterr()
    assert io.out.strip() == out and "applied" in io.err and "--corners-cache" in io.err
    # measured: raw 0.434 px RMS from the emitting points' projections; corrected 0.037 (the estimate 1.084 mm)
    assert _rms_vs_emitting(out) < raw / 4
    assert glass_main([first, "-o", out, "--glass", "1.0"]) == 0
    assert _rms_vs_emitting(out) < 0.01  # the true thickness: the noise is what is left (measured 0.0049 px)


def test_rotstar_glass_without_glass_or_a_model(tmp_path, capsys):
    out = str(tmp_path / "corrected.vnl")
    assert glass_main([_model_file(tmp_path, 0.0), "-o", out]) == 1 and not os.path.exists(out)
    assert "nothing written" in capsys.readouterr().err
    assert glass_main([str(tmp_path / "none.cameramodel"), "-o", out]) == 2
    assert capsys.readouterr().err.strip().startswith("rotstar-glass: ") and not os.path.exists(out)


def test_the_json_has_no_nan():
    g = GlassResult(float("nan"), float("nan"), 1.5, False, False, "the fit's cost has no minimum", 0.01, 0.01,
                    {0.0: 2.0, 1.0: 1.0}, [[float("nan"), 0.1], [0.5, 0.1]])
    d = json.loads(json.dumps(g.to_json(), allow_nan=False))
    assert d["thickness_mm"] is None and d["halves"] == [[None, 0.1], [0.5, 0.1]] and d["costs"] == {"0": 2.0, "1": 1.0}
    assert g.line().startswith("cover glass (index 1.5): no estimate; not applied: ")

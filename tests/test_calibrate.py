"""rotstar-calibrate on a rendered simulated D435 dataset (tests/conftest.py: d435_seq)"""

from __future__ import annotations

import os

import mrcal
import pytest

from rotstar_mrcal.cli.calibrate import resolve_lensmodel
from rotstar_mrcal.simulate import load_truth
from rotstar_mrcal.validate.truth import truth_error, truth_poses_of


@pytest.fixture(scope="module")
def calibrated(d435_seq, run_cli, tmp_path_factory):
    out = tmp_path_factory.mktemp("cal") / "cal"
    r = run_cli("rotstar-calibrate", d435_seq.path, "--outdir", out, "--lensmodel", "opencv5", "--jobs", "2")
    assert r.returncode == 0, r.stderr
    return r, out


def test_detects_calibrates_and_prints_what_it_runs(calibrated, d435_seq):
    r, out = calibrated
    model_path = r.stdout.strip()
    assert model_path == os.path.join(out, "camera-0.cameramodel") and os.path.exists(model_path)
    cmds = [line for line in r.stderr.splitlines() if line.startswith("$ ")]
    assert cmds[0].startswith("$ rotstar-detect ") and cmds[1].startswith("$ mrcal-calibrate-cameras ")
    assert "--object-width-n 14 --object-height-n 9" in cmds[1] and "--imagersize 1280 800" in cmds[1]
    assert "--lensmodel LENSMODEL_OPENCV5" in cmds[1] and "'*/rotstar_00.png'" in cmds[1]
    model = mrcal.cameramodel(model_path)
    truth = load_truth(d435_seq.path)
    e = truth_error(model, truth.model, truth_poses_of(model, truth.rt_cam_board))
    assert e.median < 0.05 and e.method == "procrustes"


def test_default_is_the_splined_model_with_a_warning(calibrated, d435_seq, run_cli, tmp_path):
    _, out = calibrated
    r = run_cli("rotstar-calibrate", d435_seq.path, "--corners", os.path.join(out, "corners.vnl"),
                "--outdir", tmp_path, "--dry-run")
    assert r.returncode == 0, r.stderr
    assert "LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx=16_Ny=10_fov_x_deg=" in r.stderr
    assert "warning" in r.stderr and "rotstar-detect" not in r.stderr  # no detection with --corners
    assert not os.path.exists(tmp_path / "camera-0.cameramodel")


def test_lensmodel_names():
    assert resolve_lensmodel("opencv8", (1280, 800), 640) == "LENSMODEL_OPENCV8"
    assert resolve_lensmodel("LENSMODEL_CAHVOR", (1280, 800), 640) == "LENSMODEL_CAHVOR"
    assert resolve_lensmodel("splined", (1000, 1000), 500, knots_x=12).startswith(
        "LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx=12_Ny=12_fov_x_deg=")
    with pytest.raises(ValueError):
        resolve_lensmodel("fisheye", (1280, 800), 640)


def test_bad_dataset(run_cli, tmp_path):
    r = run_cli("rotstar-calibrate", tmp_path)
    assert r.returncode == 2 and "pattern.json" in r.stderr


def test_detection_hint_is_not_repeated(calibrated):
    r, _ = calibrated  # rotstar-calibrate runs the calibration itself: no "next, calibrate with" advice
    assert "next, calibrate with" not in r.stderr

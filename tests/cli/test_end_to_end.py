"""The whole chain as the README tells a user to run it, checked against the simulated camera

simulated D435 capture (tests/conftest.py: 12 poses over the imager, 16-bit)
-> rotstar-detect seq > corners.vnl -> the mrcal-calibrate-cameras command it
prints (run as printed, but with --outdir a temporary folder) -> the calibrated
camera-0.cameramodel compared with seq/truth.cameramodel.

Measured (mrcal 2.5, 11 of 12 poses detected; the 60-degree pose is skipped):
projection difference over the imager median 0.0052 px, p95 0.015 px, max
0.017 px; board residual RMS 0.0052 px (2-D); fx, fy, cx, cy within 0.004 px.
"""

from __future__ import annotations

import os
import re
import shlex

import mrcal
import numpy as np
import pytest

from conftest import ROLES


@pytest.fixture(scope="module")
def calibration(d435_seq, run_cli, tmp_path_factory):
    work = tmp_path_factory.mktemp("e2e")
    det = run_cli("rotstar-detect", "--jobs", "2", d435_seq.path, cwd=work)
    assert det.returncode == 0, det.stderr
    (work / "corners.vnl").write_text(det.stdout)
    cmd = shlex.split(det.stderr.split("next, calibrate with:\n", 1)[1].strip().splitlines()[0])
    assert cmd[0] == "mrcal-calibrate-cameras" and cmd.count("--outdir") == 1
    outdir = work / "cal"
    outdir.mkdir()
    cmd[cmd.index("--outdir") + 1] = str(outdir)
    cal = run_cli(*cmd, cwd=work)
    assert cal.returncode == 0, cal.stdout + cal.stderr
    return det, cal, mrcal.cameramodel(str(outdir / "camera-0.cameramodel"))


def boards_found(det) -> int:
    m = re.search(r"rotstar-detect: (\d+) of (\d+) poses gave a board", det.stderr)
    assert m, det.stderr
    return int(m.group(1))


def test_detection_finds_the_boards(calibration, d435_seq):
    det, _, _ = calibration
    assert boards_found(det) >= len(d435_seq.poses) - 1
    for pose in d435_seq.poses:
        if pose != ROLES["steep60"]:  # see test_detect.py::test_detect_pose_steep60
            assert f"{pose}: 126 of 126 corners" in det.stderr


def test_calibration_recovers_the_camera(calibration, d435_seq):
    _, _, model = calibration
    true_model = mrcal.cameramodel(os.path.join(d435_seq.path, "truth.cameramodel"))
    assert model.intrinsics()[0] == true_model.intrinsics()[0] == "LENSMODEL_OPENCV8"
    assert np.array_equal(model.imagersize(), true_model.imagersize())
    # fx, fy, cx, cy (measured: within 0.004 px)
    assert np.allclose(model.intrinsics()[1][:4], true_model.intrinsics()[1][:4], atol=0.1)
    # the same projection over the whole imager, after the best-fitting rotation (measured:
    # median 0.0052 px, p95 0.015 px, max 0.017 px)
    diff, *_ = mrcal.projection_diff((true_model, model), gridn_width=40, use_uncertainties=False)
    assert np.median(diff) < 0.03
    assert np.percentile(diff, 95) < 0.1


def test_calibration_residuals(calibration, d435_seq):
    det, cal, model = calibration
    oi = model.optimization_inputs()
    # every detected pose was used; mrcal's outlier rejection is relative to the fitted sigma
    # (0.005 px here), so a handful of 3-sigma corners may go, but no more than 1%
    assert oi["observations_board"].shape[0] == boards_found(det)
    assert np.mean(oi["observations_board"][..., 2] <= 0) < 0.01
    res = mrcal.measurements_board(oi)
    rms = np.sqrt(np.mean(np.sum(res**2, axis=-1)))
    # measured: 0.005 px (2-D RMS), like the detector's error against the truth
    assert rms < 0.02

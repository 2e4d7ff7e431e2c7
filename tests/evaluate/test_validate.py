"""Validation with mrcal (rotstar_mrcal.calibrate and rotstar_mrcal.evaluate) on corners simulated from a known camera

The corner-level datasets here are what a detector would write for the
`d435` camera at random poses: the true projections plus Gaussian noise, in a
folder laid out like a simulated dataset (pattern.json, truth.cameramodel,
truth.json, corners.vnl; no images). Calibrations are real
mrcal-calibrate-cameras runs.
"""

from __future__ import annotations

import os

import mrcal
import numpy as np
import pytest

from rotstar_mrcal import dataset, simulate
from rotstar_mrcal.calibrate.solve import calibration_argv
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.simulate.dataset import Truth, write_truth
from rotstar_mrcal.calibrate import solve as cal
from rotstar_mrcal.evaluate.crossval import cross_validate
from rotstar_mrcal.evaluate.heldout import heldout
from rotstar_mrcal.calibrate.cornerset import load_corner_set
from rotstar_mrcal.evaluate.truth import truth_error, truth_poses_of

LENSMODEL = "LENSMODEL_OPENCV5"  # the d435 preset's lens has no rational terms: OPENCV5 is exact


def perturbed(model, index=4, delta=0.01):
    """The model with one intrinsic changed (index 4: k1)"""
    lens, intr = model.intrinsics()
    intr = intr.copy()
    intr[index] += delta
    return mrcal.cameramodel(intrinsics=(lens, intr), imagersize=model.imagersize())


def corner_dataset(path, n, seed, sigma=0.1, lens=None, layout=None, noise_seed=None, vnl="corners.vnl"):
    """A folder like a simulated dataset with a corners.vnl of noisy true corners; returns the vnl

    seed picks the poses, noise_seed (default: seed) the noise. lens: the
    camera that 'took' the corners (default: the d435 preset, which is also
    what truth.cameramodel says).
    """
    model, layout = simulate.preset_model("d435"), layout or make_layout()
    lens = lens or model
    rts = simulate.random_poses(model, layout, n, np.random.default_rng([7, seed]))
    os.makedirs(path, exist_ok=True)
    dataset.write_pattern(path, layout)
    model.write(os.path.join(path, "truth.cameramodel"))
    names = simulate.pose_names(n)
    truth = {k: simulate.true_corners(model, layout, r) for k, r in zip(names, rts)}
    write_truth(path, Truth(model, layout, dict(zip(names, rts)), truth, {"sigma": sigma}))
    rng = np.random.default_rng([8, seed if noise_seed is None else noise_seed])
    from rotstar_mrcal.vnl import write_corners

    vnl = os.path.join(path, vnl)
    with open(vnl, "w") as f:
        write_corners(f, [(f"{k}/rotstar_00.png",
                           simulate.true_corners(lens, layout, r) + rng.normal(0, sigma, truth[k].shape))
                          for k, r in zip(names, rts)])
    return vnl


def calibrate(vnl, outdir, in_process=True):
    cs = load_corner_set(vnl)
    return cal.run_calibration(calibration_argv(cs, outdir, LENSMODEL), in_process=in_process), cs


@pytest.fixture(scope="module")
def two_calibrations(tmp_path_factory):
    """Two independent 20-pose calibrations of the same simulated camera, and one of another lens"""
    root = tmp_path_factory.mktemp("xval")
    out = []
    for seed, lens in ((1, None), (2, None), (3, perturbed(simulate.preset_model("d435")))):
        vnl = corner_dataset(str(root / f"s{seed}"), 20, seed, lens=lens)
        out.append(calibrate(vnl, str(root / f"s{seed}" / "cal"), in_process=seed != 1))
    return out


def test_heldout_is_the_noise_floor_with_the_true_model_and_grows_with_a_wrong_one():
    model, layout = simulate.preset_model("d435"), make_layout()
    rts = simulate.random_poses(model, layout, 8, np.random.default_rng(3))
    sigma = 0.05
    corners = simulate.true_corners(model, layout, rts) + np.random.default_rng(4).normal(0, sigma, (8, 9, 14, 2))
    corners[2, 3, 4] = np.nan  # a missing corner
    corners[5, :, :10] = np.nan  # a board with 36 of 126 corners
    corners[6] = np.nan  # a pose without a board
    h = heldout(model, corners, layout.spacing_m)
    floor = np.sqrt(np.pi / 2) * sigma  # mean of a 2-D Gaussian's radius; the pose fit takes a little
    assert 0.85 * floor < h.mean < 1.05 * floor
    assert h.boards == 7 and np.isnan(h.per_pose[6]) and np.isnan(h.errors[2, 3, 4])
    assert h.points == 7 * 126 - 1 - 90
    wrong = heldout(perturbed(model, 4, -0.1), corners, layout.spacing_m)
    assert wrong.mean > 5 * h.mean
    # the seed pose and the solved pose agree with the truth for the true model
    assert np.allclose(h.rt_cam_frame[0, 3:], rts[0, 3:], atol=2e-3)


def test_calibration_recovers_the_camera(two_calibrations):
    (m1, cs1), _, _ = two_calibrations
    stats = cal.calibration_stats(m1)
    assert stats["boards"] == 20 and stats["lensmodel"] == LENSMODEL
    assert 0.1 < stats["rms_px"] < 0.16  # 2-D RMS of sigma = 0.1 per axis: sqrt(2) * 0.1, less the fit
    e = truth_error(m1, cs1.truth.model, truth_poses_of(m1, cs1.truth.rt_cam_board))
    assert e.method == "procrustes" and e.median < 0.5
    lazy = truth_error(m1, cs1.truth.model)  # without the poses: projection_diff
    assert lazy.method == "projection_diff" and lazy.median < 0.5


def test_diff_of_two_calibrations_of_one_camera_is_within_their_uncertainty(two_calibrations):
    (m1, _), (m2, _), _ = two_calibrations
    x = cross_validate(m1, m2, gridn_width=30)
    assert x.diff.shape == x.u0.shape == x.u1.shape == (19, 30)
    assert x.ratio_median < 1 and x.verdict == "consistent"
    assert np.mean(x.diff < x.u0 + x.u1) > 0.9  # nearly everywhere, not only in the median
    assert x.rotation_deg < 0.5


def test_a_different_lens_is_flagged(two_calibrations):
    (m1, _), _, (m3, _) = two_calibrations
    x = cross_validate(m1, m3, gridn_width=30)
    assert x.ratio_median > 2 and x.verdict == "model errors"


def test_weights_column_is_passed_to_mrcal(tmp_path):
    vnl = corner_dataset(str(tmp_path / "w"), 3, 5)
    with open(vnl) as f:
        text = f.read().replace("# filename x y level", "# filename x y weight")
    with open(vnl, "w") as f:
        f.write(text.replace(" 0.5\n", " 1\n"))
    cs = load_corner_set(vnl)
    argv = calibration_argv(cs, str(tmp_path / "cal"), LENSMODEL, focal=640)
    assert cs.weights and argv[1] == "--corners-cache-has-weights"
    assert argv[-1] == "*/rotstar_00.png" and argv[argv.index("--imagersize") + 1:][:2] == ["1280", "800"]


def test_failed_calibration_is_reported(tmp_path):
    vnl = corner_dataset(str(tmp_path / "bad"), 2, 6)
    cs = load_corner_set(vnl)
    argv = calibration_argv(cs, str(tmp_path / "cal"), "LENSMODEL_NO_SUCH_MODEL", focal=640)
    for in_process in (False, True):
        with pytest.raises(cal.CalibrationError, match="exited with"):
            cal.run_calibration(argv, in_process=in_process)


def test_in_process_calibration_leaves_numpy_print_options_alone(tmp_path):
    before = np.get_printoptions()
    vnl = corner_dataset(str(tmp_path / "p"), 4, 9)
    calibrate(vnl, str(tmp_path / "cal"), in_process=True)
    assert np.get_printoptions() == before

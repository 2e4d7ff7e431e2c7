"""Several cameras: the multi-camera dataset layout, rotstar-simulate --rig, rotstar-detect and rotstar-calibrate

One small simulated rig (the d435-small preset: two 640x400 infrared imagers
50 mm apart, each with its own lens and PSF) is rendered once per session;
it is detected and calibrated with real mrcal and compared with its truth.
The layout errors are checked on tiny hand-made datasets.
"""

from __future__ import annotations

import json
import os
import shutil

import cv2
import mrcal

from rotstar_mrcal.calibrate.solve import board_residuals
import numpy as np
import pytest

from conftest import huge_png
from rotstar_mrcal import dataset
from rotstar_mrcal.cli import calibrate as calibrate_cli
from rotstar_mrcal.cli import detect as detect_cli
from rotstar_mrcal.detect.rig import labelling_agrees
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.simulate.dataset import Settings
from rotstar_mrcal.simulate.rig import load_rig_truth, rig_cameras, rig_poses, write_rig_dataset
from rotstar_mrcal.vnl import read_corners

NPOSES = 8


@pytest.fixture(scope="module")
def rig_seq(tmp_path_factory):
    """A two-camera simulated dataset (d435-small), pose002's camera-1 folder removed (that camera missed it)"""
    seq = str(tmp_path_factory.mktemp("rig") / "seq")
    layout = make_layout()
    cams = rig_cameras("d435-small", seed=3)
    rt, seen = rig_poses(cams, layout, NPOSES, np.random.default_rng([0, 3]))
    seen[2, 1] = True  # rendered, then removed below: the truth keeps it
    write_rig_dataset(seq, layout, cams, rt, seen, Settings(supersample=2, seed=3))
    shutil.rmtree(os.path.join(seq, "pose002", "camera-1"))
    return seq


@pytest.fixture(scope="module")
def detected(rig_seq, tmp_path_factory):
    """rotstar-detect's corners.vnl of rig_seq and its exit status"""
    vnl = str(tmp_path_factory.mktemp("det") / "corners.vnl")
    rc = detect_cli.main([rig_seq, "-o", vnl, "--quiet"])
    return vnl, rc


def test_truth_files(rig_seq):
    t = load_rig_truth(rig_seq)
    assert [os.path.basename(p) for p in sorted(os.listdir(rig_seq)) if p.endswith(".cameramodel")] == [
        "truth-camera-0.cameramodel", "truth-camera-1.cameramodel"]
    assert np.allclose(t.models[0].extrinsics_rt_fromref(), 0)
    c1 = -mrcal.R_from_r(t.models[1].extrinsics_rt_fromref()[:3]).T @ t.models[1].extrinsics_rt_fromref()[3:]
    assert np.allclose(c1, (0.05, 0, 0), atol=1e-12)
    angle = np.degrees(np.linalg.norm(t.models[1].extrinsics_rt_fromref()[:3]))
    assert 0.1 <= angle <= 0.3
    assert not np.allclose(t.models[0].intrinsics()[1], t.models[1].intrinsics()[1])  # a lens of its own
    # the true corners: camera k's projection of the board at rt_ref_board
    pose = next(p for p in t.poses if 1 in t.corners[p])
    p = mrcal.transform_point_rt(t.rt_cam_board(1, pose), t.layout.board_points())
    assert np.allclose(mrcal.project(p, *t.models[1].intrinsics()), t.corners[pose][1])


def test_detect_labels_alike_and_matches_truth(rig_seq, detected):
    """Every board of every camera is labelled as the truth labels it: the same corner numbering in both"""
    vnl, rc = detected
    assert rc == 0
    t = load_rig_truth(rig_seq)
    with open(vnl) as f:
        boards = read_corners(f, t.layout.nx, t.layout.ny)
    both = 0
    for fn, grid in boards.items():
        pose, cam = fn.split(os.sep)[-3], dataset.camera_index(fn.split(os.sep)[-2])
        if grid is None:
            continue
        ok = np.isfinite(grid).all(axis=-1)
        err = np.linalg.norm(grid[ok] - t.corners[pose][cam][ok], axis=-1)
        assert err.max() < 0.2, (fn, err.max())  # a mislabelled corner would be an element (>10 px) off
        both += cam == 1
    assert both >= NPOSES // 2
    # the check across cameras passes on them, and catches a board turned in one camera
    pose = next(p for p in t.poses if all(boards.get(os.path.join(rig_seq, p, f"camera-{k}", "rotstar_00.png"))
                                          is not None for k in (0, 1)))
    a = boards[os.path.join(rig_seq, pose, "camera-0", "rotstar_00.png")]
    b = boards[os.path.join(rig_seq, pose, "camera-1", "rotstar_00.png")]
    assert labelling_agrees(a, b) == ""
    why = labelling_agrees(a, b[::-1, ::-1])
    assert why.startswith("the board-x direction differs by ") and int(why.split()[5]) > 150
    assert labelling_agrees(a, b[:, ::-1]) == "the board is mirrored in one camera only"


def test_camera_missing_in_a_pose(rig_seq, detected):
    """pose002 has no camera-1 folder: camera-0's board of pose002 is still written"""
    vnl, _ = detected
    with open(vnl) as f:
        names = {line.split()[0] for line in f if not line.startswith("#")}
    assert os.path.join(rig_seq, "pose002", "camera-0", "rotstar_00.png") in names
    assert os.path.join(rig_seq, "pose002", "camera-1", "rotstar_00.png") not in names
    assert "pose002" in dataset.read_rig(rig_seq).absent[1]


def test_printed_command(rig_seq, detected, capsys):
    vnl, _ = detected
    assert detect_cli.main([rig_seq, "-o", vnl + ".2", "--quiet"]) == 0
    err = capsys.readouterr().err
    cmd = err.split("next, calibrate the 2 cameras at once with:\n")[1].strip()
    assert f"'{rig_seq}/*/camera-0/rotstar_00.png' '{rig_seq}/*/camera-1/rotstar_00.png'" in cmd
    assert "--imagersize 640 400" in cmd
    f0, f1 = (float(v) for v in cmd.split("--focal ")[1].split()[0].split(","))
    assert abs(f0 - 320) < 0.1 * 320 and abs(f1 - 320) < 0.1 * 320


def test_calibrate_recovers_the_baseline(rig_seq, detected, tmp_path, capsys):
    """rotstar-calibrate on the rig: camera-K.cameramodel, the baseline within 1 mm and the intrinsics of the truth"""
    vnl, _ = detected
    out = str(tmp_path / "cal")
    assert calibrate_cli.main([rig_seq, "--corners", vnl, "--outdir", out]) == 0
    err = capsys.readouterr().err
    assert "camera-1:" in err and "mm from camera-0" in err
    assert "cover glass (index 1.5): " in err  # estimated for the whole rig (none here: 8 poses, no glass)
    with open(os.path.join(out, "calibration.json")) as f:
        glass = json.load(f)["glass"]
    assert glass["given"] is False and not glass["applied"] and "no glass" in glass["reason"]
    t = load_rig_truth(rig_seq)
    for k in (0, 1):
        m = mrcal.cameramodel(os.path.join(out, f"camera-{k}.cameramodel"))
        assert np.allclose(m.intrinsics()[1][:4], t.models[k].intrinsics()[1][:4], atol=0.5)
        rt, rt_true = m.extrinsics_rt_fromref(), t.models[k].extrinsics_rt_fromref()
        assert np.linalg.norm(rt[3:] - rt_true[3:]) < 1e-3  # metres
        assert np.degrees(np.linalg.norm(rt[:3] - rt_true[:3])) < 0.05
    # the plain residuals put every board through its own camera (camera 1's through camera 0's lens: ~2 px)
    e = board_residuals(m)
    assert np.isfinite(e).sum() > 500 and np.sqrt(np.nanmean(e**2)) < 0.05



def test_cameras_swapped_in_one_pose_are_dropped_and_named(rig_seq, detected, tmp_path, capsys):
    """The issue's rig with camera-0 and camera-1 swapped in one pose of 8 (as if the folders were swapped): was
    written with exit 0 at a fit RMS of 160 px and fx -29; now that pose is found, named and left out"""
    vnl, _ = detected
    text = open(vnl).read()
    pose = "pose003"
    a, b = os.path.join(pose, "camera-0") + os.sep, os.path.join(pose, "camera-1") + os.sep
    assert a in text and b in text
    swapped = tmp_path / "swapped.vnl"
    swapped.write_text(text.replace(a, "@").replace(b, a).replace("@", b))
    out = str(tmp_path / "cal")
    rc = calibrate_cli.main([rig_seq, "--corners", str(swapped), "--outdir", out])
    err = capsys.readouterr().err
    assert rc == 0, err
    assert f"dropping {pose} (" in err and "the fit is implausible" in err, err
    c = json.load(open(os.path.join(out, "calibration.json")))
    assert sorted(c["dropped"]) == [f"{pose}/camera-0", f"{pose}/camera-1"] and c["ok"]
    t = load_rig_truth(rig_seq)
    for k in (0, 1):
        m = mrcal.cameramodel(os.path.join(out, f"camera-{k}.cameramodel"))
        assert np.allclose(m.intrinsics()[1][:4], t.models[k].intrinsics()[1][:4], atol=0.5)
        assert np.linalg.norm(m.extrinsics_rt_fromref()[3:] - t.models[k].extrinsics_rt_fromref()[3:]) < 1e-3


def test_implausible_rig_fit_is_never_written(rig_seq, detected, tmp_path, capsys):
    """Four poses, one swapped: no pose can be left out (each camera needs 4 boards), so no culprit is found: exit 1
    naming the implausible fit, no model files, also with --keep"""
    vnl, _ = detected
    keep = ("pose001", "pose003", "pose005", "pose006")
    lines = [x for x in open(vnl).read().splitlines(keepends=True)
             if x.startswith("#") or x.split()[0].split(os.sep)[-3] in keep]
    assert len({x.split()[0] for x in lines if not x.startswith("#")}) == 8  # both cameras in each
    text = "".join(lines)
    a, b = os.path.join("pose003", "camera-0") + os.sep, os.path.join("pose003", "camera-1") + os.sep
    swapped = tmp_path / "swapped.vnl"
    swapped.write_text(text.replace(a, "@").replace(b, a).replace("@", b))
    out = str(tmp_path / "cal")
    rc = calibrate_cli.main([rig_seq, "--corners", str(swapped), "--outdir", out, "--keep"])
    err = capsys.readouterr()
    assert rc == 1 and err.out == "" and "FAILED: " in err.err and "fit RMS" in err.err, err.err
    assert not [f for f in os.listdir(out) if f.endswith(".cameramodel")]

# ---------------------------------------------------------------------------
# the layout's errors, on tiny datasets
# ---------------------------------------------------------------------------
LAYOUT = make_layout(screen=(800, 600), pitch=100, band=24)


def tiny_rig(tmp_path, sizes=((60, 40), (48, 30)), poses=("pose000", "pose001")):
    seq = str(tmp_path / "seq")
    dataset.write_pattern(seq, LAYOUT)
    for p in poses:
        for k, (w, h) in enumerate(sizes):
            dataset.write_pose(seq, f"{p}/camera-{k}", {f["file"]: np.zeros((h, w), np.uint8) for f in LAYOUT.frames()})
    return seq


def test_layout_read(tmp_path):
    seq = tiny_rig(tmp_path)
    assert dataset.is_multi_camera(seq)
    r = dataset.read_rig(seq)
    assert r.cameras == [0, 1] and r.sizes == {0: (60, 40), 1: (48, 30)}  # sizes may differ between cameras
    assert r.poses[1] == ["pose000/camera-1", "pose001/camera-1"]


def test_different_frame_counts(tmp_path):
    """(one identity frame missing is no difference: load_pose reads the pose; tests/test_dataset.py)"""
    seq = tiny_rig(tmp_path)
    os.remove(os.path.join(seq, "pose001", "camera-1", "rotstar_03.png"))
    with pytest.raises(dataset.DatasetError) as e:
        dataset.read_rig(seq)
    msg = str(e.value)
    assert "\n" not in msg
    assert msg.startswith(os.path.join(seq, "pose001", "camera-1", "rotstar_03.png") + ": missing, though ")
    assert "the cameras of a pose must hold the same frames" in msg


def test_sizes_differ_within_a_camera(tmp_path, capsys):
    seq = tiny_rig(tmp_path)
    cv2.imwrite(os.path.join(seq, "pose001", "camera-1", "rotstar_00.png"), np.zeros((31, 48), np.uint8))
    with pytest.raises(dataset.DatasetError, match=r"pose001/camera-1/rotstar_00\.png: image size 48x31 differs from "
                                                   r".*pose000/camera-1/rotstar_00\.png \(48x30\): every image of one "
                                                   r"camera \(camera-1\)"):
        dataset.read_rig(seq)
    assert detect_cli.main([seq, "-o", str(tmp_path / "c.vnl")]) == 2  # bad input: exit 2, one line
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "image size 48x31 differs" in err[0]


def test_layout_errors(tmp_path):
    seq = tiny_rig(tmp_path)
    os.rename(os.path.join(seq, "pose001"), os.path.join(seq, "left"))
    with pytest.raises(dataset.DatasetError, match=r"left: a multi-camera pose folder must be named poseNNN"):
        dataset.read_rig(seq)
    os.rename(os.path.join(seq, "left"), os.path.join(seq, "pose0"))
    with pytest.raises(dataset.DatasetError, match=r"pose folders pose0 and pose000 have the same number"):
        dataset.read_rig(seq)
    shutil.rmtree(os.path.join(seq, "pose0"))
    shutil.copy(os.path.join(seq, "pose000", "camera-0", "rotstar_00.png"), os.path.join(seq, "pose000", "x.png"))
    with pytest.raises(dataset.DatasetError, match=r"pose000/x\.png: not a camera-K folder"):
        dataset.read_rig(seq)


def test_camera_folder_with_leading_zeros(tmp_path, capsys):
    """camera-01 is not read as camera 1 and then opened as camera-1: refused in one line naming it"""
    seq = tiny_rig(tmp_path)
    os.rename(os.path.join(seq, "pose001", "camera-1"), os.path.join(seq, "pose001", "camera-01"))
    with pytest.raises(dataset.DatasetError, match=r"pose001/camera-01: a camera folder is named camera-K without "
                                                   r"leading zeros; rename it camera-1$"):
        dataset.read_rig(seq)
    assert detect_cli.main([seq, "-o", str(tmp_path / "c.vnl")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "camera-01: a camera folder is named camera-K" in err[0]
    assert not os.path.exists(tmp_path / "c.vnl")


def test_absurd_frame_header_skips_that_pose_only(tmp_path, capsys):
    """A camera's first frame whose header claims 60000x60000 is not taken for the camera's size: that pose is
    skipped naming the file, the others are read (here all dark: exit 1, no traceback)"""
    seq = tiny_rig(tmp_path)
    huge_png(os.path.join(seq, "pose001", "camera-1", "rotstar_00.png"))
    assert dataset.read_rig(seq).sizes == {0: (60, 40), 1: (48, 30)}
    assert detect_cli.main([seq, "-o", str(tmp_path / "c.vnl")]) == 1
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if "pose001/camera-1" in line]
    assert len(lines) == 1 and "pose001/camera-1/rotstar_00.png: its header claims a 60000x60000 frame" in lines[0]
    assert "pose000/camera-1: skipped: all dark" in err and "Traceback" not in err


def test_turned_board_dropped_and_too_few_boards(rig_seq, detected, tmp_path, capsys):
    """A pose whose camera-1 images are turned by 180 degrees (not how this rig sees a board) is dropped from
    every camera; a camera left with one board gets no command (mrcal needs 2 per camera): exit 1"""
    t = load_rig_truth(rig_seq)
    with open(detected[0]) as f:
        found = read_corners(f, t.layout.nx, t.layout.ny)
    both = [p for p in t.poses
            if all(found.get(os.path.join(rig_seq, p, f"camera-{k}", "rotstar_00.png")) is not None for k in (0, 1))][:2]
    seq = str(tmp_path / "seq")
    os.makedirs(seq)
    shutil.copy(os.path.join(rig_seq, "pattern.json"), seq)
    for p in both:
        shutil.copytree(os.path.join(rig_seq, p), os.path.join(seq, p))
    turned = os.path.join(seq, both[1], "camera-1")
    for f in os.listdir(turned):
        fn = os.path.join(turned, f)
        cv2.imwrite(fn, cv2.imread(fn, cv2.IMREAD_UNCHANGED)[::-1, ::-1].copy())
    vnl = str(tmp_path / "c.vnl")
    assert detect_cli.main([seq, "-o", vnl, "--quiet"]) == 1
    err = capsys.readouterr().err
    assert f"{both[1]}: skipped in every camera: labelled differently in camera-0 and camera-1: the board-x direction" in err
    assert "camera-0: 1 board(s); mrcal needs at least 2 per camera" in err  # both cameras are left with one
    with open(vnl) as f:
        boards = read_corners(f, t.layout.nx, t.layout.ny)
    assert all(boards[os.path.join(seq, both[1], f"camera-{k}", "rotstar_00.png")] is None for k in (0, 1))
    assert boards[os.path.join(seq, both[0], "camera-1", "rotstar_00.png")] is not None


def test_simulate_rig_arguments(tmp_path, capsys):
    from rotstar_mrcal.cli import simulate

    for argv, msg in ((["--rgb"], "--rgb adds the colour camera of a --rig"),
                      (["--rig", "d435", "--camera", "wide"], "--camera and --rig exclude each other"),
                      (["--rig", "d435", "--display-offsets", "random:1"], "--display-offsets and --display-map are not simulated")):
        with pytest.raises(SystemExit) as e:
            simulate.parse_args(["--out", str(tmp_path / "x"), *argv])
        assert e.value.code == 2 and msg in capsys.readouterr().err


@pytest.mark.slow  # make test-slow: a longer end-to-end run
def test_simulate_rig_with_a_seidel_lens(tmp_path, capsys):
    """--rig with --seidel: every camera renders through the wavefront lens over its own imager (the right
    imager's amplitudes x0.9), recorded in the truth; the images are blurrier than without a PSF"""
    import json

    from rotstar_mrcal.cli import simulate

    common = ["--rig", "d435-small", "--poses", "2", "--supersample", "1", "--no-identity"]
    assert simulate.main(["--out", str(tmp_path / "s"), *common, "--seidel", "coma=1.5,focus=0.3"]) == 0
    assert simulate.main(["--out", str(tmp_path / "g"), *common, "--blur", "0"]) == 0
    cams = json.load(open(tmp_path / "s" / "truth.json"))["settings"]["cameras"]
    assert "coma 1.5" in cams[0]["psf"] and "coma 1.35" in cams[1]["psf"] and "tilt -1.35" in cams[1]["psf"]
    pose = sorted(p.name for p in (tmp_path / "s").glob("pose*/camera-1"))
    a = cv2.imread(str(tmp_path / "s" / "pose000" / "camera-0" / "checkerboard.png"), cv2.IMREAD_UNCHANGED)
    b = cv2.imread(str(tmp_path / "g" / "pose000" / "camera-0" / "checkerboard.png"), cv2.IMREAD_UNCHANGED)
    energy = lambda img: np.sum(np.diff(img.astype(float), axis=1) ** 2)  # noqa: E731  (of the edges)
    assert energy(a) < 0.9 * energy(b) and pose
    capsys.readouterr()


@pytest.mark.slow
def test_three_cameras_of_different_sizes(tmp_path, monkeypatch, capsys):
    """--rgb: the colour camera's 640x360 beside 640x400 (no --imagersize: mrcal reads each camera's size from
    its images, so the command runs where rotstar-detect ran); every camera recovered against the truth"""
    from rotstar_mrcal.cli import simulate

    monkeypatch.chdir(tmp_path)
    assert simulate.main(["--rig", "d435-small", "--rgb", "--poses", "15", "--supersample", "2", "--seed", "1",
                          "--out", "seq"]) == 0
    assert calibrate_cli.main(["seq", "--outdir", "cal"]) == 0
    err = capsys.readouterr().err
    assert "--imagersize" not in err.split("$ mrcal-calibrate-cameras")[-1]
    t = load_rig_truth("seq")
    for k in (0, 1, 2):
        m = mrcal.cameramodel(os.path.join("cal", f"camera-{k}.cameramodel"))
        assert tuple(m.imagersize()) == tuple(t.models[k].imagersize())
        assert np.allclose(m.intrinsics()[1][:4], t.models[k].intrinsics()[1][:4], atol=0.5)
        c = -mrcal.R_from_r(m.extrinsics_rt_fromref()[:3]).T @ m.extrinsics_rt_fromref()[3:]
        c_true = -mrcal.R_from_r(t.models[k].extrinsics_rt_fromref()[:3]).T @ t.models[k].extrinsics_rt_fromref()[3:]
        assert np.linalg.norm(c - c_true) < 1e-3


def test_imagersize_that_is_not_the_cameras_is_named(tmp_path, capsys):
    """A wrong --imagersize on a rig: named as such, before anything is solved"""
    seq = tiny_rig(tmp_path)
    vnl = tmp_path / "c.vnl"
    vnl.write_text(f"# filename x y level\n{seq}/pose000/camera-0/rotstar_00.png - - -\n")
    rc = calibrate_cli.main([seq, "--corners", str(vnl), "--outdir", str(tmp_path / "cal"), "--imagersize", "60", "40"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "the imager size given, 60x40, is not the size of" in err[0], err
    assert "camera-1 images (48x30)" in err[0], err

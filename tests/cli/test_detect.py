"""rotstar-detect as a user runs it: bad inputs, the corners.vnl it writes, its options

The datasets here are built from the session's simulated D435 dataset
(tests/conftest.py): good pose folders are copied and broken in the ways a
recording goes wrong; three more poses are rendered (a board partly out of
view, a camera that drifted and one that shook during the sequence). Every
pose keeps its truth, so every board the tool writes is checked against it.
"""

from __future__ import annotations

import dataclasses
import io
import math
import os
import re
import shlex
import shutil

import cv2
import mrcal
import numpy as np
import pytest

from conftest import D435_SETTINGS, ROLES, huge_png
from rotstar_mrcal import simulate
from rotstar_mrcal.simulate import look_at_pose, write_dataset
from rotstar_mrcal.vnl import read_corners

FIRST = "rotstar_00.png"
ROTSTAR = [f"rotstar_{k:02d}.png" for k in range(8)]

# pose folder -> the reason its one stderr line must give (None: a good pose)
EXPECT = {
    "good_a": None,  # copy of pose001
    "good_b": None,  # copy of the 55-degree pose
    "missing_frame": r"missing_frame/rotstar_03\.png: missing frame",
    "missing_first": r"missing_first/rotstar_00\.png: missing frame",
    "extra_frame": r"extra_frame/rotstar_08\.png: extra frame not in pattern\.json",
    "size_mismatch": r"size_mismatch/rotstar_04\.png: frame size 1278x800 differs from the others \(1280x800\)",
    "size_larger": r"size_larger/rotstar_04\.png: frame size 1282x800 differs from the others \(1280x800\)",
    "checker_size": r"checker_size/checkerboard\.png: frame size differs",
    "corrupt_png": r"corrupt_png/rotstar_02\.png: not a readable image",
    "truncated_png": r"truncated_png/rotstar_05\.png: not a readable image",
    "mixed_depth": r"mixed_depth: frames mix 8- and 16-bit",
    "colour_frame": r"colour_frame/rotstar_01\.png: colour image",
    "huge_header": r"huge_header/rotstar_03\.png: its header claims a 60000x60000 frame \(3600 Mpx",
    "dark": r"all dark",
    "saturated": r"saturated",
    "out_of_view": None,  # part of the board off the image: the identity frames label the corners in view
    "moved_drift": r"camera moved",
    "moved_jitter": r"camera moved",
    "reversed_order": r"frames out of order: frame 0 shows the angle of frame [17]",
    "mirrored": r"board seen mirrored \(the image flipped, or the screen seen through a mirror\)",
    "shuffled_order": r"frames out of order",
}
SHUFFLE = [5, 2, 7, 0, 3, 1, 6, 4]  # frame 0 shows the pattern at angle 5 pi / 16


# ---------------------------------------------------------------------------
# datasets
# ---------------------------------------------------------------------------
def copy_pose(src_seq, pose, dst_seq, name):
    shutil.copytree(os.path.join(src_seq, pose), os.path.join(dst_seq, name))
    return os.path.join(dst_seq, name)


def rewrite(folder, fn, f):
    """Apply f to one image file (read unchanged, written back as returned)"""
    path = os.path.join(folder, fn)
    img = cv2.imread(path, cv2.IMREAD_UNCHANGED)
    assert cv2.imwrite(path, f(img))


def scaled(k):
    return lambda img: np.clip(img.astype(np.float64) * k, 0, 65535).astype(np.uint16)


def in_the_dark(img):
    """A sensor in the dark: black level, read noise and a signal of a few DN (not scaled(0.01): that
    scales the noise too and is a well exposed image in fewer bits)"""
    rng = np.random.default_rng(0)
    return np.clip(200 + img * 0.0005 + rng.normal(0, 30, img.shape), 0, 65535).astype(np.uint16)


def moved_poses(model, layout, rt0, rng):
    """Per-frame poses: a rotation drifting to ~3 px of image motion; random ~1 px shakes"""
    f = model.intrinsics()[1][0]
    nfr = len(layout.frames())

    def turned(r):
        return mrcal.compose_rt(np.concatenate((r, np.zeros(3))), rt0)

    drift = np.array([turned(np.array((0.0, 3.0 / f * min(k, 7) / 7, 0.0))) for k in range(nfr)])
    jitter = np.array([turned(np.append(rng.normal(0, 1.0 / f, 2), 0.0)) for k in range(nfr)])
    return drift, jitter


@pytest.fixture(scope="module")
def bad_seq(d435_seq, tmp_path_factory):
    """A dataset holding two good poses and every way a pose can be broken; (path, truth corners)"""
    src, L = d435_seq.path, d435_seq.layout
    seq = str(tmp_path_factory.mktemp("bad") / "seq")
    os.makedirs(seq)
    shutil.copy(os.path.join(src, "pattern.json"), seq)
    truth = {}

    def copy(pose, name):
        truth[name] = d435_seq.corners(pose)
        return copy_pose(src, pose, seq, name)

    copy("pose001", "good_a")
    copy(ROLES["steep55b"], "good_b")
    os.remove(os.path.join(copy("pose002", "missing_frame"), "rotstar_03.png"))
    os.remove(os.path.join(copy("pose002", "missing_first"), FIRST))
    d = copy("pose002", "extra_frame")
    shutil.copy(os.path.join(d, FIRST), os.path.join(d, "rotstar_08.png"))
    rewrite(copy("pose003", "size_mismatch"), "rotstar_04.png", lambda img: img[:, 1:-1])
    rewrite(copy("pose003", "size_larger"), "rotstar_04.png", lambda img: np.pad(img, ((0, 0), (0, 2))))
    rewrite(copy("pose003", "checker_size"), "checkerboard.png", lambda img: img[:-2])
    with open(os.path.join(copy("pose004", "corrupt_png"), "rotstar_02.png"), "wb") as fh:
        fh.write(b"this is not a PNG\n" * 50)
    path = os.path.join(copy("pose004", "truncated_png"), "rotstar_05.png")
    with open(path, "rb") as fh:
        data = fh.read()
    with open(path, "wb") as fh:
        fh.write(data[: len(data) // 2])
    huge_png(os.path.join(copy("pose004", "huge_header"), "rotstar_03.png"))
    rewrite(copy("pose005", "mixed_depth"), "rotstar_06.png", lambda img: (img >> 8).astype(np.uint8))
    rewrite(copy("pose005", "colour_frame"), "rotstar_01.png",
            lambda img: np.dstack((img, img, img // 2)))
    d = copy("pose006", "dark")
    for fn in ROTSTAR + ["checkerboard.png"]:
        rewrite(d, fn, in_the_dark)
    d = copy("pose006", "saturated")
    for fn in ROTSTAR + ["checkerboard.png"]:
        rewrite(d, fn, scaled(60))
    d = copy("pose007", "reversed_order")
    for k, fn in enumerate(ROTSTAR):
        os.rename(os.path.join(d, fn), os.path.join(d, f"tmp_{7 - k}"))
    for k, fn in enumerate(ROTSTAR):
        os.rename(os.path.join(d, f"tmp_{k}"), os.path.join(d, fn))
    d = copy("pose001", "mirrored")
    for fn in os.listdir(d):
        rewrite(d, fn, np.fliplr)
    d = copy("pose007", "shuffled_order")
    for k, fn in enumerate(ROTSTAR):
        os.rename(os.path.join(d, ROTSTAR[SHUFFLE[k]]), os.path.join(d, f"tmp_{k}"))
    for k, fn in enumerate(ROTSTAR):
        os.rename(os.path.join(d, f"tmp_{k}"), os.path.join(d, fn))

    # rendered: part of the board off the right edge; a camera that moved
    model = d435_seq.model
    rt0 = look_at_pose(model, L, (600.0, 420.0), 0.45, tilt=math.radians(30), tilt_axis=0.5, roll=0.2)
    out = look_at_pose(model, L, (1100.0, 420.0), 0.45, tilt=math.radians(20), tilt_axis=0.5, roll=0.2)
    drift, jitter = moved_poses(model, L, rt0, np.random.default_rng(3))
    extra = str(tmp_path_factory.mktemp("extra") / "seq")
    # supersample 1 (half the rendering): these three poses are checked for their labels and skip reasons only
    t = write_dataset(extra, L, model, [out, drift, jitter], dataclasses.replace(D435_SETTINGS, supersample=1), jobs=2)
    for pose, name in zip(t.poses, ("out_of_view", "moved_drift", "moved_jitter")):
        truth[name] = t.corners[pose]
        shutil.move(os.path.join(extra, pose), os.path.join(seq, name))
    assert sorted(truth) == sorted(EXPECT)
    return seq, truth


@pytest.fixture(scope="module")
def bad_run(bad_seq, run_cli, tmp_path_factory):
    seq, _ = bad_seq
    return run_cli("rotstar-detect", seq, cwd=tmp_path_factory.mktemp("run1"))


@pytest.fixture(scope="module")
def good_seq(d435_seq, tmp_path_factory):
    """Two good poses (12 and 55 degrees of tilt); (path, truth corners)"""
    seq = str(tmp_path_factory.mktemp("good") / "seq")
    os.makedirs(seq)
    shutil.copy(os.path.join(d435_seq.path, "pattern.json"), seq)
    truth = {}
    for pose in ("pose003", ROLES["steep55b"]):
        copy_pose(d435_seq.path, pose, seq, pose)
        truth[pose] = d435_seq.corners(pose)
    return seq, truth


def pose_lines(stderr: str, pose: str) -> list[str]:
    pat = re.compile(rf"(^|[\s/]){re.escape(pose)}[:/]")
    return [line for line in stderr.splitlines() if pat.search(line)]


def printed_command(stderr: str) -> list[str]:
    assert "next, calibrate with:\n" in stderr
    cmd = shlex.split(stderr.split("next, calibrate with:\n", 1)[1].strip().splitlines()[0])
    assert cmd[0] == "mrcal-calibrate-cameras"
    return cmd


def option(cmd: list[str], name: str, n: int = 1):
    i = cmd.index(name)
    return cmd[i + 1] if n == 1 else cmd[i + 1 : i + 1 + n]


def boards_of(stdout: str, seq: str, layout) -> dict:
    """{pose: (ny, nx, 2) or None} from corners.vnl text"""
    found = read_corners(io.StringIO(stdout), layout.nx, layout.ny)
    out = {}
    for fn, grid in found.items():
        assert fn == os.path.join(seq, os.path.basename(os.path.dirname(fn)), FIRST)
        out[os.path.basename(os.path.dirname(fn))] = grid
    return out


def agrees_with_truth(grid: np.ndarray, truth: np.ndarray, tol: float) -> bool:
    if truth.ndim == 4:  # a camera that moved: one truth per frame; the labelling is what matters
        truth = truth[:8].mean(axis=0)
    return bool(np.nanmax(np.linalg.norm(grid - truth, axis=-1)) < tol)


# ---------------------------------------------------------------------------
# bad inputs
# ---------------------------------------------------------------------------
def test_bad_dataset_exit_status_and_summary(bad_run, bad_seq):
    assert bad_run.returncode == 0, bad_run.stderr  # some poses gave a board
    assert f"rotstar-detect: 3 of {len(EXPECT)} poses gave a board" in bad_run.stderr
    assert "Traceback" not in bad_run.stderr




@pytest.mark.parametrize("pose", [p for p, why in EXPECT.items() if why])
def test_bad_pose_gets_one_line_with_its_reason(bad_run, pose):
    # skipped while detected, or after all poses by the dataset's motion check (a camera that drifted
    # moves every frame alike, as a screen's display offsets do within one pose)
    lines = [line for line in pose_lines(bad_run.stderr, pose) if "skipped" in line]
    assert len(lines) == 1, pose_lines(bad_run.stderr, pose)
    assert re.search(EXPECT[pose], lines[0]), lines[0]


@pytest.mark.parametrize("pose", ["good_a", "good_b"])
def test_good_poses_still_processed(bad_run, bad_seq, d435_seq, pose):
    seq, truth = bad_seq
    lines = pose_lines(bad_run.stderr, pose)
    assert len(lines) == 1 and f"{pose}: 126 of 126 corners" in lines[0]
    boards = boards_of(bad_run.stdout, seq, d435_seq.layout)
    assert boards[pose] is not None
    # measured: max error 0.012 / 0.020 px
    assert agrees_with_truth(boards[pose], truth[pose], 0.05)


def test_every_board_written_agrees_with_truth(bad_run, bad_seq, d435_seq):
    """Whatever the tool accepts must be labelled right (a wrong label is >= 10 px off)"""
    seq, truth = bad_seq
    boards = boards_of(bad_run.stdout, seq, d435_seq.layout)
    assert sorted(boards) == sorted(EXPECT)  # one entry per pose folder, in or out
    for pose, grid in boards.items():
        if grid is not None:
            assert agrees_with_truth(grid, truth[pose], 0.05 if truth[pose].ndim == 3 else 3.0), pose
        else:
            assert EXPECT[pose], f"{pose}: a good pose was skipped"


def test_stderr_has_no_stray_lines(bad_run):
    known = re.compile(r"^\[\d+/\d+\] \S+: |^\S+: skipped: |^rotstar-detect: |^next, calibrate with:$"
                       r"|^  mrcal-calibrate-cameras ")
    stray = [line for line in bad_run.stderr.splitlines() if not known.search(line)]
    assert stray == []


def progress_messages(stderr: str) -> set[str]:
    """'pose: message' of every progress line, without the counter and the timing"""
    return {re.sub(r"  \(\d+ s, ~\d+ s left\)$", "", line.split("] ", 1)[1])
            for line in stderr.splitlines() if re.match(r"\[\d+/\d+\] ", line)}


@pytest.mark.slow  # make test-slow: an end-to-end run, left out of make test
def test_jobs_2_gives_identical_stdout(bad_run, bad_seq, run_cli, tmp_path):
    seq, _ = bad_seq
    r2 = run_cli("rotstar-detect", "--jobs", "2", seq, cwd=tmp_path)
    assert r2.returncode == bad_run.returncode
    assert r2.stdout == bad_run.stdout
    assert len(progress_messages(bad_run.stderr)) == len(EXPECT)
    assert progress_messages(r2.stderr) == progress_messages(bad_run.stderr)
    assert printed_command(r2.stderr) == printed_command(bad_run.stderr)


def test_missing_pattern_json(d435_seq, run_cli, tmp_path):
    seq = str(tmp_path / "seq")
    os.makedirs(seq)
    copy_pose(d435_seq.path, "pose001", seq, "pose001")
    r = run_cli("rotstar-detect", seq, cwd=tmp_path)
    assert r.returncode == 2
    assert r.stdout == ""
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "pattern.json" in lines[0] and seq in lines[0]


@pytest.mark.parametrize("content", ["{not json", '{"format": "rotstar-pattern/1"}'], ids=["not-json", "no-grid"])
def test_unreadable_pattern_json(tmp_path, run_cli, content):
    seq = tmp_path / "seq"
    (seq / "pose000").mkdir(parents=True)
    (seq / "pattern.json").write_text(content)
    r = run_cli("rotstar-detect", seq, cwd=tmp_path)
    assert r.returncode == 2 and r.stdout == ""
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "pattern.json" in lines[0]


def test_dataset_without_poses(d435_seq, run_cli, tmp_path):
    seq = tmp_path / "seq"
    (seq / "notes").mkdir(parents=True)
    shutil.copy(os.path.join(d435_seq.path, "pattern.json"), seq)
    r = run_cli("rotstar-detect", seq, cwd=tmp_path)
    assert r.returncode == 2 and r.stdout == ""
    assert "no pose folders" in r.stderr


def test_no_pose_gives_a_board(d435_seq, run_cli, tmp_path):
    seq = str(tmp_path / "seq")
    os.makedirs(seq)
    shutil.copy(os.path.join(d435_seq.path, "pattern.json"), seq)
    d = copy_pose(d435_seq.path, "pose001", seq, "dark")
    for fn in ROTSTAR:
        rewrite(d, fn, in_the_dark)
    os.remove(os.path.join(copy_pose(d435_seq.path, "pose001", seq, "missing"), "rotstar_07.png"))
    r = run_cli("rotstar-detect", seq, cwd=tmp_path)
    assert r.returncode == 1
    assert r.stdout.splitlines() == ["# filename x y level", f"{seq}/dark/{FIRST} - - -", f"{seq}/missing/{FIRST} - - -"]
    assert len(pose_lines(r.stderr, "dark")) == 1 and len(pose_lines(r.stderr, "missing")) == 1
    assert "0 of 2 poses gave a board" in r.stderr
    assert "mrcal-calibrate-cameras" not in r.stderr


def test_pose_folder_name_mrcal_cannot_read(d435_seq, run_cli, tmp_path):
    seq = str(tmp_path / "seq")
    os.makedirs(seq)
    shutil.copy(os.path.join(d435_seq.path, "pattern.json"), seq)
    d = copy_pose(d435_seq.path, "pose001", seq, "pose 1")
    for fn in ROTSTAR:
        rewrite(d, fn, scaled(0.01))  # dark: fails fast; the name alone breaks the run
    copy_pose(d435_seq.path, "pose003", seq, "pose003")
    r = run_cli("rotstar-detect", seq, cwd=tmp_path)
    assert "Traceback" not in r.stderr
    assert r.returncode == 0
    lines = pose_lines(r.stderr, "pose 1")
    assert len(lines) == 1 and "skipped" in lines[0]
    assert len(read_corners(io.StringIO(r.stdout), d435_seq.layout.nx, d435_seq.layout.ny)) >= 1


def test_quiet_still_says_why_a_pose_was_skipped(d435_seq, run_cli, tmp_path):
    seq = str(tmp_path / "seq")
    os.makedirs(seq)
    shutil.copy(os.path.join(d435_seq.path, "pattern.json"), seq)
    os.remove(os.path.join(copy_pose(d435_seq.path, "pose001", seq, "missing"), "rotstar_07.png"))
    r = run_cli("rotstar-detect", "--quiet", seq, cwd=tmp_path)
    assert r.returncode == 1
    assert len(pose_lines(r.stderr, "missing")) == 1


# ---------------------------------------------------------------------------
# what it writes
# ---------------------------------------------------------------------------
def test_stdout_is_corners_vnl_in_mrcal_order(bad_run, bad_seq, d435_seq, tmp_path):
    seq, truth = bad_seq
    L = d435_seq.layout
    lines = bad_run.stdout.splitlines()
    assert lines[0] == "# filename x y level"
    rows = {}
    for line in lines[1:]:
        f = line.split()
        assert len(f) == 4
        rows.setdefault(f[0], []).append(f[1:])
    # the poses in sorted order, nx*ny rows per board, one '- - -' row per skipped pose
    assert list(rows) == [os.path.join(seq, p, FIRST) for p in sorted(EXPECT)]
    for fn, r in rows.items():
        pose = os.path.basename(os.path.dirname(fn))
        if EXPECT[pose]:
            assert r == [["-", "-", "-"]]
        else:
            assert len(r) == L.nx * L.ny and all(v[2] in ("0.5", "-") for v in r)  # vnl.LEVEL
            # record j*nx + i is corner (i, j); a board partly out of view has '- - -' rows
            xy = np.array([[float(v[0]), float(v[1])] if v[0] != "-" else [np.nan, np.nan] for v in r])
            seen = np.isfinite(xy[:, 0])
            assert seen.sum() >= (L.nx * L.ny if pose != "out_of_view" else 60)
            assert np.allclose(xy[seen], truth[pose].reshape(-1, 2)[seen], atol=0.05)
    # mrcal reads the same thing
    fn = tmp_path / "corners.vnl"
    fn.write_text(bad_run.stdout)
    obs, _, paths = mrcal.compute_chessboard_corners(
        L.nx, L.ny, globs_per_camera=(os.path.join(seq, "*", FIRST),), corners_cache_vnl=str(fn),
        weight_column_kind="level")
    assert [os.path.basename(os.path.dirname(p)) for p in paths] == ["good_a", "good_b", "out_of_view"]
    for o, pose in zip(obs, ("good_a", "good_b", "out_of_view")):
        assert o.shape == (L.ny, L.nx, 3)
        seen = o[..., 2] > 0  # mrcal marks a missing corner with weight -1
        assert seen.sum() >= (L.nx * L.ny if pose != "out_of_view" else 60)
        assert np.allclose(o[..., :2][seen], truth[pose][seen], atol=0.05) and np.all(o[..., 2][seen] == 1)


def test_printed_mrcal_command(bad_run, bad_seq, d435_seq):
    seq, _ = bad_seq
    L = d435_seq.layout
    cmd = printed_command(bad_run.stderr)
    assert float(option(cmd, "--object-spacing")) == pytest.approx(0.0254 / 264 * 150, rel=1e-8)
    assert float(option(cmd, "--object-spacing")) == pytest.approx(L.spacing_m, rel=1e-8)
    assert option(cmd, "--object-width-n") == "14" and option(cmd, "--object-height-n") == "9"
    assert option(cmd, "--imagersize", 2) == ["1280", "800"]
    assert option(cmd, "--lensmodel") == "LENSMODEL_OPENCV8"
    assert option(cmd, "--corners-cache") == "corners.vnl"
    assert 0.9 * 640 < float(option(cmd, "--focal")) < 1.1 * 640  # the D435 preset has fx = fy = 640
    assert "--corners-cache-has-weights" not in cmd
    assert cmd[-1] == os.path.join(seq, "*", FIRST)


def test_help(run_cli):
    r = run_cli("rotstar-detect", "--help")
    assert r.returncode == 0 and r.stderr == ""
    for word in ("--jobs", "--refine", "--weights", "--window", "--max-motion", "pattern.json", "exit status:"):
        assert word in r.stdout


def test_the_default_refiner_is_psf_sim_for_rotstar_s_corners_only():
    from rotstar_mrcal.cli.detect import parse_args

    assert parse_args(["seq"]).refine == "psf-sim"
    assert parse_args(["seq", "--refine", "symmetric"]).refine == "symmetric"
    assert parse_args(["seq", "--method", "phase"]).refine == "symmetric"  # (its start: rotstar's symmetric fit)
    with pytest.raises(SystemExit):
        parse_args(["seq", "--method", "phase", "--refine", "symmetric"])


def test_bad_option(run_cli):
    r = run_cli("rotstar-detect", "--refine", "nonsense", "seq")
    assert r.returncode == 2 and "invalid choice" in r.stderr and r.stdout == ""


# measured with the crop fixed (pipeline.py, cb cut to the board's bounding box like the frames):
# opencv RMS 0.033 / 0.138 px, max 0.07 / 0.48 px (12 / 55 degrees of tilt; its window is 2 px on
# the steep pose); saddle RMS 0.017 / 0.019 px, max 0.03 / 0.04 px. As it is: RMS 0.8-4 px,
# saddle rejects 85-95% of the corners.
REFINE_BOUNDS = {"opencv": (0.25, 1.0), "saddle": (0.05, 0.15)}


@pytest.mark.parametrize("refine", ["opencv", "saddle"])
def test_refine_on_checkerboard_frame(good_seq, d435_seq, run_cli, tmp_path, refine):
    seq, truth = good_seq
    out = tmp_path / "corners.vnl"
    r = run_cli("rotstar-detect", "--refine", refine, "-o", out, seq, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert r.stdout == ""  # -o: the corners go to the file
    cmd = printed_command(r.stderr)
    assert option(cmd, "--corners-cache") == str(out)
    boards = boards_of(out.read_text(), seq, d435_seq.layout)
    assert sorted(boards) == sorted(truth)
    max_rms, max_err = REFINE_BOUNDS[refine]
    for pose, grid in boards.items():
        err = np.linalg.norm(grid - truth[pose], axis=-1)
        assert np.isfinite(err).mean() > 0.95, pose
        assert np.sqrt(np.nanmean(err**2)) < max_rms and np.nanmax(err) < max_err, pose


def test_refine_needs_the_checkerboard_frame(good_seq, d435_seq, run_cli, tmp_path):
    src, _ = good_seq
    seq = str(tmp_path / "seq")
    os.makedirs(seq)
    shutil.copy(os.path.join(src, "pattern.json"), seq)
    copy_pose(src, "pose003", seq, "pose003")
    os.remove(os.path.join(seq, "pose003", "checkerboard.png"))
    r = run_cli("rotstar-detect", "--refine", "opencv", seq, cwd=tmp_path)
    assert r.returncode == 1
    line, = pose_lines(r.stderr, "pose003")
    assert "needs the checkerboard frame" in line


def test_weights_column(good_seq, d435_seq, run_cli, tmp_path):
    seq, truth = good_seq
    L = d435_seq.layout
    r = run_cli("rotstar-detect", "--weights", seq, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    # (the default, psf-sim, on a lens without coma: the symmetric fit's corners, and it says so)
    assert "rotstar-detect: psf-sim: no coma (" in r.stderr and "the corners are the symmetric fit's" in r.stderr
    lines = r.stdout.splitlines()
    assert lines[0] == "# filename x y weight"
    w = np.array([float(line.split()[3]) for line in lines[1:]])
    assert len(w) == 2 * L.nx * L.ny
    assert np.all(w > 0) and np.median(w) == pytest.approx(1.0, rel=0.05) and np.ptp(w) > 0
    cmd = printed_command(r.stderr)
    assert "--corners-cache-has-weights" in cmd
    fn = tmp_path / "corners.vnl"
    fn.write_text(r.stdout)
    obs, *_ = mrcal.compute_chessboard_corners(
        L.nx, L.ny, globs_per_camera=(os.path.join(seq, "*", FIRST),), corners_cache_vnl=str(fn),
        weight_column_kind="weight")
    assert obs.shape == (2, L.ny, L.nx, 3)
    assert np.allclose(obs[..., 2].ravel(), w, rtol=1e-5)
    for o, pose in zip(obs, sorted(truth)):
        assert np.allclose(o[..., :2], truth[pose], atol=0.05)


def test_board_with_too_few_corners_for_mrcal(run_cli, tmp_path):
    """A board hanging far out of view (identity frames): its few corners are written as no board, and said"""
    from rotstar_lab.benchmark.coverage import plan_captures
    from rotstar_mrcal.pattern.layout import make_layout
    from rotstar_mrcal.simulate import Settings, preset_model

    model, layout = preset_model("pinhole-small"), make_layout(screen=(800, 600), pitch=100, band=24)
    plan = plan_captures(model, layout, n=6, hanging=2, seed=0)
    seq = str(tmp_path / "seq")
    write_dataset(seq, layout, model, plan.rts[[0, 1, 2, 6]], Settings(bits=16, seed=0, supersample=1), jobs=2)  # (counts only)
    r = run_cli("rotstar-detect", seq, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    limit = 2 * min(layout.nx, layout.ny)
    line, = [x for x in r.stderr.splitlines() if x.startswith("pose003: ")]
    n = int(re.match(r"pose003: (\d+) corners, mrcal ignores boards with <= (\d+); written as no board$", line)[1])
    assert 0 < n <= limit and f"<= {limit};" in line  # the hanging board gave corners, too few for mrcal
    assert "rotstar-detect: 3 of 4 poses gave a board (1 more gave too few corners for mrcal: written as no " \
           "board)" in r.stderr
    assert [x for x in r.stdout.splitlines() if x.startswith(f"{seq}/pose003/")] == [f"{seq}/pose003/{FIRST} - - -"]
    fn = tmp_path / "corners.vnl"
    fn.write_text(r.stdout)
    _, _, paths = mrcal.compute_chessboard_corners(layout.nx, layout.ny, globs_per_camera=(os.path.join(seq, "*", FIRST),),
                                                   corners_cache_vnl=str(fn), weight_column_kind="level")
    assert len(paths) == 3  # what rotstar-detect said: mrcal uses three boards


@pytest.mark.parametrize("size", [(60000, 60000), (9000, 9000)])
def test_frame_size_read_from_the_pgm_header(tmp_path, size):
    """Formats other than PNG too: a PGM whose header claims an absurd size is refused by its header, one line"""
    from rotstar_mrcal import dataset

    fn = str(tmp_path / "rotstar_00.pgm")
    with open(fn, "wb") as fh:
        fh.write(f"P5\n{size[0]} {size[1]}\n65535\n".encode() + bytes(100))
    with pytest.raises(dataset.DatasetError, match=rf"^{re.escape(fn)}: its header claims an? .*(more than 50|"
                                                   rf"{size[0]}x{size[1]}).*: a corrupt or foreign file$"):
        dataset.read_image(fn)


def test_blur_map_and_psf_refine_under_coma(run_cli, tmp_path):
    """--blur-map DIR writes the table and the picture; the widths and coma directions are the lens's;
    --refine psf and psf-sim bring the corners nearer the light's centroid than the symmetric fit (near views,
    2.5 waves)"""
    from rotstar_mrcal.detect.blurmap import read_table
    from rotstar_mrcal.optics.psf import LensPSF
    from rotstar_mrcal.optics.wavefront import Seidel
    from rotstar_mrcal.pattern.layout import make_layout
    from rotstar_mrcal.simulate import Settings, preset_model

    model, layout = preset_model("pinhole-small"), make_layout(screen=(800, 600), pitch=100, band=24, identity=False)
    lens = LensPSF(Seidel(coma=2.5, focus=0.3), model.imagersize())
    rts = [np.array((0, 0, 0, -0.0257 + dx, -0.0193 + dy, 0.08)) for dx, dy in ((0.025, 0.012), (-0.02, -0.01))]
    seq = str(tmp_path / "seq")
    write_dataset(seq, layout, model, np.array(rts), Settings(bits=16, seed=0), jobs=2, psf=lens)
    truth = {f"pose{i:03d}": simulate.true_corners(model, layout, rt) for i, rt in enumerate(rts)}
    err = {}
    for refine in ("symmetric", "psf", "psf-sim"):
        r = run_cli("rotstar-detect", "--refine", refine, "--blur-map", tmp_path / "bm", "-o",
                    tmp_path / f"{refine}.vnl", seq, cwd=tmp_path)
        assert r.returncode == 0, r.stderr
        assert "blur map of" in r.stderr
        assert ("rotstar-detect: psf-sim: coma up to " in r.stderr) == (refine == "psf-sim"), r.stderr
        boards = boards_of((tmp_path / f"{refine}.vnl").read_text(), seq, layout)
        err[refine] = np.concatenate([np.linalg.norm(boards[p] - truth[p], axis=-1).ravel() for p in truth])
    rms = {k: float(np.sqrt(np.nanmean(v ** 2))) for k, v in err.items()}
    assert rms["psf"] < 0.7 * rms["symmetric"], rms
    assert rms["psf-sim"] < 0.4 * rms["symmetric"], rms
    assert (tmp_path / "bm" / "blur_map.png").stat().st_size > 10000
    t = read_table(str(tmp_path / "bm" / "blur_map.csv"))
    assert len(t) > 20
    W, H = model.imagersize()
    c = np.array(((W - 1) / 2, (H - 1) / 2))
    h = np.linalg.norm(t[:, :2] - c, axis=1) / np.hypot(*c)
    radial = np.degrees(np.arctan2(t[:, 1] - c[1], t[:, 0] - c[0]))
    strong = 2.5 * h > 1.0
    off = np.abs((t[strong, 8] - radial[strong] + 180) % 360 - 180)  # the tail points away from the centre
    assert strong.sum() > 5 and np.median(off) < 15, off
    assert 0.4 < np.median(t[:, 2]) < 1.2

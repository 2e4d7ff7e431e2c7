"""Bad input, bad output paths and interrupts (issue 10's fault list): every case a one-line error
naming the file and the reason with exit status 2 (1: the job ran but failed, 130: interrupted), or
correct output; no traceback, no hang, no half-written or overwritten file.

The datasets are small (a 6x4 grid on an 800x600 screen seen by the 640x400 pinhole-small camera,
rendered in about a second); the commands run as the user runs them, in a subprocess.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
import signal
import subprocess
import time

import cv2
import numpy as np
import pytest

from conftest import VENV_BIN, cli_env, ctrl_c_reaches_it, run_command
from rotstar_mrcal import dataset
from rotstar_mrcal.cli import common
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.simulate import Settings, preset_model, random_poses, write_dataset

LAYOUT = make_layout(screen=(800, 600), pitch=100, band=24)
FIRST = "rotstar_00.png"


@pytest.fixture(scope="module")
def seq(tmp_path_factory) -> str:
    """Two poses, 16-bit, 1 % noise; every pose gives all 24 corners"""
    path = str(tmp_path_factory.mktemp("faults") / "seq")
    model = preset_model("pinhole-small")
    write_dataset(path, LAYOUT, model, random_poses(model, LAYOUT, 2, np.random.default_rng(1), max_tilt_deg=30),
                  Settings(bits=16, seed=0, supersample=1))  # (read for labels and reasons only)
    return path


def copy_seq(seq: str, dst, poses=("pose000", "pose001")) -> str:
    """pattern.json and some poses of seq in a fresh folder"""
    out = str(dst)
    os.makedirs(out)
    shutil.copy(os.path.join(seq, "pattern.json"), out)
    for p in poses:
        shutil.copytree(os.path.join(seq, p), os.path.join(out, p))
    return out


def cli(tool: str, *args, cwd=None, timeout=None) -> subprocess.CompletedProcess:
    """The command as the user runs it (conftest.run_command); with a time limit (a hang): a real process"""
    return run_command(tool, *args, cwd=cwd, timeout=timeout, process=timeout is not None)


def one_line_error(r: subprocess.CompletedProcess, code: int = 2, *words: str) -> str:
    """The only stderr line of a refused command (argparse's usage lines aside); checks code and words"""
    assert r.returncode == code, (r.returncode, r.stderr)
    assert "Traceback" not in r.stderr, r.stderr
    lines = [line for line in r.stderr.strip().splitlines() if not line.startswith(("usage:", " "))]
    assert len(lines) == 1, r.stderr
    for w in words:
        assert w in lines[0], lines[0]
    return lines[0]


def digest(path) -> str:
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()


def leftovers(folder) -> list[str]:
    """Temporary files of atomic_write left in a folder"""
    return [f for f in os.listdir(folder) if ".part" in f]


# ---- 1. output paths: checked before the work, atomic, never over an input -------------
def test_detect_output_in_missing_folder(seq, tmp_path):
    r = cli("rotstar-detect", seq, "-o", "nodir/c.vnl", cwd=tmp_path)
    one_line_error(r, 2, "nodir/c.vnl", "no such folder")
    assert "[1/" not in r.stderr and r.stdout == ""  # refused before any pose was processed


def test_detect_output_under_a_file(seq, tmp_path):
    (tmp_path / "afile").write_text("x")
    r = cli("rotstar-detect", seq, "-o", "afile/c.vnl", cwd=tmp_path)
    one_line_error(r, 2, "afile/c.vnl", "is a file")
    assert (tmp_path / "afile").read_text() == "x"


def test_detect_output_over_an_input_frame_is_refused(seq, tmp_path):
    s = copy_seq(seq, tmp_path / "seq")
    frame = os.path.join(s, "pose000", FIRST)
    before = digest(frame)
    r = cli("rotstar-detect", s, "-o", frame, cwd=tmp_path)
    one_line_error(r, 2, frame, "input")
    assert digest(frame) == before and "[1/" not in r.stderr


def test_detect_output_over_pattern_json_is_refused(seq, tmp_path):
    s = copy_seq(seq, tmp_path / "seq", poses=("pose000",))
    before = digest(os.path.join(s, "pattern.json"))
    r = cli("rotstar-detect", s, "-o", os.path.join(s, "pattern.json"), cwd=tmp_path)
    one_line_error(r, 2, "pattern.json", "is the input")
    assert digest(os.path.join(s, "pattern.json")) == before


def test_detect_output_new_file_inside_a_pose_folder_is_refused(seq, tmp_path):
    s = copy_seq(seq, tmp_path / "seq", poses=("pose000",))
    r = cli("rotstar-detect", s, "-o", os.path.join(s, "pose000", "corners.vnl"), cwd=tmp_path)
    one_line_error(r, 2, "corners.vnl", "inside the input folder")
    assert not os.path.exists(os.path.join(s, "pose000", "corners.vnl"))


def test_detect_output_written_atomically_beside_the_dataset(seq, tmp_path):
    s = copy_seq(seq, tmp_path / "seq")
    r = cli("rotstar-detect", s, "-o", os.path.join(s, "corners.vnl"), cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    text = open(os.path.join(s, "corners.vnl")).read()
    assert text.count(FIRST) == 2 * LAYOUT.nx * LAYOUT.ny and leftovers(s) == []


def test_pattern_out_under_a_file(tmp_path):
    (tmp_path / "afile").write_text("x")
    r = cli("rotstar-pattern", "--out", "afile/pattern", cwd=tmp_path)
    one_line_error(r, 2, "afile/pattern", "afile is a file")
    assert "[1/" not in r.stderr


def test_pattern_out_is_a_file(tmp_path):
    (tmp_path / "afile").write_text("x")
    one_line_error(cli("rotstar-pattern", "--out", "afile", cwd=tmp_path), 2, "afile", "not a folder")


def test_pattern_files_written_atomically(tmp_path):
    r = cli("rotstar-pattern", "--out", "p", "--screen", "800x600", "--pitch", "100", "--band", "24", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    files = sorted(os.listdir(tmp_path / "p"))
    # 8 rotating-star, 10 identity (6x4 corners) and the checkerboard PNGs, json, html
    assert leftovers(tmp_path / "p") == [] and "pattern.json" in files and len(files) == 21
    assert dataset.read_pattern(str(tmp_path / "p"))[1].nx == 6


def test_simulate_out_under_a_file(tmp_path):
    (tmp_path / "afile").write_text("x")
    r = cli("rotstar-simulate", "--out", "afile/seq", "--camera", "pinhole-small", "--poses", "1", cwd=tmp_path)
    one_line_error(r, 2, "afile/seq", "afile is a file")


def test_simulate_out_is_the_pattern_folder(tmp_path):
    dataset.write_pattern(str(tmp_path / "pat"), LAYOUT)
    before = digest(tmp_path / "pat" / "pattern.json")
    r = cli("rotstar-simulate", "--out", "pat", "--pattern", "pat", "--camera", "pinhole-small", "--poses", "1",
            cwd=tmp_path)
    one_line_error(r, 2, "pat", "--pattern folder")
    assert digest(tmp_path / "pat" / "pattern.json") == before and os.listdir(tmp_path / "pat") == ["pattern.json"]


def test_segment_out_under_a_file(seq, tmp_path):
    (tmp_path / "afile").write_text("x")
    r = cli("rotstar-segment", os.path.join(seq, "pose000"), "--pattern", seq, "--out", "afile/pose000",
            cwd=tmp_path)
    one_line_error(r, 2, "afile/pose000", "afile is a file")


def test_segment_out_inside_the_recording_is_refused(seq, tmp_path):
    rec = tmp_path / "rec"
    shutil.copytree(os.path.join(seq, "pose000"), rec)
    r = cli("rotstar-segment", rec, "--pattern", seq, "--out", rec / "p", cwd=tmp_path)
    one_line_error(r, 2, "inside the input folder")
    assert not (rec / "p").exists()


def test_segment_out_beside_the_pattern_json_is_fine(seq, tmp_path):
    """The usual call, --pattern SEQ --out SEQ/<pose>, is not taken for writing over an input"""
    s = copy_seq(seq, tmp_path / "seq", poses=())
    r = cli("rotstar-segment", os.path.join(seq, "pose000"), "--pattern", s, "--out", os.path.join(s, "pose009"),
            cwd=tmp_path)
    assert r.returncode == 1 and "too short" in r.stderr and "input" not in r.stderr, r.stderr


def test_capture_out_under_a_file(seq, tmp_path):
    (tmp_path / "afile").write_text("x")
    r = cli("rotstar-capture", "--backend", "replay", "--device", "nothing.npy", "--pattern", seq,
            "--out", "afile/seq", cwd=tmp_path)
    one_line_error(r, 2, "afile/seq", "afile is a file")


def test_synth_out_under_a_file(tmp_path):
    (tmp_path / "afile").write_text("x")
    r = cli("rotstar-synth", "experiment", "--quick", "--out", "afile/out", cwd=tmp_path)
    one_line_error(r, 2, "afile/out", "afile is a file")


# ---- 2. pattern.json values --------------------------------------------------------------
def broken(d: dict, path: str, value):
    """d with d[a][b]... = value (value DELETE: the key removed)"""
    d = json.loads(json.dumps(d))
    *keys, last = path.split(".")
    t = d
    for k in keys:
        t = t[k]
    if value is DELETE:
        del t[last]
    else:
        t[last] = value
    return d


DELETE = object()
PATTERN_CASES = {  # id: (field, value, what the message says)
    "nx-negative": ("grid.nx", -3, "grid.nx is -3"),
    "nx-zero": ("grid.nx", 0, "grid.nx is 0"),
    "ny-one": ("grid.ny", 1, "grid.ny is 1"),
    "nx-huge": ("grid.nx", 10**12, "grid.nx is"),
    "nx-fraction": ("grid.nx", 5.5, "grid.nx is 5.5; must be an integer"),
    "nx-string": ("grid.nx", "6", "grid.nx is \"6\"; must be a number"),
    "nx-missing": ("grid.nx", DELETE, "grid.nx missing"),
    "nx-null": ("grid.nx", None, "grid.nx is null"),
    "pitch-nan": ("grid.pitch", math.nan, "grid.pitch is nan; must be finite"),
    "pitch-zero": ("grid.pitch", 0, "grid.pitch is 0"),
    "width-inf": ("screen.width", math.inf, "screen.width is inf; must be finite"),
    "width-negative": ("screen.width", -800, "screen.width is -800"),
    "height-huge": ("screen.height", 1e300, "screen.height is"),
    "pixel-pitch-zero": ("screen.pixel_pitch_m", 0, "screen.pixel_pitch_m is 0"),
    "pixel-pitch-bool": ("screen.pixel_pitch_m", True, "screen.pixel_pitch_m is true"),
    "origin-short": ("grid.origin", [1], "grid.origin"),
    "step-zero": ("element.step_rad", 0, "element.step_rad is 0"),
    "band-negative": ("element.band", -24, "element.band is -24"),
    "marker-outside": ("element.marker", [9, 0], "element.marker.i is 9"),
    "grid-off-screen": ("grid.origin", [700, 100], "do not fit on the 800x600 screen"),
    "grid-missing": ("grid", DELETE, "grid missing"),
    "frames-missing": ("frames", DELETE, "frames missing"),
    "frame-path": ("frames", [{"file": "../x.png", "kind": "rotstar"}] * 2, "not a plain file name"),
}


@pytest.mark.parametrize("case", PATTERN_CASES)
def test_bad_pattern_json_value(seq, tmp_path, case):
    field, value, says = PATTERN_CASES[case]
    s = copy_seq(seq, tmp_path / "seq", poses=("pose000",))
    d = broken(json.load(open(os.path.join(s, "pattern.json"))), field, value)
    with open(os.path.join(s, "pattern.json"), "w") as f:
        json.dump(d, f)  # (nan, inf as JSON's NaN, Infinity: Python reads them)
    line = one_line_error(cli("rotstar-detect", s, cwd=tmp_path), 2, os.path.join(s, "pattern.json") + ": ", says)
    assert "noise" not in line


def test_pattern_json_with_one_rotstar_frame(seq, tmp_path):
    s = copy_seq(seq, tmp_path / "seq", poses=("pose000",))
    d = json.load(open(os.path.join(s, "pattern.json")))
    d["frames"] = d["frames"][:1] + d["frames"][-1:]
    json.dump(d, open(os.path.join(s, "pattern.json"), "w"))
    one_line_error(cli("rotstar-detect", s, cwd=tmp_path), 2, "frames has 1 rotating-star frame(s); need at least 2")


def _identity_frames(d: dict) -> list[int]:
    return [k for k, f in enumerate(d["frames"]) if f["kind"] == "identity"]


def _swap_identity(d):
    k = _identity_frames(d)
    d["frames"][k[2]], d["frames"][k[3]] = d["frames"][k[3]], d["frames"][k[2]]


IDENTITY_CASES = {  # id: (change to pattern.json, what the message says)
    "frames-missing": (lambda d: d.update(frames=[f for f in d["frames"] if f["kind"] != "identity"]),
                       "frames: no identity frames, though the identity section describes 10"),
    "out-of-order": (_swap_identity, "frames: identity frames with indices [0, 1, 3, 2, 4"),
    "one-too-few": (lambda d: d["frames"].pop(_identity_frames(d)[-1]),
                    "frames: identity frames with indices [0, 1, 2, 3, 4, 5, 6, 7, 8]; the 6x4 grid's code needs 0..9"),
    "index-not-a-number": (lambda d: d["frames"][_identity_frames(d)[0]].update(index="0"),
                           "identity frames with indices ['0', 1"),
    "section-of-another-grid": (lambda d: d.update(identity=make_layout().to_dict()["identity"]),
                                "identity: frames 13, weight 6; a 6x4 grid's code has 10 frames of weight 5"),
    "section-missing": (lambda d: d.pop("identity"), "identity missing: frames lists 10 identity frame(s)"),
    "section-not-an-object": (lambda d: d.update(identity=[1, 2]), "identity is not an object"),
    "codewords-changed": (lambda d: d["identity"]["codewords"].reverse(), "identity.codewords differ"),
}


def _write_identity_case(seq, dst, case) -> str:
    s = copy_seq(seq, dst, poses=("pose000",))
    d = json.load(open(os.path.join(s, "pattern.json")))
    IDENTITY_CASES[case][0](d)
    with open(os.path.join(s, "pattern.json"), "w") as f:
        json.dump(d, f)
    return s


@pytest.mark.parametrize("case", IDENTITY_CASES)
def test_bad_identity_frames_in_pattern_json(seq, tmp_path, case):
    s = _write_identity_case(seq, tmp_path / "seq", case)
    one_line_error(cli("rotstar-detect", s, cwd=tmp_path), 2, os.path.join(s, "pattern.json") + ": ",
                   IDENTITY_CASES[case][1])


def test_bad_identity_frames_refused_by_every_tool(seq, tmp_path):
    """The same one line, exit 2, from the tools that read a pattern.json before recording or rendering"""
    s = _write_identity_case(seq, tmp_path / "seq", "one-too-few")
    says = os.path.join(s, "pattern.json") + ": frames: identity frames with indices"
    rec = os.path.join(s, "pose000")
    for tool, *args in (("rotstar-segment", rec, "--pattern", s, "--out", tmp_path / "out" / "pose000"),
                        ("rotstar-capture", "--backend", "replay", "--device", "nothing.npy", "--pattern", s,
                         "--out", tmp_path / "cap"),
                        ("rotstar-simulate", "--pattern", s, "--out", tmp_path / "sim", "--camera", "pinhole-small"),
                        ("rotstar-calibrate", s, "--outdir", tmp_path / "cal")):
        one_line_error(cli(tool, *args, cwd=tmp_path), 2, says)
    assert not any((tmp_path / d).exists() for d in ("out", "cap", "sim", "cal"))


def test_pattern_json_not_an_object(tmp_path):
    s = tmp_path / "seq"
    (s / "pose000").mkdir(parents=True)
    (s / "pattern.json").write_text("[1, 2, 3]\n")
    one_line_error(cli("rotstar-detect", s, cwd=tmp_path), 2, "pattern.json: not a rotstar pattern description")


# ---- 3. rotstar-pattern arguments --------------------------------------------------------
@pytest.mark.parametrize("args,says", [
    (["--frames", "0"], "--frames: '0': must be an integer >= 2"),
    (["--frames", "1"], "--frames: '1': must be an integer >= 2"),
    (["--step", "pi/0"], "--step: 'pi/0'"),
    (["--step", "0"], "--step: '0': the rotation per frame must be finite and not 0"),
    (["--step", "nan"], "--step: 'nan'"),
    (["--frames", "20", "--step", "pi/8"], "reach pi, where the frames repeat"),
    (["--gamma", "0"], "--gamma: '0'"),
    (["--gamma", "inf"], "--gamma: 'inf'"),
    (["--ppi", "-264"], "--ppi: '-264'"),
    (["--pixel-pitch-mm", "0"], "--pixel-pitch-mm: '0'"),
    (["--pitch", "-150"], "--pitch: '-150'"),
    (["--band", "0"], "--band: '0'"),
    (["--nx", "0"], "--nx: '0'"),
    (["--screen", "0x1640"], "--screen: '0x1640': width and height must be positive"),
], ids=lambda v: "_".join(v) if isinstance(v, list) else None)
def test_pattern_nonsense_arguments(tmp_path, args, says):
    r = cli("rotstar-pattern", "--out", "p", *args, cwd=tmp_path)
    one_line_error(r, 2, says)
    assert not (tmp_path / "p").exists()


# ---- 4. rotstar-detect numeric options ---------------------------------------------------
@pytest.mark.parametrize("args", [["--window", "-5"], ["--window", "0"], ["--window", "nan"], ["--window", "inf"],
                                  ["--window", "1"], ["--max-motion", "-1"], ["--max-motion", "nan"],
                                  ["--max-motion", "0"], ["--jobs", "0"], ["--jobs", "-2"], ["--jobs", "1.5"]],
                         ids="_".join)
def test_detect_nonsense_numbers(seq, tmp_path, args):
    r = cli("rotstar-detect", seq, *args, cwd=tmp_path)
    one_line_error(r, 2, f"argument {args[0]}", f"'{args[1]}': must be")
    assert r.stdout == ""


def test_detect_smallest_window_works(seq, tmp_path):
    r = cli("rotstar-detect", seq, "--window", "2", cwd=tmp_path)
    assert r.returncode == 0 and "2 of 2 poses gave a board" in r.stderr, r.stderr


# ---- 5. pose folders whose files do not match pattern.json -------------------------------
def renamed_pose(src: str, dst: str) -> None:
    os.makedirs(dst)
    for f in os.listdir(src):
        shutil.copy(os.path.join(src, f), os.path.join(dst, "frame_" + f.split("_")[-1]))


def test_renamed_frames_are_reported_as_a_skipped_pose(seq, tmp_path):
    s = copy_seq(seq, tmp_path / "seq", poses=("pose000",))
    renamed_pose(os.path.join(seq, "pose001"), os.path.join(s, "renamed"))
    r = cli("rotstar-detect", s, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    lines = [line for line in r.stderr.splitlines() if "] renamed:" in line]
    assert len(lines) == 1 and "skipped" in lines[0] and f"{s}/renamed: no frame named as in pattern.json" in lines[0]
    assert FIRST in lines[0] and "frame_00.png" in lines[0]
    assert "1 of 2 poses gave a board" in r.stderr


def test_no_folder_matches_pattern_json(seq, tmp_path):
    s = str(tmp_path / "seq")
    os.makedirs(s)
    shutil.copy(os.path.join(seq, "pattern.json"), s)
    renamed_pose(os.path.join(seq, "pose000"), os.path.join(s, "renamed"))
    r = cli("rotstar-detect", s, cwd=tmp_path)
    one_line_error(r, 2, "no pose folders", f"{s}/renamed: no frame named as in pattern.json", "frame_00.png")


# ---- 6. darkness judged on the data, not the container -----------------------------------
def rewrite_pose(src: str, dst: str, f) -> None:
    os.makedirs(dst)
    for fn in os.listdir(src):
        img = cv2.imread(os.path.join(src, fn), cv2.IMREAD_UNCHANGED)
        assert cv2.imwrite(os.path.join(dst, fn), f(img))


def test_10bit_values_in_16bit_png_are_not_dark(seq, tmp_path):
    s = copy_seq(seq, tmp_path / "seq", poses=())
    rewrite_pose(os.path.join(seq, "pose000"), os.path.join(s, "tenbit"), lambda img: img >> 6)  # max ~920 DN
    assert cv2.imread(os.path.join(s, "tenbit", FIRST), cv2.IMREAD_UNCHANGED).max() < 1024
    r = cli("rotstar-detect", s, cwd=tmp_path)
    assert r.returncode == 0 and "tenbit: 24 of 24 corners" in r.stderr, r.stderr


def test_real_darkness_is_still_detected(seq, tmp_path):
    """A sensor in the dark: black level, read noise, and a signal of a few DN"""
    rng = np.random.default_rng(0)
    s = copy_seq(seq, tmp_path / "seq", poses=())
    rewrite_pose(os.path.join(seq, "pose000"), os.path.join(s, "dark"),
                 lambda img: np.clip(200 + img * 0.0005 + rng.normal(0, 30, img.shape), 0, 65535).astype(np.uint16))
    rewrite_pose(os.path.join(seq, "pose000"), os.path.join(s, "black"), lambda img: np.zeros_like(img))
    r = cli("rotstar-detect", s, cwd=tmp_path)
    assert r.returncode == 1, r.stderr
    for pose in ("dark", "black"):
        line = next(line for line in r.stderr.splitlines() if f" {pose}: " in line)
        assert "skipped: all dark" in line, line


# ---- 7. reasons that name the cause ------------------------------------------------------
def test_segment_on_a_three_frame_recording(seq, tmp_path):
    rec = tmp_path / "rec"
    rec.mkdir()
    for k in range(3):
        shutil.copy(os.path.join(seq, "pose000", f"rotstar_0{k}.png"), rec / f"{k}.png")
    r = cli("rotstar-segment", rec, "--pattern", seq, "--out", tmp_path / "out" / "pose000", cwd=tmp_path)
    assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
    line = r.stderr.strip().splitlines()[-1]  # (after the line describing the recording)
    assert "too short: 3 frame(s), need at least" in line and "not still" not in r.stderr, line


@pytest.mark.parametrize("tool", ["rotstar-detect", "rotstar-segment", "rotstar-simulate"])
def test_missing_dataset_folder(tmp_path, tool):
    args = {"rotstar-detect": ["nothing"], "rotstar-segment": ["rec", "--pattern", "nothing", "--out", "o/p"],
            "rotstar-simulate": ["--pattern", "nothing", "--out", "o", "--poses", "1"]}[tool]
    one_line_error(cli(tool, *args, cwd=tmp_path), 2, "nothing: no such folder")


def test_dataset_folder_without_pattern_json_keeps_its_message(tmp_path):
    (tmp_path / "seq" / "pose000").mkdir(parents=True)
    one_line_error(cli("rotstar-detect", "seq", cwd=tmp_path), 2, "seq/pattern.json: no pattern.json")


# ---- 10. interrupts and odd files ----------------------------------------------------------
def children(pid: int) -> set[int]:
    """Live child processes of pid (from /proc; zombies do not count)"""
    out = set()
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                stat = open(f"/proc/{d}/stat").read()
            except OSError:
                continue
            fields = stat.rsplit(")", 1)[1].split()
            if int(fields[1]) == pid and fields[0] != "Z":
                out.add(int(d))
    return out


def alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@pytest.fixture(scope="module")
def many_poses(seq, tmp_path_factory) -> str:
    """24 copies of the two poses: a few seconds of work for two processes"""
    s = str(tmp_path_factory.mktemp("many") / "seq")
    os.makedirs(s)
    shutil.copy(os.path.join(seq, "pattern.json"), s)
    for k in range(24):
        shutil.copytree(os.path.join(seq, f"pose00{k % 2}"), os.path.join(s, f"pose{k:03d}"))
    return s


def start_detect(many_poses, tmp_path, *extra, children_first=2):
    """rotstar-detect started on many_poses, once it has children_first child processes"""
    p = subprocess.Popen([os.path.join(VENV_BIN, "rotstar-detect"), many_poses, "--jobs", "2", *extra],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path, env=cli_env(),
                         start_new_session=True, preexec_fn=ctrl_c_reaches_it)
    t0 = time.monotonic()
    while len(children(p.pid)) < children_first:  # the resource tracker and the forkserver
        assert p.poll() is None and time.monotonic() - t0 < 30, p.communicate()
        time.sleep(0.02)
    if children_first >= 2:
        time.sleep(0.3)  # the workers are busy with poses
    return p, children(p.pid)


def test_sigterm_leaves_no_worker_running(many_poses, tmp_path):
    p, workers = start_detect(many_poses, tmp_path, "-o", "c.vnl")
    os.kill(p.pid, signal.SIGTERM)
    out, err = p.communicate(timeout=30)
    t0 = time.monotonic()
    while any(alive(w) for w in workers) and time.monotonic() - t0 < 5:
        time.sleep(0.05)
    assert not any(alive(w) for w in workers), workers
    assert p.returncode == 130 and "Traceback" not in err, err
    assert err.strip().splitlines()[-1] == "rotstar-detect: interrupted"
    assert os.listdir(tmp_path) == []  # no corners.vnl, no temporary file


@pytest.mark.parametrize("children_first", [2, 1], ids=["while-working", "while-the-pool-starts"])
def test_ctrl_c_prints_one_line_and_exits_130(many_poses, tmp_path, children_first):
    """Ctrl-C at work, or while the pool starts (CI once lost that one: the run went on to exit 0)"""
    p, workers = start_detect(many_poses, tmp_path, "-o", "c.vnl", children_first=children_first)
    os.killpg(p.pid, signal.SIGINT)  # as a terminal does: the whole process group
    out, err = p.communicate(timeout=30)
    assert p.returncode == 130 and "Traceback" not in err and "KeyboardInterrupt" not in err, err
    assert err.strip().splitlines()[-1] == "rotstar-detect: interrupted"
    assert [line for line in err.splitlines() if not line.startswith("[")] == ["rotstar-detect: interrupted"]
    time.sleep(0.2)
    assert not any(alive(w) for w in workers) and os.listdir(tmp_path) == []


def test_ctrl_c_one_process(many_poses, tmp_path):
    p = subprocess.Popen([os.path.join(VENV_BIN, "rotstar-detect"), many_poses, "-o", "c.vnl"], stderr=subprocess.PIPE,
                         text=True, cwd=tmp_path, env=cli_env(), preexec_fn=ctrl_c_reaches_it)
    t0 = time.monotonic()
    while "[1/" not in open(f"/proc/{p.pid}/cmdline").read() and time.monotonic() - t0 < 1.5:
        time.sleep(0.05)
    p.send_signal(signal.SIGINT)
    err = p.communicate(timeout=30)[1]
    assert p.returncode == 130 and "Traceback" not in err and err.strip().endswith("rotstar-detect: interrupted"), err
    assert os.listdir(tmp_path) == []


def test_fifo_named_like_a_frame_does_not_hang(seq, tmp_path):
    s = copy_seq(seq, tmp_path / "seq")
    fifo = os.path.join(s, "pose001", "rotstar_03.png")
    os.remove(fifo)
    os.mkfifo(fifo)
    r = cli("rotstar-detect", s, cwd=tmp_path, timeout=60)
    assert r.returncode == 0, r.stderr
    line = next(line for line in r.stderr.splitlines() if "pose001" in line)
    assert f"skipped: {fifo}: a FIFO, not a regular file" in line
    assert "1 of 2 poses gave a board" in r.stderr


def test_fifo_as_pattern_json_does_not_hang(tmp_path):
    s = tmp_path / "seq"
    s.mkdir()
    os.mkfifo(s / "pattern.json")
    one_line_error(cli("rotstar-detect", s, cwd=tmp_path, timeout=60), 2, "pattern.json: a FIFO, not a regular file")


def test_fifo_in_a_recording_does_not_hang(seq, tmp_path):
    rec = tmp_path / "rec"
    shutil.copytree(os.path.join(seq, "pose000"), rec)
    os.mkfifo(rec / "zz.png")
    r = cli("rotstar-segment", rec, "--pattern", seq, "--out", tmp_path / "o" / "p", cwd=tmp_path, timeout=60)
    one_line_error(r, 2, "zz.png: not a regular file")


# ---- 11. corrupt inputs of simulate and report -------------------------------------------
def test_simulate_corrupt_camera_model(tmp_path):
    (tmp_path / "cam.cameramodel").write_text("this is not a camera model\n")
    r = cli("rotstar-simulate", "--out", "seq", "--camera", "cam.cameramodel", "--poses", "1", cwd=tmp_path)
    one_line_error(r, 2, "cam.cameramodel: not a readable camera model")
    assert not (tmp_path / "seq").exists()


@pytest.mark.parametrize("content", ["{not json", "[1, 2]", "\xff\xfe binary"], ids=["not-json", "list", "binary"])
def test_report_corrupt_results_file(tmp_path, content):
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "results.json").write_bytes(content.encode("latin-1"))
    r = cli("rotstar-report", "x", "--out", "rep", cwd=tmp_path)
    one_line_error(r, 2, "x/results.json: not a rotstar-crossval results file")


# ---- the shared helpers (cli/common.py) ----------------------------------------------------
@pytest.mark.parametrize("tool", ["rotstar-pattern", "rotstar-detect", "rotstar-simulate", "rotstar-segment",
                                  "rotstar-capture", "rotstar-synth"])
def test_help_documents_the_exit_codes(tool):
    r = cli(tool, "--help")
    text = " ".join(r.stdout.split())  # (argparse wraps the lines)
    assert r.returncode == 0 and "130 interrupted" in text and "2 bad input or arguments" in text


def test_atomic_write_removes_the_temporary_file_on_failure(tmp_path):
    fn = tmp_path / "out.txt"
    fn.write_text("old")
    with pytest.raises(KeyboardInterrupt):
        with common.atomic_write(str(fn)) as f:
            f.write("half")
            raise KeyboardInterrupt
    assert fn.read_text() == "old" and os.listdir(tmp_path) == ["out.txt"]
    with common.atomic_write(str(fn)) as f:
        f.write("new")
    assert fn.read_text() == "new" and os.listdir(tmp_path) == ["out.txt"]


def test_run_turns_failures_into_a_line_and_a_code(capsys):
    def main(argv):
        common.fail(f"{argv[0]}: bad", common.EXIT_FAILED)

    assert common.run("rotstar-x", main, ["seq/pattern.json"]) == 1
    assert capsys.readouterr().err == "rotstar-x: seq/pattern.json: bad\n"

    def interrupted(argv):
        raise KeyboardInterrupt

    assert common.run("rotstar-x", interrupted) == 130
    assert capsys.readouterr().err == "rotstar-x: interrupted\n"
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL


@pytest.mark.slow  # make test-slow: a longer end-to-end run
def test_synth_sigterm_stops_at_once_and_leaves_no_worker(tmp_path):
    """The sweep's pool (spawned workers) is terminated too, not drained first"""
    p = subprocess.Popen([os.path.join(VENV_BIN, "rotstar-synth"), "experiment", "--quick", "--jobs", "2",
                          "--no-plots", "--out", "o"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         cwd=tmp_path, env=cli_env())

    def workers():
        return {c for c in children(p.pid) if "spawn_main" in open(f"/proc/{c}/cmdline").read()}

    t0 = time.monotonic()
    while len(workers()) < 2:
        assert p.poll() is None and time.monotonic() - t0 < 60, p.communicate()
        time.sleep(0.05)
    w = workers()
    time.sleep(1.0)
    os.kill(p.pid, signal.SIGTERM)
    t1 = time.monotonic()
    err = p.communicate(timeout=60)[1]
    assert p.returncode == 130 and "Traceback" not in err, err
    assert err.strip().splitlines()[-1] == "rotstar-synth: interrupted" and time.monotonic() - t1 < 15
    time.sleep(0.2)
    assert not any(alive(x) for x in w)
    assert not os.path.exists(tmp_path / "o" / "summary.md")


def test_ctrl_c_while_the_command_starts_is_one_line(tmp_path):
    """A Ctrl-C that comes while a console script still imports its modules (numpy, OpenCV, mrcal): one line and
    exit 130, not a KeyboardInterrupt traceback (rotstar_mrcal/cli/__init__.py). The Ctrl-C is sent by the
    process to itself right after the cli package, where the real script would still be importing."""
    script = ("import os, signal, sys; sys.argv[0] = os.path.join(os.getcwd(), 'rotstar-detect'); "
              "import rotstar_mrcal.cli; os.kill(os.getpid(), signal.SIGINT); import rotstar_mrcal.cli.detect; "
              "print('not interrupted')")
    r = subprocess.run([os.path.join(VENV_BIN, "python"), "-c", script], capture_output=True, text=True,
                       cwd=tmp_path, env=cli_env(), preexec_fn=ctrl_c_reaches_it, timeout=60)
    assert r.returncode == 130 and r.stderr == "rotstar-detect: interrupted\n" and r.stdout == "", r
    # once the command runs, Python's own handler is back: cli.common.run catches the KeyboardInterrupt
    script = ("import os, signal, sys; sys.argv[0] = 'rotstar-x'; import rotstar_mrcal.cli.common as c; "
              "sys.exit(c.run('rotstar-x', lambda argv: os.kill(os.getpid(), signal.SIGINT) or time.sleep(5)))")
    r = subprocess.run([os.path.join(VENV_BIN, "python"), "-c", "import time; " + script], capture_output=True,
                       text=True, cwd=tmp_path, env=cli_env(), preexec_fn=ctrl_c_reaches_it, timeout=60)
    assert r.returncode == 130 and r.stderr.strip() == "rotstar-x: interrupted", r

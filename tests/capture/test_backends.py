"""Capture without a camera: the replay backend, the libcamera and realsense backends' edges, and
rotstar-capture driven by replayed simulated recordings of the looping player"""

from __future__ import annotations

import io
import json
import os
import stat
import sys
import textwrap

import cv2
import numpy as np
import pytest

from conftest import SMALL_LAYOUT

from rotstar_mrcal import dataset as ds, simulate
from rotstar_mrcal.capture.backend_libcamera import LibcameraSource
from rotstar_mrcal.capture.backend_replay import ReplaySource, save_recording
from rotstar_mrcal.capture.backends import open_source
from rotstar_mrcal.capture.motion import is_still, still_fraction
from rotstar_mrcal.capture.source import CaptureError, record
from rotstar_mrcal.capture.simulated import camera_stream, loop_irradiance, player_schedule
from rotstar_mrcal.cli.capture import main as rotstar_capture
from rotstar_mrcal.pattern.loop import player_loop
from rotstar_mrcal.pattern.layout import make_layout

LAYOUT = SMALL_LAYOUT  # (the pattern_dir fixture's) the default sequence: 8 + 10 identity frames + 1
N_ENTRIES = len(player_loop(LAYOUT.frames()))
HOLD = 18  # 20 entries x 18 refreshes at 60 Hz = 6 s = exactly 150 frames at 25 fps: the stream repeats
LOOP = 150


@pytest.fixture(scope="module")
def loop_frames():
    """One loop of the player (150 camera frames, 16-bit) as the pinhole-small camera sees it; repeats seamlessly"""
    model = simulate.preset_model("pinhole-small")
    rt = simulate.random_poses(model, LAYOUT, 1, np.random.default_rng(3))[0]
    E = loop_irradiance(LAYOUT, model, rt, supersample=2)
    sched = player_schedule(N_ENTRIES, hold=HOLD, refresh_hz=60, duration=12.5)
    frames, _ = camera_stream(E, sched, LOOP, fps=25, exposure_s=0.012, noise=0.01, t0=0.013, rng=7)
    return frames


# ---- replay ----------------------------------------------------------------------------------
def test_replay_folder_npy_raw_and_video(tmp_path):
    frames = (np.arange(6 * 4 * 5).reshape(6, 4, 5) * 1000).astype(np.uint16)
    folder = tmp_path / "frames"
    folder.mkdir()
    for k, f in enumerate(frames):  # natural order: frame2 before frame10
        cv2.imwrite(str(folder / f"frame{k * 4}.png"), f)
    src = ReplaySource(str(folder))
    assert len(src) == 6 and src.full_scale == 65535.0
    got = record(src, 10)
    np.testing.assert_array_equal(got.frames, frames)
    assert got.sequence.tolist() == list(range(6)) and src.read() is None
    np.testing.assert_array_equal(src.frames()[3], frames[3])

    save_recording(str(tmp_path / "r.npy"), frames, sequence=[0, 1, 2, 4, 5, 6], fps=25)
    src = open_source("replay", device=str(tmp_path / "r.npy"), fps=None)
    rec = record(src, 6)
    assert rec.dropped == 1 and src.fps == 25.0 and rec.t_ns[3] == 4 * 40_000_000

    (tmp_path / "dump.raw").write_bytes(frames.tobytes())  # as v4l2-ctl --stream-to writes it
    with pytest.raises(CaptureError, match="needs --size WxH and --fourcc"):
        ReplaySource(str(tmp_path / "dump.raw"))
    src = ReplaySource(str(tmp_path / "dump.raw"), size=(5, 4), fourcc="Y16")
    np.testing.assert_array_equal(src.frames(), frames)
    with pytest.raises(CaptureError, match="not a whole number of 4x4 Y16 frames"):
        ReplaySource(str(tmp_path / "dump.raw"), size=(4, 4), fourcc="Y16")

    grey8 = (np.arange(5)[:, None, None] * 50 + np.zeros((5, 48, 64))).astype(np.uint8)
    w = cv2.VideoWriter(str(tmp_path / "v.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 25, (64, 48), isColor=False)
    for f in grey8:
        w.write(f)
    w.release()
    src = ReplaySource(str(tmp_path / "v.avi"))
    v = src.frames()
    assert v.shape == (5, 48, 64) and v.dtype == np.uint8 and src.fps == 25.0
    assert np.abs(v.astype(int) - grey8).max() <= 3  # lossy
    assert any("lossy" in n for n in src.info()["notes"])

    colour = tmp_path / "colour"
    colour.mkdir()
    cv2.imwrite(str(colour / "a.png"), np.dstack([grey8[1]] * 3))  # grey stored as colour: exact
    cv2.imwrite(str(colour / "b.png"), np.dstack([grey8[1], grey8[2], grey8[3]]))
    src = ReplaySource(str(colour))
    np.testing.assert_array_equal(src.read().image, grey8[1])
    assert src.read().image.ndim == 2 and any("converted to grey" in n for n in src.notes)
    (tmp_path / "empty").mkdir()
    with pytest.raises(CaptureError, match="no image files"):
        ReplaySource(str(tmp_path / "empty"))
    with pytest.raises(CaptureError, match="neither a folder of frames"):
        ReplaySource(str(tmp_path / "nothing.mkv"))


# ---- libcamera (a fake `cam`) and realsense (not installed) ------------------------------------
FAKE_CAM = """\
    #!{python}
    import os, re, sys
    import numpy as np
    args = sys.argv[1:]
    with open(os.environ["FAKE_CAM_LOG"], "a") as log:
        log.write(" ".join(args) + "\\n")
        script = [a for a in args if a.startswith("--script=")]
        if script:
            log.write(open(script[0].split("=", 1)[1]).read())
    n = int([a for a in args if a.startswith("-C")][0][2:])
    pattern = [a for a in args if a.startswith("-F")][0][2:]
    fmt = dict(kv.split("=") for kv in args[args.index("-s") + 1].split(","))
    w, h = int(fmt["width"]), int(fmt["height"])
    for k in range(n):
        img = (np.arange(w * h).reshape(h, w) + 100 * k).astype("<u2")
        row = np.zeros((h, w * 2 + 32), np.uint8)          # a stride wider than the row
        row[:, : 2 * w] = img.view(np.uint8).reshape(h, -1)
        row.tofile(pattern.replace("#", f"stream0-{{k + 5:06d}}"))
    """


def test_libcamera_backend_with_a_fake_cam(tmp_path, monkeypatch):
    cam = tmp_path / "cam"
    cam.write_text(textwrap.dedent(FAKE_CAM).format(python=sys.executable))
    cam.chmod(cam.stat().st_mode | stat.S_IEXEC)
    monkeypatch.setenv("FAKE_CAM_LOG", str(tmp_path / "log"))
    src = LibcameraSource(camera="2", size=(8, 3), pixelformat="Y16", chunk=3, cam=str(cam))
    assert src.set_exposure_us(4000) == 4000.0
    src.set_gain(2.0)
    frames = [src.read() for _ in range(4)]  # two chunks: cam runs twice
    assert [f.sequence for f in frames] == [5, 6, 7, 14]
    np.testing.assert_array_equal(frames[1].image, (np.arange(24).reshape(3, 8) + 100).astype(np.uint16))
    log = (tmp_path / "log").read_text()
    assert log.count("-c 2 -C3 -s width=8,height=3,pixelformat=R16") == 2
    assert "ExposureTime: 4000" in log and "AeEnable: false" in log and "AnalogueGain: 2.0" in log
    with pytest.raises(CaptureError, match="not installed"):
        LibcameraSource(cam=str(tmp_path / "no-such-cam"))
    with pytest.raises(CaptureError, match="use R8 .GREY. or R16"):
        LibcameraSource(pixelformat="YUYV", cam=str(cam))


def test_realsense_backend_needs_pyrealsense2(monkeypatch):
    monkeypatch.setitem(sys.modules, "pyrealsense2", None)  # as if not installed
    with pytest.raises(CaptureError, match="needs pyrealsense2"):
        open_source("realsense")


def test_stillness():
    d = np.r_[np.nan, [0.001] * 11, 0.05, [0.001] * 11, 0.06]
    assert still_fraction(d, 0.003) == pytest.approx(22 / 24) and is_still(d, 0.003)
    assert not is_still(np.r_[np.nan, [0.02] * 24], 0.003)


# ---- rotstar-capture on replayed recordings ---------------------------------------------------
def run_capture(argv, capsys, source=None, stdin: str | None = None, monkeypatch=None):
    if stdin is not None:
        monkeypatch.setattr(sys, "stdin", io.StringIO(stdin))
    code = rotstar_capture([str(a) for a in argv], source=source)
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.slow  # make test-slow: a longer end-to-end run
def test_capture_auto_two_poses_from_a_replay(loop_frames, pattern_dir, tmp_path, capsys):
    """Pose A (still), the camera moving, pose B (still, the board elsewhere): two poses, then the end"""
    A = np.concatenate([loop_frames] * 3)[:400]
    moving = np.stack([np.roll(loop_frames[k % LOOP], (k, 2 * k), axis=(0, 1)) for k in range(30)])
    B = np.roll(np.concatenate([loop_frames] * 4)[:520], (-120, -200), axis=(1, 2))
    save_recording(str(tmp_path / "session.npy"), np.concatenate([A, moving, B]), fps=25)
    out_dir = tmp_path / "seq"
    code, out, err = run_capture(["--backend", "replay", "--device", tmp_path / "session.npy",
                                  "--pattern", pattern_dir, "--out", out_dir, "--auto", "--frames", 380,
                                  "--keep-raw"], capsys)
    assert code == 0, err
    assert out.split() == [str(out_dir / "pose000"), str(out_dir / "pose001")]
    assert "pose000: board complete (24/24)" in err and "pose001: board complete (24/24)" in err
    assert "waiting for the view to move and then be still" in err and "the recording ended" in err
    assert "corners in" in err and "nothing yet near" in err  # coverage so far
    cov = cv2.imread(str(out_dir / "coverage.png"))
    assert cov.shape == (400, 640, 3)
    log = json.loads((out_dir / "capture.json").read_text())
    assert log["source"]["backend"] == "replay" and [e["pose"] for e in log["poses"]["seq"]] == ["pose000", "pose001"]
    assert (out_dir / "raw" / "pose001.npy").exists() and (out_dir / "raw" / "pose001.json").exists()
    # pose B's board is where pose B put it: 120 rows up, 200 columns left of pose A's
    c = [json.loads((out_dir / p / "segment.json").read_text()) for p in ("pose000", "pose001")]
    assert all(x["quick_check"]["corners"] == 24 for x in c)
    a = cv2.imread(str(out_dir / "pose000" / "rotstar_00.png"), cv2.IMREAD_UNCHANGED).astype(float)
    b = cv2.imread(str(out_dir / "pose001" / "rotstar_00.png"), cv2.IMREAD_UNCHANGED).astype(float)
    assert np.abs(np.roll(a, (-120, -200), axis=(0, 1))[40:-40, 80:-80] - b[40:-40, 80:-80]).mean() < 0.01 * 65535
    # every pose holds every frame of pattern.json, the identity frames included
    names = [f["file"] for f in LAYOUT.frames()]
    assert "identity_09.png" in names and "identity_10.png" not in names
    for p in ("pose000", "pose001"):
        assert sorted(f for f in os.listdir(out_dir / p) if f.endswith(".png")) == sorted(names)


def test_capture_interactive_and_failures(loop_frames, pattern_dir, tmp_path, capsys, monkeypatch):
    rec = np.concatenate([loop_frames] * 3)
    save_recording(str(tmp_path / "still.npy"), rec, fps=25)
    # Enter, then q
    code, out, err = run_capture(["--backend", "replay", "--device", tmp_path / "still.npy", "--pattern", pattern_dir,
                                  "--out", tmp_path / "a", "--frames", 360], capsys, stdin="\nq\n",
                                 monkeypatch=monkeypatch)
    assert code == 0, err
    assert "pose000: press Enter to record the next 360 frames of the replay" in err and "pose001: press" in err
    assert out.split() == [str(tmp_path / "a" / "pose000")] and not (tmp_path / "a" / "raw").exists()
    # a recording shorter than a loop (here: without the start marker): said so, nothing written, exit 1
    code, out, err = run_capture(["--backend", "replay", "--device", tmp_path / "still.npy", "--pattern", pattern_dir,
                                  "--out", tmp_path / "b", "--frames", 120, "--poses", 1], capsys, stdin="\n",
                                 monkeypatch=monkeypatch)
    assert code == 1 and "pose000: not usable: no start marker" in err and out == ""
    # bad arguments
    with pytest.raises(SystemExit):
        rotstar_capture(["--backend", "replay", "--device", "x.npy", "--pattern", str(pattern_dir), "--out", "o",
                         "--exposure", "4000"])
    code, out, err = run_capture(["--backend", "replay", "--device", tmp_path / "missing.npy", "--pattern",
                                  pattern_dir, "--out", tmp_path / "c"], capsys)
    assert code == 1 and "cannot read" in err
    code, out, err = run_capture(["--backend", "replay", "--device", tmp_path / "still.npy", "--pattern",
                                  tmp_path / "nothing", "--out", tmp_path / "c"], capsys)
    assert code == 2 and "nothing: no such folder" in err


def test_segment_cli_on_a_folder_of_8bit_frames(loop_frames, pattern_dir, tmp_path, capsys):
    from rotstar_mrcal.cli.segment import main as rotstar_segment

    folder = tmp_path / "frames"
    folder.mkdir()
    for k, f in enumerate(np.concatenate([loop_frames] * 2)[:300]):
        cv2.imwrite(str(folder / f"{k}.png"), (f // 257).astype(np.uint8))
    code = rotstar_segment([str(folder), "--pattern", str(pattern_dir / "pattern.json"), "--out",
                            str(tmp_path / "seq" / "p"), "--average", "4"])
    out, err = capsys.readouterr()
    assert code == 0, err
    img = cv2.imread(str(tmp_path / "seq" / "p" / "rotstar_00.png"), cv2.IMREAD_UNCHANGED)
    assert img.dtype == np.uint16 and img.max() > 40000  # 8-bit averages scaled by 257
    assert "board found: 24 of 24 corners (complete)" in err
    info = json.loads((tmp_path / "seq" / "p" / "segment.json").read_text())
    assert all(b - a == 4 for a, b in info["frames_averaged"].values())
    # again: refused without --force
    assert rotstar_segment([str(folder), "--pattern", str(pattern_dir), "--out", str(tmp_path / "seq" / "p")]) == 2
    # and a 10-bit recording in 16-bit words is scaled up
    save_recording(str(tmp_path / "ten.npy"), np.concatenate([loop_frames] * 2)[:300] // 64)
    assert rotstar_segment([str(tmp_path / "ten.npy"), "--pattern", str(pattern_dir), "--out",
                            str(tmp_path / "seq" / "q")]) == 0
    err = capsys.readouterr().err
    assert "10-bit data in a 16-bit word? scaled by 64" in err and "board found: 24 of 24" in err


# ---- the paper's whole sequence ----------------------------------------------------------------
def test_capture_paper_sequence_one_pose(tmp_path, capsys):
    """rotstar-capture on a replay of the player showing rotstar-pattern --paper-sequence (29 loop entries): the pose
    holds every frame, the phase shifts and the star included, each its own display frame"""
    paper = make_layout(screen=(800, 600), pitch=100, band=24, phase_period=100, star_segments=16)
    n = len(player_loop(paper.frames()))
    hold = 24  # 29 entries x 24 refreshes at 60 Hz = 11.6 s = 290 camera frames at 25 fps: the stream repeats
    model = simulate.preset_model("pinhole-small")
    rt = simulate.random_poses(model, paper, 1, np.random.default_rng(3))[0]
    E = loop_irradiance(paper, model, rt, supersample=2)
    sched = player_schedule(n, hold=hold, refresh_hz=60, duration=25)
    frames, _ = camera_stream(E, sched, 290, fps=25, exposure_s=0.012, noise=0.01, t0=0.013, rng=7)
    save_recording(str(tmp_path / "session.npy"), np.concatenate([frames] * 3), fps=25)
    (tmp_path / "pattern").mkdir()
    (tmp_path / "pattern" / "pattern.json").write_text(paper.to_json())
    out_dir = tmp_path / "seq"
    code, out, err = run_capture(["--backend", "replay", "--device", tmp_path / "session.npy", "--pattern",
                                  tmp_path / "pattern", "--out", out_dir, "--auto", "--frames", 700, "--hold", hold],
                                 capsys)
    assert code == 0, err
    assert out.split() == [str(out_dir / "pose000")] and "pose000: board complete (24/24)" in err
    names = [f["file"] for f in paper.frames()]
    assert sorted(f for f in os.listdir(out_dir / "pose000") if f.endswith(".png")) == sorted(names)
    pose = ds.load_pose(str(out_dir), "pose000", paper)
    assert pose.phase.shape == (2, 4, 400, 640) and pose.star.shape == (400, 640)
    for k, f in enumerate(paper.frames()):
        got = cv2.imread(str(out_dir / "pose000" / f["file"]), cv2.IMREAD_UNCHANGED).astype(float) / 65535
        assert np.sqrt(np.mean((got - np.clip(0.9 * E[k + 1], 0, 1)) ** 2)) < 0.01, f["file"]

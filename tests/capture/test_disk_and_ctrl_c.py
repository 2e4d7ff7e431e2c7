"""rotstar-capture's faults, run as a user meets them: a real process on a recording of the player that
rotstar-simulate --recording writes, a full disk (a small tmpfs), a real SIGINT while a pose is detected or
its folder written; and rotstar-simulate's --help"""

from __future__ import annotations

import io
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from rotstar_mrcal import dataset as ds
from rotstar_mrcal.cli.capture import main as rotstar_capture
from rotstar_mrcal.cli.simulate import parse_args as simulate_args
from rotstar_mrcal.pattern.layout import make_layout

from conftest import VENV_BIN, cli_env, ctrl_c_reaches_it

LAYOUT = make_layout(screen=(800, 600), pitch=100, band=24)  # 6 x 4 corners, 20 loop entries
HOLD = 18  # 20 entries x 18 refreshes at 60 Hz: a 6 s loop, 150 camera frames at 25 fps
FRAMES = 340  # per capture recording: > 2 loops, within the 355 still frames of a pose at --loops 1.2


@pytest.fixture(scope="module")
def recording(tmp_path_factory, run_cli):
    """(pattern folder, rec.npy): rotstar-simulate --recording of two poses, as a camera films the player"""
    d = tmp_path_factory.mktemp("rec")
    (d / "pattern").mkdir()
    (d / "pattern" / "pattern.json").write_text(LAYOUT.to_json())
    r = run_cli("rotstar-simulate", "--recording", d / "rec.npy", "--pattern", d / "pattern", "--camera",
                "pinhole-small", "--hold", HOLD, "--loops", 1.2, "--supersample", 2, "--poses", 2)
    assert r.returncode == 0, r.stderr
    assert r.stdout == f"{d / 'rec.npy'}\n"
    return d / "pattern", d / "rec.npy"


def test_simulated_recording_segments_into_a_pose_that_detect_reads(recording, tmp_path, run_cli):
    pattern, rec = recording
    meta = json.loads(rec.with_suffix(".json").read_text())
    meta = meta["simulated"]
    assert (meta["still_frames"], meta["moving_frames"]) == (355, 25)  # 1 s + 2.2 loops of 6 s, then 1 s moving
    first = tmp_path / "first.npy"  # the first pose's still frames: what a camera of that pose records
    np.save(first, np.load(rec, mmap_mode="r")[:355])
    r = run_cli("rotstar-segment", first, "--pattern", pattern, "--out", tmp_path / "seq" / "pose000")
    assert r.returncode == 0, r.stderr
    assert "24 of 24 corners" in r.stderr
    r = run_cli("rotstar-detect", tmp_path / "seq", "-o", tmp_path / "corners.vnl")
    assert r.returncode == 0, r.stderr
    rows = [ln for ln in (tmp_path / "corners.vnl").read_text().splitlines() if not ln.startswith("#")]
    assert len(rows) == 24 and all(ln.split()[-1] != "-" for ln in rows)


def test_auto_capture_of_a_simulated_recording_takes_both_poses(recording, tmp_path, capsys):
    """rotstar-capture --auto on the recording: the first pose at once, then the camera's move and the second pose
    (a move the simulator did not draw, the camera never moving, gave one pose and 'the recording ended')"""
    pattern, rec = recording
    code = rotstar_capture(["--backend", "replay", "--device", str(rec), "--pattern", str(pattern), "--hold", str(HOLD),
                            "--frames", "300", "--auto", "--out", str(tmp_path / "seq")])
    out, err = capsys.readouterr()
    assert code == 0 and out.split() == [str(tmp_path / "seq" / p) for p in ("pose000", "pose001")], err
    assert err.count("board complete (24/24)") == 2


def test_replay_says_it_waits_for_enter(recording, tmp_path, capsys, monkeypatch):
    """Without --auto a replay waits for Enter before each pose: the prompt says so, and how to go on without"""
    pattern, rec = recording
    monkeypatch.setattr(sys, "stdin", io.StringIO("q\n"))
    code = rotstar_capture(["--backend", "replay", "--device", str(rec), "--pattern", str(pattern), "--frames", "300",
                            "--out", str(tmp_path / "seq")])
    err = capsys.readouterr().err
    assert code == 1 and ("rotstar-capture: pose000: press Enter to record the next 300 frames of the replay (q: "
                          "quit; --auto goes on without waiting)") in err.splitlines(), err


def capture_cmd(pattern, rec, out) -> list[str]:
    return [os.path.join(VENV_BIN, "rotstar-capture"), "--backend", "replay", "--device", str(rec), "--pattern",
            str(pattern), "--hold", str(HOLD), "--frames", str(FRAMES), "--auto", "--poses", "1", "--out", str(out)]


@pytest.fixture
def small_disk(tmp_path):
    """small_disk(kib) -> a tmpfs of that size (mounting needs root: skipped otherwise)"""
    mounted = []

    def mount(kib: int):
        d = tmp_path / f"disk{len(mounted)}"
        d.mkdir()
        if subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={kib}k", "tmpfs", str(d)],
                          capture_output=True).returncode:
            pytest.skip("cannot mount a tmpfs here (not root)")
        mounted.append(d)
        return d

    yield mount
    for d in mounted:
        subprocess.run(["umount", str(d)], check=True)


def test_capture_onto_a_full_disk_says_so(recording, small_disk):
    """The recording (340 frames of 640x400 x 2 bytes, 174 MB) cannot fit: one line naming it, exit 1, nothing
    left (it was a SIGBUS, exit 135, and a sparse file of the recording's size)"""
    pattern, rec = recording
    disk = small_disk(2048)
    r = subprocess.run(capture_cmd(pattern, rec, disk / "seq"), capture_output=True, text=True,
                       env=cli_env(), stdin=subprocess.DEVNULL, timeout=60)
    assert r.returncode == 1, (r.returncode, r.stderr)
    assert "Traceback" not in r.stderr
    raw = disk / "seq" / "raw" / "pose000.npy"
    assert f"rotstar-capture: {raw}: no space left on device (174 MB needed)" in r.stderr.splitlines()
    assert not (disk / "seq" / "raw").exists() and not (disk / "seq" / "pose000").exists()


def test_capture_whose_pose_folder_fills_the_disk_says_so(recording, small_disk):
    """Room for the recording and 2 MB more: the pose's frames (~5 MB of PNGs) do not fit; one line naming the
    pose folder and the reason, exit 1, no pose folder or temporary one (it was a traceback from cv2.imwrite)"""
    pattern, rec = recording
    disk = small_disk((128 + FRAMES * 640 * 400 * 2) // 1024 + 2048)
    r = subprocess.run(capture_cmd(pattern, rec, disk / "seq"), capture_output=True, text=True,
                       env=cli_env(), stdin=subprocess.DEVNULL, timeout=60)
    assert r.returncode == 1 and "Traceback" not in r.stderr, (r.returncode, r.stderr)
    last = r.stderr.splitlines()[-1]
    assert last.startswith(f"rotstar-capture: {disk / 'seq' / 'pose000'}: cannot write ") and \
        last.endswith(".png (No space left on device)"), r.stderr
    assert not (disk / "seq" / "pose000").exists() and leftovers(disk / "seq") == []


def interrupt_when(pattern, rec, out, ready, ignore_sigint: bool = False, delay: float = 0.0):
    """Run rotstar-capture, send SIGINT delay s after ready(out) holds; CompletedProcess (returncode, stderr)"""
    p = subprocess.Popen(capture_cmd(pattern, rec, out), stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env=cli_env(),
                         preexec_fn=(lambda: signal.signal(signal.SIGINT, signal.SIG_IGN)) if ignore_sigint else None)
    t0 = time.monotonic()
    try:
        while p.poll() is None and not ready(out) and time.monotonic() - t0 < 60:
            time.sleep(0.001)
        time.sleep(delay)
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=30)
    finally:
        if p.poll() is None:
            p.kill()
    return subprocess.CompletedProcess(p.args, p.returncode, "", err)


def leftovers(out) -> list[str]:
    return sorted(f for f in os.listdir(out) if f.startswith(".")) if out.exists() else []


def test_sigint_during_detection_stops_the_capture(recording, tmp_path):
    """Started as a script's background job (SIGINT ignored, as the shell does): a SIGINT 0.6 s after the
    recording's file appears (it is recorded in ~0.2 s, then split and detected for ~1.7 s) stops the session
    at once (it was ignored: the pose was detected and written, exit 0)"""
    pattern, rec = recording
    out = tmp_path / "seq"
    r = interrupt_when(pattern, rec, out, lambda o: (o / "raw" / "pose000.npy").exists(), ignore_sigint=True,
                       delay=0.6)
    assert r.returncode == 130, (r.returncode, r.stderr)
    assert "rotstar-capture: interrupted" in r.stderr and "Traceback" not in r.stderr
    assert not (out / "pose000").exists() and not (out / "raw").exists() and leftovers(out) == []


def test_sigint_while_the_pose_folder_is_written_leaves_no_part_of_it(recording, tmp_path):
    """SIGINT the moment the pose's folder (or its temporary one) appears: no pose folder with some of its
    frames (it was left with 2-11 of them), no hidden temporary folder"""
    pattern, rec = recording
    out = tmp_path / "seq"
    writing = lambda o: o.exists() and any(f.startswith(("pose000", ".pose000")) for f in os.listdir(o))  # noqa: E731
    r = interrupt_when(pattern, rec, out, writing)
    assert r.returncode in (0, 130) and "Traceback" not in r.stderr, (r.returncode, r.stderr)
    if (out / "pose000").exists():  # the signal came after the rename: the folder is whole
        want = {f["file"] for f in ds.read_pattern(str(pattern))[0]["frames"]} | {"segment.json"}
        assert set(os.listdir(out / "pose000")) == want
    else:
        assert r.returncode == 130
    assert leftovers(out) == []


def test_sigint_while_a_rig_pose_is_written_leaves_no_camera_of_it(recording, tmp_path):
    """rotstar-segment of two cameras' recordings, SIGINT as soon as the first camera's folder appears: the new
    pose folder is removed whole (it kept camera-0 without camera-1) or, the signal too late, holds both"""
    pattern, rec = recording
    cam = tmp_path / "cam.npy"
    np.save(cam, np.load(rec, mmap_mode="r")[:355])
    out = tmp_path / "seq" / "pose000"
    p = subprocess.Popen([os.path.join(VENV_BIN, "rotstar-segment"), str(cam), str(cam), "--pattern", str(pattern),
                          "--out", str(out)], stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env=cli_env())
    try:
        t0 = time.monotonic()
        while p.poll() is None and not (out.exists() and os.listdir(out)) and time.monotonic() - t0 < 60:
            time.sleep(0.001)
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=30)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode in (0, 130) and "Traceback" not in err, (p.returncode, err)
    if p.returncode == 130:
        assert not out.exists(), os.listdir(out)
    else:
        assert sorted(os.listdir(out)) == ["camera-0", "camera-1"]
    assert leftovers(out.parent) == []


def test_sigint_while_rotstar_simulate_writes_a_pose_leaves_no_part_of_it(recording, tmp_path):
    """rotstar-simulate, SIGINT the moment a pose folder (or its temporary one) appears: every pose folder left is
    whole (all 19 frames of the pattern; one was left with some of them), no temporary folder"""
    out = tmp_path / "sim"
    p = subprocess.Popen([os.path.join(VENV_BIN, "rotstar-simulate"), "--out", str(out), "--camera", "pinhole-small",
                          "--pattern", str(recording[0]), "--poses", "3", "--supersample", "1"],
                         stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env=cli_env(), preexec_fn=ctrl_c_reaches_it)
    try:
        t0 = time.monotonic()
        while p.poll() is None and not (out.exists() and any("pose" in f for f in os.listdir(out))) \
                and time.monotonic() - t0 < 60:
            time.sleep(0.001)
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=30)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 130 and "Traceback" not in err, (p.returncode, err)
    want = {f["file"] for f in ds.read_pattern(str(out))[0]["frames"]}
    assert len(want) == 19
    for pose in (f for f in os.listdir(out) if f.startswith("pose")):
        assert set(os.listdir(out / pose)) == want, pose
    assert leftovers(out) == []


def test_a_stdout_that_cannot_be_written_is_one_line(recording, tmp_path):
    """stdout on a full disk (/dev/full): 'stdout: No space left on device', exit 1 (it was a traceback)"""
    pattern, rec = recording
    cam = tmp_path / "cam.npy"
    np.save(cam, np.load(rec, mmap_mode="r")[:355])
    with open("/dev/full", "w") as full:
        r = subprocess.run([os.path.join(VENV_BIN, "rotstar-segment"), str(cam), "--pattern", str(pattern), "--out",
                            str(tmp_path / "seq" / "pose000"), "--no-check"], stdout=full, stderr=subprocess.PIPE,
                           text=True, env=cli_env(), timeout=60)
    assert r.returncode == 1 and r.stderr.splitlines()[-1] == "rotstar-segment: stdout: No space left on device", \
        r.stderr
    assert "Traceback" not in r.stderr and "Exception ignored" not in r.stderr


def test_simulate_help_shows_meaningful_defaults_and_exit_codes(capsys):
    with pytest.raises(SystemExit):
        simulate_args(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "(default: None)" not in text and "(default: True)" not in text and "(default: False)" not in text
    assert "--no-identity leave out the identity frames" in text and "--out SEQ dataset folder to write (needed" in text
    assert "--supersample SUPERSAMPLE s: s x s sub-pixels per camera pixel (default: 4)" in text
    assert "exit status: 0 done;" in text and "130 interrupted" in text
    assert "rotstar-simulate --recording rec.npy" in text

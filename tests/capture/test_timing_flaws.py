"""The display's and the camera's timing flaws, simulated, and segmentation by content through them

Each recording: the capture's simulated camera (capture.simulated.record_player,
the code path rotstar-simulate --recording writes) filming the looping player
(20 entries, held as pattern.loop.SHORT_HOLDS says: the rotating star 11 refreshes at 60 Hz, 183 ms, the
identity frames and the checkerboard 6, 100 ms, the start marker 3; 2.6 s a loop) at 25 fps, 8 ms exposures,
for --until-enough's first look (one loop and two camera frames) from a random point of the loop, with every
flaw on
(simulated.ALL_FLAWS: the panel scanning out over a refresh, a 5 ms LCD
response, a 480 Hz PWM backlight, the browser a refresh late or early, the
driver losing frames, the camera's clock drifting). Tiny images (a quarter of
the pinhole-small camera) keep it fast.

Truth per camera frame (camera_stream's truth): the entry it mostly shows and
its impurity (the largest difference at any pixel from that entry alone, in
units of the screen's white). A displayed frame was *seen* when two
consecutive camera frames (consecutive sequence numbers) both caught it with
an impurity <= 0.02. Accepted into a pose: no camera frame of another entry,
none with an impurity > BLEND; a pose whose every frame was seen is kept; a
pose that is refused names frames that were not seen.
"""

from __future__ import annotations

import dataclasses
import io
import json
import re
import sys

import cv2
import numpy as np
import pytest

from rotstar_mrcal import simulate
from rotstar_mrcal.capture.segment import Options, SegmentError, segment
from rotstar_mrcal.capture.simulated import (
    ALL_FLAWS, Flaws, blend_weights, camera_stream, loop_irradiance, player_schedule, pwm_gain, record_player,
    write_player_recording,
)
from rotstar_mrcal.capture.backend_replay import ReplaySource
from rotstar_mrcal.pattern.layout import make_layout, unspared
from rotstar_mrcal.pattern.loop import entry_holds, player_loop

LAYOUT = make_layout(screen=(800, 600), pitch=100, band=24)
LOOP = player_loop(LAYOUT.frames())
N = len(LOOP)
HOLDS = entry_holds(LOOP)  # the player's holds for a short capture: the rotating star 11 refreshes, the rest 6 (marker 3)
FPS, EXPOSURE = 25.0, 0.008
BLEND, CLEAN = 0.1, 0.02


def scenes(k):
    model = simulate.preset_model("pinhole-small")
    rts = simulate.random_poses(model, LAYOUT, k, np.random.default_rng(3))
    return [np.stack([cv2.resize(e, (e.shape[1] // 4, e.shape[0] // 4), interpolation=cv2.INTER_AREA)
                      for e in loop_irradiance(LAYOUT, model, rt, supersample=2)]) for rt in rts]


def seen(truth, seq) -> set[int]:
    """The entries two consecutive camera frames caught clean"""
    return {truth[i][0] for i in range(1, len(truth)) if seq[i] == seq[i - 1] + 1 and truth[i][0] == truth[i - 1][0]
            and truth[i][1] <= CLEAN and truth[i - 1][1] <= CLEAN}


def one(E, s: int, opts: Options = Options(method="content")):
    """One flawed recording and its split: (kept, missing files by truth, accepted frames of another entry,
    accepted blends, largest accepted impurity)"""
    rng = np.random.default_rng([7, s])
    T = int(np.ceil(HOLDS.sum() / 60 * FPS)) + 2  # one loop and two camera frames (cli.capture.first_look)
    truth: list = []
    frames, seq = record_player(E, HOLDS, T, ALL_FLAWS, fps=FPS, exposure_s=EXPOSURE, start_entry=int(rng.integers(N)),
                                start_phase=float(rng.uniform()), rng=rng, truth=truth, noise=0.01)
    missing = {LOOP[e]["file"] for e in range(1, N)} - {LOOP[e]["file"] for e in seen(truth, seq)}
    try:
        seg = segment(frames, LAYOUT.frames(), LAYOUT, 65535.0, opts, times=seq / FPS)
    except SegmentError as e:
        named = set(re.findall(r"\w+_\d+\.png|checkerboard\.png", str(e)))
        assert named and named <= missing, (s, str(e), missing)
        return False, missing, 0, 0, 0.0
    assert not unspared(LAYOUT.frames(), seg.missing) and set(seg.missing) <= missing, (s, seg.missing, missing)
    wrong = blends = 0
    worst = 0.0
    for k in range(1, N):
        for i in seg.used.get(LOOP[k]["file"], []):
            e, imp = truth[i]
            wrong += e != k
            blends += e == k and imp > BLEND
            worst = max(worst, imp)
    return True, missing, wrong, blends, worst


def many(Es, n):
    """(kept, refused, kept without a frame the pose can spare) of n recordings"""
    kept = refused = spared = 0
    for s in range(n):
        ok, missing, wrong, blends, worst = one(Es[s % len(Es)], s)
        assert wrong == 0 and blends == 0, (s, wrong, blends, worst)
        assert ok or unspared(LAYOUT.frames(), sorted(missing)), s  # every frame it needs seen: kept
        kept += ok
        refused += not ok
        spared += ok and bool(missing)
    return kept, refused, spared


def test_flawed_recordings_few():
    kept, refused, spared = many(scenes(1), 12)
    assert kept >= 8


def test_blended_rows_left_out():
    """A camera frame that caught a little of the entry before or after in some rows (the panel scanning out, the
    LCD still switching) passes the comparison of consecutive frames; it is left out of the average"""
    E = scenes(1)[0]
    on = [one(E, s)[4] for s in range(6)]
    off = [one(E, s, Options(method="content", content_blend_z=0))[4] for s in range(6)]  # recording 5: 0.047
    assert max(on) <= CLEAN < max(off), (on, off)


@pytest.mark.slow
def test_flawed_recordings_200():
    """The issue's count: 200 recordings, 0 blended or misidentified camera frames accepted"""
    kept, refused, spared = many(scenes(4), 200)
    assert kept >= 180 and spared >= 1 and refused >= 1  # (poses lacking a frame they can spare, or one they
    #                                                          cannot, occur: kept, or refused naming it)


def test_the_flaws_each():
    E = np.stack([np.full((8, 6), v) for v in (0.0, 0.3, 0.6, 0.9)])
    # a browser that is late now and then: entries one refresh longer, the loop drifts later
    plain = player_schedule(4, 6, duration=5)
    late = player_schedule(4, 6, duration=5, late=0.5, rng=1)
    assert {round((s.t1 - s.t0) * 60) for s in late} == {6, 7} and late[10].t0 > plain[10].t0
    early = player_schedule(4, 6, duration=5, early=0.5, rng=1)
    assert {round((s.t1 - s.t0) * 60) for s in early} == {5, 6}
    # per-entry holds (the player's hold per frame kind)
    sched = player_schedule(4, [2, 6, 6, 3], duration=4)
    assert [round((s.t1 - s.t0) * 60) for s in sched[:4]] == [2, 6, 6, 3]
    # the LCD's response: an exposure that starts 2 ms after a switch still sees 2 % of the entry before
    w = blend_weights(plain, 0.102, 0.112, 8, 0.0, response_s=0.005)
    assert set(w) == {0, 1} and np.allclose(w[0], 0.5 * 0.003 ** 2 / 0.005 / 0.01)
    # PWM: a short exposure sees the backlight's phase, a whole number of periods does not
    assert pwm_gain(0.0, 0.004, 500, 0.5) == 1.0 and pwm_gain(0.0, 0.003, 500, 0.5) == pytest.approx(4 / 3)
    # clock drift: the camera's frame i starts at i / (fps (1 + drift)); dropped frames leave sequence gaps
    truth: list = []
    fr, seq = camera_stream(E, sched, 50, fps=25, exposure_s=0.004, scan_s=0, noise=0, clock_drift=0.01,
                            drop_rate=0.2, rng=2, truth=truth)
    assert len(fr) == len(seq) == len(truth) < 50 and np.all(np.diff(seq) >= 1) and np.any(np.diff(seq) > 1)
    fr0, _ = camera_stream(E, sched, 50, fps=25, exposure_s=0.004, scan_s=0, noise=0, rng=2)
    assert not np.array_equal(fr[:5], fr0[:5]) or len(fr) != 50
    # the whole chain with no flaws gives clean, in-order frames
    truth = []
    record_player(E, 6, 40, Flaws(scan_s=0.0), truth=truth, noise=0)
    assert all(imp == 0 or imp > 0 for _, imp in truth) and len(truth) == 40


@pytest.mark.slow
def test_replayed_flawed_recording(tmp_path):
    """rotstar-simulate --recording's writer with the flaws, read back by the replay backend as a device's
    recording (sequence gaps where the driver lost frames), split by content from where the pose starts"""
    model = simulate.preset_model("pinhole-small")
    rt = simulate.random_poses(model, LAYOUT, 1, np.random.default_rng(5))
    fn = str(tmp_path / "rec.npy")
    flaws = dataclasses.replace(ALL_FLAWS, drop_rate=0.03)
    n = write_player_recording(fn, LAYOUT, model, rt, hold=7, loops=1.0, still_s=0.1, exposure_s=EXPOSURE,
                               supersample=1, seed=3, flaws=flaws)
    src = ReplaySource(fn)
    seq = src.sequence_numbers()
    assert len(src) == n and seq[-1] + 1 > n  # frames lost: gaps in the sequence numbers
    with open(str(tmp_path / "rec.json")) as f:
        assert json.load(f)["simulated"]["flaws"]["drop_rate"] == 0.03
    seg = segment(src.frames(), LAYOUT.frames(), LAYOUT, src.full_scale, Options(hold=7), times=seq / src.fps)
    assert len(seg.images) == N - 1 and seg.method in ("content", "loop")


def flawed_recording(tmp_path, run_cli, loops: int, poses: int, seed: int):
    """tmp_path/rec.npy: rotstar-simulate's recording of the looping player (short holds, every timing flaw) showing
    LAYOUT (written to tmp_path/pattern/)"""
    (tmp_path / "pattern").mkdir()
    (tmp_path / "pattern" / "pattern.json").write_text(LAYOUT.to_json())
    rec = tmp_path / "rec.npy"
    r = run_cli("rotstar-simulate", "--recording", rec, "--pattern", tmp_path / "pattern", "--camera", "pinhole-small",
                "--hold", "short", "--timing-flaws", "--loops", loops, "--supersample", 2, "--poses", poses,
                "--seed", seed)
    assert r.returncode == 0, r.stderr
    return rec


@pytest.mark.slow
def test_short_holds_with_flaws_through_the_commands(tmp_path, run_cli):
    """rotstar-simulate --recording --hold short --timing-flaws, two loops of the first pose (what a camera records
    from anywhere in the loop; one loop is not always enough, test_flawed_recordings_200), rotstar-segment --hold short, rotstar-detect: every corner"""
    rec = flawed_recording(tmp_path, run_cli, loops=1, poses=1, seed=4)
    meta = json.loads(rec.with_suffix(".json").read_text())
    first = tmp_path / "first.npy"
    n = int((2 * HOLDS.sum() + 2 * HOLDS.max()) / 60 * FPS)  # two loops and two entries (5.6 s)
    np.save(first, np.load(rec, mmap_mode="r")[15:15 + n])  # from wherever the loop is 0.6 s in
    (tmp_path / "first.json").write_text(json.dumps({"sequence": meta["sequence"][15:15 + n], "fps": meta["fps"]}))
    r = run_cli("rotstar-segment", first, "--pattern", tmp_path / "pattern", "--out", tmp_path / "seq" / "pose000",
                "--hold", "short")
    assert r.returncode == 0, r.stderr
    assert "found by their content" in r.stderr and "24 of 24 corners" in r.stderr, r.stderr
    r = run_cli("rotstar-detect", tmp_path / "seq", "-o", tmp_path / "corners.vnl")
    assert r.returncode == 0, r.stderr


@pytest.mark.slow
def test_capture_records_until_enough(tmp_path, run_cli, capsys, monkeypatch):
    """rotstar-capture --until-enough on a replayed flawed short-hold recording: it stops as soon as every frame has
    two clean camera frames, well before the --loops limit, says the seconds, and the pose has the whole board"""
    from rotstar_mrcal.cli.capture import main as rotstar_capture

    rec = flawed_recording(tmp_path, run_cli, loops=2, poses=1, seed=5)
    monkeypatch.setattr(sys, "stdin", io.StringIO("\n"))
    code = rotstar_capture(["--backend", "replay", "--device", str(rec), "--pattern", str(tmp_path / "pattern"),
                            "--hold", "short", "--loops", "2", "--until-enough", "--poses", "1",
                            "--out", str(tmp_path / "seq")])
    out, err = capsys.readouterr()
    assert code == 0 and "board complete (24/24)" in err, err
    secs = [float(m) for m in re.findall(r"pose000: ([\d.]+) s at the screen", err)]
    limit = 2 * HOLDS.sum() / 60
    assert len(secs) == 1 and secs[0] < 0.8 * limit, (secs, limit, err)
    info = json.loads((tmp_path / "seq" / "pose000" / "segment.json").read_text())
    assert info["method"] == "content" and min(len(u) for u in info["frames_used"].values()) >= 2


@pytest.mark.slow
def test_auto_with_short_holds(tmp_path, run_cli, capsys):
    """--auto with the short holds: the next pose once the view has moved and is still again, by content (the
    plain difference test wants most consecutive frames equal, which short holds never give)"""
    from rotstar_mrcal.cli.capture import main as rotstar_capture

    rec = flawed_recording(tmp_path, run_cli, loops=1, poses=2, seed=6)
    code = rotstar_capture(["--backend", "replay", "--device", str(rec), "--pattern", str(tmp_path / "pattern"),
                            "--hold", "short", "--loops", "2", "--until-enough", "--auto", "--poses", "2",
                            "--out", str(tmp_path / "seq")])
    out, err = capsys.readouterr()
    assert code == 0 and err.count("board complete (24/24)") == 2, err
    assert len(re.findall(r"pose00[01]: [\d.]+ s at the screen", err)) == 2, err


def test_default_capture_without_an_identity_frame(tmp_path, run_cli, capsys, monkeypatch):
    """rotstar-capture with its defaults (the short holds, --until-enough) on a replay whose camera lost every frame
    that saw identity_03 and the checkerboard: the pose is written without them after the first look (2.7 s here),
    says so, and rotstar-detect reads the whole board from the other identity frames"""
    from rotstar_mrcal.cli.capture import main as rotstar_capture

    model = simulate.preset_model("pinhole-small")
    rt = simulate.random_poses(model, LAYOUT, 1, np.random.default_rng(3))[0]
    E = loop_irradiance(LAYOUT, model, rt, supersample=1)
    sched = player_schedule(N, HOLDS, duration=9.0, start_entry=5, start_phase=0.4)
    gone = {k for k, e in enumerate(LOOP) if e["file"] in ("identity_03.png", "checkerboard.png")}
    truth: list = []
    camera_stream(E, sched, 200, fps=FPS, exposure_s=EXPOSURE, rng=1, truth=truth)
    lost = [i for i, (e, _) in enumerate(truth) if e in gone]
    frames, seq = camera_stream(E, sched, 200, fps=FPS, exposure_s=EXPOSURE, rng=1, drop_frames=lost)
    np.save(tmp_path / "rec.npy", frames)
    (tmp_path / "rec.json").write_text(json.dumps({"sequence": seq.tolist(), "fps": FPS}))
    (tmp_path / "pattern").mkdir()
    (tmp_path / "pattern" / "pattern.json").write_text(LAYOUT.to_json())
    monkeypatch.setattr(sys, "stdin", io.StringIO("\n"))
    code = rotstar_capture(["--backend", "replay", "--device", str(tmp_path / "rec.npy"), "--pattern",
                            str(tmp_path / "pattern"), "--poses", "1", "--out", str(tmp_path / "seq")])
    err = capsys.readouterr().err
    assert code == 0 and "board complete (24/24)" in err, err
    assert "pose000: written without identity_03.png, checkerboard.png (not seen clean" in err, err
    assert "pose000: 2.7 s at the screen" in err and "source ended" not in err, err  # one loop (157 refreshes at
    #                                                                               60 Hz) and two camera frames
    pose = tmp_path / "seq" / "pose000"
    assert not (pose / "identity_03.png").exists() and (pose / "identity_02.png").exists()
    assert json.loads((pose / "segment.json").read_text())["missing"] == ["identity_03.png", "checkerboard.png"]
    r = run_cli("rotstar-detect", tmp_path / "seq", "-o", tmp_path / "corners.vnl")
    assert r.returncode == 0 and "pose000: identity_03.png missing" in r.stderr, r.stderr
    rows = [ln.split() for ln in (tmp_path / "corners.vnl").read_text().splitlines() if "/pose000/" in ln]
    assert len(rows) == 24 and all(r[1] != "-" for r in rows), rows

"""Segmentation of simulated recordings of the looping player, end to end against the direct rendering

The recordings come from rotstar_mrcal.capture.simulated: the screen showing
the start marker and every pattern frame, rendered once from one camera pose
by the foundation's simulator, then streamed like a 25 fps camera filming
the player (hold 20 refreshes at 60 Hz, ~8 camera frames per display frame):
transition frames that blend two display frames row by row (the panel scans
out over one refresh), noise in every camera frame, a start in the middle of
the loop, more than two loops, a dropped and a doubled display frame and a
camera frame lost by the driver.
"""

from __future__ import annotations

import io
import json

import cv2
import numpy as np
import pytest

from rotstar_mrcal import simulate
from rotstar_mrcal.capture.backend_replay import save_recording
from rotstar_mrcal.capture.segment import (Options, SegmentError, check_order, core_range, find_markers, segment,
                                           stable_runs, threshold)
from rotstar_mrcal.capture.simulated import camera_stream, loop_irradiance, player_schedule
from rotstar_mrcal.cli.detect import main as rotstar_detect
from rotstar_mrcal.cli.segment import main as rotstar_segment
from rotstar_mrcal.display.loop import expected_levels, player_loop
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.vnl import read_corners

LAYOUT = make_layout(screen=(800, 600), pitch=100, band=24)
N_ENTRIES = len(player_loop(LAYOUT.frames()))
FILES = [f["file"] for f in LAYOUT.frames()]
GAIN, NOISE = 0.9, 0.01


@pytest.fixture(scope="module")
def scene():
    """The pinhole-small camera at one pose; the irradiance of every loop entry; the true corners"""
    model = simulate.preset_model("pinhole-small")
    rt = simulate.random_poses(model, LAYOUT, 1, np.random.default_rng(3))[0]
    E = loop_irradiance(LAYOUT, model, rt)
    return model, rt, E, simulate.true_corners(model, LAYOUT, rt)


@pytest.fixture(scope="module")
def small(scene):
    """The same irradiance at half size (fast, for the segmentation unit tests)"""
    E = scene[2]
    return np.stack([cv2.resize(e, (e.shape[1] // 2, e.shape[0] // 2), interpolation=cv2.INTER_AREA) for e in E])


def hard_recording(E, seed=2, bits=16, **kw):
    """Starts in the middle of entry 4; display frame 13 dropped (loop 2), 25 doubled (loop 3); camera frame 40 lost"""
    sched = player_schedule(N_ENTRIES, hold=20, refresh_hz=60, duration=12, start_entry=4, start_phase=0.4,
                            drop=[13], double=[25])
    return camera_stream(E, sched, 290, fps=25, exposure_s=0.012, scan_s=1 / 60, gain=GAIN, noise=NOISE,
                         bits=bits, drop_frames=[40], rng=seed, **kw)


def run(main, *args, capsys):
    """A CLI's main() in this process: (exit status, stdout, stderr)"""
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


# ---- the acceptance test ---------------------------------------------------------
def test_segment_then_detect_equals_direct_rendering(scene, tmp_path, capsys):
    """rotstar-segment then rotstar-detect on a recording == rotstar-detect on the directly rendered dataset"""
    model, rt, E, truth = scene
    # the directly rendered dataset, as rotstar-simulate writes it (same renderer, one noisy exposure)
    direct = tmp_path / "direct"
    simulate.write_dataset(str(direct), LAYOUT, model, [rt], simulate.Settings(gain=GAIN, noise=NOISE, seed=1))
    # the recording of the player
    frames, seq = hard_recording(E)
    rec = tmp_path / "rec.npy"
    save_recording(str(rec), frames, seq, fps=25)
    (tmp_path / "pattern").mkdir()
    (tmp_path / "pattern" / "pattern.json").write_text(LAYOUT.to_json())
    code, out, err = run(rotstar_segment, rec, "--pattern", tmp_path / "pattern", "--out", tmp_path / "seq" / "pose000",
                         "--plot", tmp_path / "signal.png", "--no-check", capsys=capsys)
    assert code == 0, err
    assert out.strip() == str(tmp_path / "seq" / "pose000")
    assert "1 camera frame(s) were dropped" in err
    assert "a display frame was dropped?" in err  # the loop with the missing frame was not used
    assert (tmp_path / "seq" / "pattern.json").exists() and (tmp_path / "signal.png").stat().st_size > 10000
    info = json.loads((tmp_path / "seq" / "pose000" / "segment.json").read_text())
    assert sum(lp["ok"] for lp in info["loops"]) == 1 and info["value_scale"] == 1.0

    # every averaged frame is its display frame: no transition blended in, no frame swapped
    for k, f in enumerate(FILES):
        got = cv2.imread(str(tmp_path / "seq" / "pose000" / f), cv2.IMREAD_UNCHANGED).astype(float) / 65535
        want = np.clip(GAIN * E[k + 1], 0, 1)
        a, b = info["frames_averaged"][f]
        assert b - a >= 5
        assert np.sqrt(np.mean((got - want) ** 2)) < 1.5 * NOISE / np.sqrt(b - a), f

    # both datasets through rotstar-detect
    corners = {}
    for name, seqdir in (("direct", direct), ("segmented", tmp_path / "seq")):
        code, out, err = run(rotstar_detect, seqdir, capsys=capsys)
        assert code == 0, err
        corners[name] = read_corners(io.StringIO(out), LAYOUT.nx, LAYOUT.ny)[f"{seqdir}/pose000/rotstar_00.png"]
    err_direct = np.linalg.norm(corners["direct"] - truth, axis=-1)
    err_seg = np.linalg.norm(corners["segmented"] - truth, axis=-1)
    diff = np.linalg.norm(corners["segmented"] - corners["direct"], axis=-1)
    print(f"rms error vs truth: direct {np.sqrt(np.mean(err_direct**2)):.4f} px, segmented "
          f"{np.sqrt(np.mean(err_seg**2)):.4f} px; segmented vs direct: max {diff.max():.4f} px")
    assert np.all(np.isfinite(diff))
    assert np.sqrt(np.mean(err_direct**2)) < 0.02 and np.sqrt(np.mean(err_seg**2)) < 0.02
    assert diff.max() < 0.05  # the same corners, within noise
    # averaging several frames can only help
    assert np.sqrt(np.mean(err_seg**2)) <= np.sqrt(np.mean(err_direct**2)) + 0.002


# ---- the cases one by one ----------------------------------------------------------------
def test_loops_dropped_doubled_and_the_start(small):
    frames, _ = hard_recording(small, bits=8)
    seg = segment(frames, LAYOUT.frames(), LAYOUT, 255.0)
    reasons = [v.reason for v in seg.loops]
    assert reasons[0].startswith("8 frame(s) between start markers, pattern.json has 9")  # the dropped frame
    assert seg.loop.ok and seg.chosen == 1
    assert any(r.startswith("incomplete") for r in reasons)  # the recording ends mid-loop
    # the doubled frame is one long stretch of the last loop, and does not disturb it
    lengths = [seg.stretches[i].length for i in seg.loops[2].stretches] if seg.loops[2].stretches else []
    assert not lengths or max(lengths) > 1.6 * np.median(lengths)
    # the recording started mid-loop: the first stretches precede the first marker
    assert not seg.markers[0] and seg.stretches[0].truncated
    # order: every frame averaged lies inside its stretch, in the order of pattern.json
    starts = [seg.ranges[f][0] for f in FILES]
    assert starts == sorted(starts)


def test_one_loop_is_enough_and_8bit(small):
    sched = player_schedule(N_ENTRIES, hold=20, duration=4.0)
    frames, _ = camera_stream(small, sched, 90, fps=25, exposure_s=0.01, noise=0.004, bits=8, rng=1)
    seg = segment(frames, LAYOUT.frames(), LAYOUT, 255.0)
    assert seg.loop.ok and len(seg.images) == len(FILES)
    assert seg.images[FILES[0]].dtype == np.float64


def test_every_loop_missing_a_frame_is_rejected(small):
    sched = player_schedule(N_ENTRIES, hold=20, duration=12, drop=[3, 13, 23])
    frames, _ = camera_stream(small, sched, 290, fps=25, noise=NOISE, rng=3)
    with pytest.raises(SegmentError, match=r"no usable loop.*frame\(s\) between start markers, pattern.json has 9"):
        segment(frames, LAYOUT.frames(), LAYOUT, 65535.0)


def test_wrong_pattern_json_is_rejected(small):
    frames, _ = camera_stream(small, player_schedule(N_ENTRIES, hold=20, duration=12), 290, fps=25, rng=4)
    six = make_layout(screen=(800, 600), pitch=100, band=24, nframes=6)
    with pytest.raises(SegmentError, match="more than 7 stable stretches before the next start marker"):
        segment(frames, six.frames(), six, 65535.0)


def test_moving_camera_is_rejected(small):
    sched = player_schedule(N_ENTRIES, hold=20, duration=12)
    # a slow drift: stretches still form, but the image moves ~1 px over a loop
    frames, _ = camera_stream(small, sched, 290, fps=25, noise=NOISE, drift_px=(0.01, 0.005), rng=5)
    with pytest.raises(SegmentError, match=r"the camera moved: the image drifts 0\.[5-9]\d px over the loop"):
        segment(frames, LAYOUT.frames(), LAYOUT, 65535.0, Options(max_motion=0.3))
    # still, the same recording passes
    frames, _ = camera_stream(small, sched, 290, fps=25, noise=NOISE, rng=5)
    seg = segment(frames, LAYOUT.frames(), LAYOUT, 65535.0, Options(max_motion=0.3))
    assert seg.loop.motion_px < 0.05
    # shaking: no stable stretches at all
    rng = np.random.default_rng(6)
    shaken = np.stack([np.roll(f, tuple(rng.integers(-3, 4, 2)), axis=(0, 1)) for f in frames])
    with pytest.raises(SegmentError, match="the view is not still"):
        segment(shaken, LAYOUT.frames(), LAYOUT, 65535.0)


def test_no_player_no_marker(small):
    frames = np.repeat((small[3:5] * 60000).astype(np.uint16), 20, axis=0)  # two frames, no marker, no loop
    frames[20:] = (small[3] * 60000).astype(np.uint16)
    with pytest.raises(SegmentError):
        segment(frames, LAYOUT.frames(), LAYOUT, 65535.0)


# ---- the pieces ---------------------------------------------------------------------------
def test_pieces():
    d = np.r_[np.nan, np.full(30, 0.01), 0.3, 0.2, np.full(30, 0.011)]
    tau = threshold(d)
    assert 0.011 < tau < 0.2
    assert stable_runs(d, tau, 4) == [(0, 31), (32, 63)]  # frame 31: a transition
    assert core_range(0, 31, 1, 8) == (11, 19)
    levels = np.array([0.6, 0.35, 0.02, 0.6, 0.35, 0.6, 0.02, 0.35])
    assert find_markers(levels, 4).tolist() == [False, False, True, False, False, False, True, False]
    with pytest.raises(SegmentError, match="no start marker"):
        find_markers(np.array([0.5, 0.52, 0.51, 0.53, 0.5]), 4)
    want = expected_levels(LAYOUT, player_loop(LAYOUT.frames()))
    assert check_order(2 * want + 0.1, want, 0.9) == (pytest.approx(1.0), "")
    r, why = check_order(np.roll(want, 1), want, 0.9)  # off by one
    assert why and r < 0.9


@pytest.mark.slow
def test_d435_full_size_10bit_end_to_end(tmp_path, capsys):
    """The real case: the default iPad layout, the D435 preset at 1280x800, Y16 words holding 10-bit values"""
    layout = make_layout()
    model = simulate.preset_model("d435")
    rt = simulate.random_poses(model, layout, 1, np.random.default_rng(11))[0]
    E = loop_irradiance(layout, model, rt)
    truth = simulate.true_corners(model, layout, rt)
    sched = player_schedule(len(player_loop(layout.frames())), hold=30, refresh_hz=60, duration=12.5,
                            start_entry=7, start_phase=0.5)
    frames, seq = camera_stream(E, sched, 300, fps=25, exposure_s=0.008, gain=GAIN, noise=NOISE, value_bits=10, rng=3)
    save_recording(str(tmp_path / "rec.npy"), frames // 64, seq, fps=25)  # low-aligned 10-bit data
    (tmp_path / "pattern").mkdir()
    (tmp_path / "pattern" / "pattern.json").write_text(layout.to_json())
    code, out, err = run(rotstar_segment, tmp_path / "rec.npy", "--pattern", tmp_path / "pattern",
                         "--out", tmp_path / "seq" / "pose000", capsys=capsys)
    assert code == 0, err
    assert "scaled by 64" in err and "board found: 126 of 126 corners (complete)" in err
    code, out, err = run(rotstar_detect, tmp_path / "seq", capsys=capsys)
    assert code == 0, err
    got = read_corners(io.StringIO(out), layout.nx, layout.ny)[f"{tmp_path / 'seq'}/pose000/rotstar_00.png"]
    e = np.linalg.norm(got - truth, axis=-1)
    print(f"D435 10-bit: rms {np.sqrt(np.mean(e**2)):.4f} px, max {e.max():.4f} px")
    assert np.sqrt(np.mean(e**2)) < 0.02

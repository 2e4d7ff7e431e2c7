"""Segmentation of simulated recordings of the looping player, end to end against the direct rendering

The recordings come from rotstar_mrcal.capture.simulated: the screen showing
the start marker and every pattern frame, rendered once from one camera pose
by the foundation's simulator, then streamed like a 25 fps camera filming
the player (hold 20 refreshes at 60 Hz, ~8 camera frames per display frame):
transition frames that blend two display frames row by row (the panel scans
out over one refresh), noise in every camera frame, a start in the middle of
the loop, more than two loops, a dropped and a doubled display frame and a
camera frame lost by the driver.

LAYOUT is the default sequence (8 rotating-star frames, 10 identity frames
for its 6 x 4 grid, the checkerboard: 20 loop entries); PLAIN is the same
screen without identity frames (10 entries), the sequence of datasets made
before them, which must segment as it always did.
"""

from __future__ import annotations

import io
import json

import cv2
import numpy as np
import pytest

from rotstar_mrcal import simulate
from rotstar_mrcal.capture.backend_replay import save_recording
from rotstar_mrcal.capture.segment import (
    Options, SegmentError, check_order, core_range, find_markers, segment, stable_runs, threshold,
)
from rotstar_mrcal.capture.simulated import camera_stream, loop_irradiance, player_schedule
from rotstar_mrcal.cli.detect import main as rotstar_detect
from rotstar_mrcal.cli.segment import main as rotstar_segment
from rotstar_mrcal.pattern.loop import expected_levels, player_loop
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.vnl import read_corners

LAYOUT = make_layout(screen=(800, 600), pitch=100, band=24)
N_ENTRIES = len(player_loop(LAYOUT.frames()))
FILES = [f["file"] for f in LAYOUT.frames()]
PLAIN = make_layout(screen=(800, 600), pitch=100, band=24, identity=False)
N_PLAIN = len(player_loop(PLAIN.frames()))
GAIN, NOISE = 0.9, 0.01


@pytest.fixture(scope="module")
def scene():
    """The pinhole-small camera at one pose; the irradiance of every loop entry; the true corners"""
    model = simulate.preset_model("pinhole-small")
    rt = simulate.random_poses(model, LAYOUT, 1, np.random.default_rng(3))[0]
    E = loop_irradiance(LAYOUT, model, rt)
    return model, rt, E, simulate.true_corners(model, LAYOUT, rt)


def half(E):
    return np.stack([cv2.resize(e, (e.shape[1] // 2, e.shape[0] // 2), interpolation=cv2.INTER_AREA) for e in E])


@pytest.fixture(scope="module")
def small(scene):
    """The same irradiance at half size (fast, for the segmentation unit tests), with identity frames"""
    return half(scene[2])


@pytest.fixture(scope="module")
def small_plain(small):
    """The loop without identity frames: the marker, the rotating-star frames and the checkerboard"""
    kinds = [e["kind"] for e in player_loop(LAYOUT.frames())]
    return small[[k != "identity" for k in kinds]]


def hard_recording(E, seed=2, bits=16, **kw):
    """Starts in the middle of the sixth entry from the end; in the second loop a display frame is dropped
    (identity_04, or rotstar_06 without identity frames), in the third one the entry after the rotating-star
    frames is doubled (identity_00, or the checkerboard); camera frame 40 lost; ends 8 entries into the fourth
    loop"""
    n = len(E)
    drop = 6 + (13 if n > N_PLAIN else 7)
    sched = player_schedule(n, hold=20, refresh_hz=60, duration=12 + 2 * (n - N_PLAIN) / 3, start_entry=n - 6,
                            start_phase=0.4, drop=[drop], double=[6 + n + 9])
    return camera_stream(E, sched, int(290 + 50 * (n - N_PLAIN) / 3), fps=25, exposure_s=0.012, scan_s=1 / 60,
                         gain=GAIN, noise=NOISE, bits=bits, drop_frames=[40], rng=seed, **kw)


def identity_read(folder, truth, layout=LAYOUT) -> np.ndarray:
    """(nx * ny,) element indices decoded from the identity frames of a pose folder at the true corners (-1: unread)

    An identity frame shows each element's square uniformly, so its level at the element's centre (the corner)
    is the element's level in that frame.
    """
    files = [f["file"] for f in layout.frames() if f["kind"] == "identity"]
    xy = truth.reshape(-1, 2)
    levels = np.stack([cv2.imread(str(folder / f), cv2.IMREAD_UNCHANGED).astype(float)[
        np.round(xy[:, 1]).astype(int), np.round(xy[:, 0]).astype(int)] for f in files], axis=-1)
    return layout.identity_code.decode(levels)[0]


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
    # the identity frames, read at the true element centres, name every element: in order, none repeated
    assert identity_read(tmp_path / "seq" / "pose000", truth).tolist() == list(range(LAYOUT.nx * LAYOUT.ny))

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
def test_loops_dropped_doubled_and_the_start(small_plain):
    """Without identity frames, as before them"""
    frames, _ = hard_recording(small_plain, bits=8)
    seg = segment(frames, PLAIN.frames(), PLAIN, 255.0)
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
    plain = [f["file"] for f in PLAIN.frames()]
    starts = [seg.ranges[f][0] for f in plain]
    assert starts == sorted(starts)


def test_identity_frames_dropped_doubled_and_in_order(small):
    """The default sequence: an identity frame dropped (that loop rejected), one doubled (that loop used)"""
    frames, _ = hard_recording(small, bits=8)
    seg = segment(frames, LAYOUT.frames(), LAYOUT, 255.0)
    reasons = [v.reason for v in seg.loops]
    assert reasons[0].startswith("18 frame(s) between start markers, pattern.json has 19")
    assert seg.loop.ok and seg.chosen == 1 and any(r.startswith("incomplete") for r in reasons)
    lengths = [seg.stretches[i].length for i in seg.loop.stretches]
    assert lengths[9] > 1.6 * np.median(lengths)  # identity_00, held twice as long: one stretch
    # every averaged frame is its display frame (the identity frames differ in half of the elements: a swap
    # or a shift by one would be many times the noise)
    for k, f in enumerate(FILES):
        want = np.clip(GAIN * small[k + 1], 0, 1) * 255
        assert np.sqrt(np.mean((seg.images[f] - want) ** 2)) < 2 * NOISE * 255, f


def test_one_loop_is_enough_and_8bit(small):
    sched = player_schedule(N_ENTRIES, hold=20, duration=7.5)
    frames, _ = camera_stream(small, sched, 185, fps=25, exposure_s=0.01, noise=0.004, bits=8, rng=1)
    seg = segment(frames, LAYOUT.frames(), LAYOUT, 255.0)
    assert seg.loop.ok and len(seg.images) == len(FILES)
    assert seg.images[FILES[0]].dtype == np.float64


def test_recording_too_short_for_the_longer_loop(small):
    """One loop without identity frames is too short for the sequence with them"""
    frames, _ = camera_stream(small, player_schedule(N_ENTRIES, hold=20, duration=4.0), 60, fps=25, rng=1)
    with pytest.raises(SegmentError, match=r"too short: 60 frame\(s\), need at least 80 \(one whole loop of the "
                                           r"player: 20 entries"):
        segment(frames, LAYOUT.frames(), LAYOUT, 65535.0)


def test_every_loop_missing_a_frame_is_rejected(small_plain):
    sched = player_schedule(N_PLAIN, hold=20, duration=12, drop=[3, 13, 23])
    frames, _ = camera_stream(small_plain, sched, 290, fps=25, noise=NOISE, rng=3)
    with pytest.raises(SegmentError, match=r"no usable loop.*frame\(s\) between start markers, pattern.json has 9"):
        segment(frames, PLAIN.frames(), PLAIN, 65535.0)


def test_wrong_pattern_json_is_rejected(small, small_plain):
    frames, _ = camera_stream(small_plain, player_schedule(N_PLAIN, hold=20, duration=12), 290, fps=25, rng=4)
    six = make_layout(screen=(800, 600), pitch=100, band=24, nframes=6, identity=False)
    with pytest.raises(SegmentError, match="more than 7 stable stretches before the next start marker"):
        segment(frames, six.frames(), six, 65535.0)
    # a player without identity frames, a pattern.json with them, and the other way round
    with pytest.raises(SegmentError, match="9 frame.s. between start markers, pattern.json has 19"):
        segment(frames[:200], LAYOUT.frames(), LAYOUT, 65535.0)  # (2.4 loops: one marker per 20 entries expected)
    frames, _ = camera_stream(small, player_schedule(N_ENTRIES, hold=20, duration=12), 290, fps=25, rng=4)
    with pytest.raises(SegmentError, match="more than 9 stable stretches before the next start marker"):
        segment(frames, PLAIN.frames(), PLAIN, 65535.0)


def test_moving_camera_is_rejected(small_plain):
    sched = player_schedule(N_PLAIN, hold=20, duration=12)
    # a slow drift: stretches still form, but the image moves ~1 px over a loop
    frames, _ = camera_stream(small_plain, sched, 290, fps=25, noise=NOISE, drift_px=(0.01, 0.005), rng=5)
    with pytest.raises(SegmentError, match=r"the camera moved: the image drifts 0\.[5-9]\d px over the loop"):
        segment(frames, PLAIN.frames(), PLAIN, 65535.0, Options(max_motion=0.3))
    # still, the same recording passes
    frames, _ = camera_stream(small_plain, sched, 290, fps=25, noise=NOISE, rng=5)
    seg = segment(frames, PLAIN.frames(), PLAIN, 65535.0, Options(max_motion=0.3))
    assert seg.loop.motion_px < 0.05
    # shaking: no stable stretches at all
    rng = np.random.default_rng(6)
    shaken = np.stack([np.roll(f, tuple(rng.integers(-3, 4, 2)), axis=(0, 1)) for f in frames])
    with pytest.raises(SegmentError, match="the view is not still"):
        segment(shaken, PLAIN.frames(), PLAIN, 65535.0)


def test_no_player_no_marker(small):
    frames = np.repeat((small[3:5] * 60000).astype(np.uint16), 20, axis=0)  # two frames, no marker, no loop
    frames[20:] = (small[3] * 60000).astype(np.uint16)
    with pytest.raises(SegmentError):
        segment(frames, PLAIN.frames(), PLAIN, 65535.0)


def test_small_board_far_away_keeps_the_identity_frames_apart(tmp_path):
    """The board's corners span 1 % of the image: the changes between identity frames stay far above the threshold

    Averaged over the whole image, the change between two identity frames (a quarter of the board's area) was
    about the noise of the room around the screen; segmentation averages over the screen's pixels only
    (motion.screen_pixels).
    """
    model = simulate.preset_model("pinhole-small")
    rt = simulate.look_at_pose(model, LAYOUT, (200.0, 150.0), 0.3, tilt=0.3)
    E = loop_irradiance(LAYOUT, model, rt, supersample=2)
    corners = simulate.true_corners(model, LAYOUT, rt)
    x0, y0 = corners.reshape(-1, 2).min(axis=0)
    x1, y1 = corners.reshape(-1, 2).max(axis=0)
    assert (x1 - x0) * (y1 - y0) / (640 * 400) < 0.01
    frames, _ = camera_stream(E, player_schedule(N_ENTRIES, hold=20, duration=8), 200, fps=25, noise=NOISE, rng=9)
    seg = segment(frames, LAYOUT.frames(), LAYOUT, 65535.0)
    sts = [seg.stretches[i] for i in seg.loop.stretches]
    jump = [np.nanmax(seg.d[a.stop : b.start + 1]) / seg.tau for a, b in zip(sts, sts[1:])]
    print("change / threshold at each loop entry:", np.round(jump, 1).tolist())
    assert min(jump[9:19]) > 5  # identity_00 ... checkerboard
    assert 0.005 < seg.mask.mean() < 0.1  # the screen, not the room
    for k, f in enumerate(FILES):
        want = np.clip(GAIN * E[k + 1], 0, 1) * 65535
        assert np.sqrt(np.mean((seg.images[f] - want) ** 2)) < 2 * NOISE * 65535, f


def test_board_partly_out_of_view(tmp_path, capsys):
    """The case identity frames are for: part of the board outside the image; rotstar-segment as a device's
    recording goes through it, the identity frames read back at the true corners in view"""
    model = simulate.preset_model("pinhole-small")
    rt = simulate.look_at_pose(model, LAYOUT, (40.0, 330.0), 0.12, tilt=0.4, roll=0.2)
    truth = simulate.true_corners(model, LAYOUT, rt)
    inside = np.all((truth > 3) & (truth < np.array([636, 396])), axis=-1)
    assert 4 < inside.sum() < LAYOUT.nx * LAYOUT.ny - 4
    E = loop_irradiance(LAYOUT, model, rt, supersample=2)
    frames, seq = camera_stream(E, player_schedule(N_ENTRIES, hold=20, duration=9, start_entry=17), 220, fps=25,
                                noise=NOISE, gain=GAIN, rng=10)
    save_recording(str(tmp_path / "rec.npy"), frames, seq, fps=25)
    (tmp_path / "pattern.json").write_text(LAYOUT.to_json())
    code, out, err = run(rotstar_segment, tmp_path / "rec.npy", "--pattern", tmp_path, "--out",
                         tmp_path / "seq" / "pose000", capsys=capsys)
    assert code == 0, err
    got = identity_read(tmp_path / "seq" / "pose000", np.clip(truth, 0, [639, 399]))
    want = np.arange(LAYOUT.nx * LAYOUT.ny)
    assert np.array_equal(got[inside.ravel()], want[inside.ravel()])


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
    # a part of the board in view: the identity frames' levels are those of the elements in view, anything
    # from all black to all white; the order check does not depend on them
    rec = want.copy()
    rec[9:19] = np.random.default_rng(0).uniform(0.2, 0.45, 10)
    assert check_order(rec, want, 0.9)[1] == ""
    plain = expected_levels(PLAIN, player_loop(PLAIN.frames()))
    assert check_order(plain, want[[k for k in range(20) if not 9 <= k < 19]], 0.9)[1] == ""


@pytest.mark.slow
def test_d435_full_size_10bit_end_to_end(tmp_path, capsys):
    """The real case: the default iPad layout and sequence (13 identity frames), the D435 preset at 1280x800,
    Y16 words holding 10-bit values"""
    layout = make_layout()
    model = simulate.preset_model("d435")
    rt = simulate.random_poses(model, layout, 1, np.random.default_rng(11))[0]
    E = loop_irradiance(layout, model, rt, supersample=2)
    truth = simulate.true_corners(model, layout, rt)
    sched = player_schedule(len(player_loop(layout.frames())), hold=20, refresh_hz=60, duration=14.5,
                            start_entry=7, start_phase=0.5)
    frames, seq = camera_stream(E, sched, 360, fps=25, exposure_s=0.008, gain=GAIN, noise=NOISE, value_bits=10, rng=3)
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
    assert identity_read(tmp_path / "seq" / "pose000", truth, layout).tolist() == list(range(126))
    e = np.linalg.norm(got - truth, axis=-1)
    print(f"D435 10-bit: rms {np.sqrt(np.mean(e**2)):.4f} px, max {e.max():.4f} px")
    assert np.sqrt(np.mean(e**2)) < 0.02


# ---- the paper's whole sequence ------------------------------------------------------------
PAPER = make_layout(screen=(800, 600), pitch=100, band=24, phase_period=100, star_segments=16)


def test_paper_sequence_segments_in_order():
    """rotstar-pattern --paper-sequence: the phase shifts (whose four steps have the same level) and the star
    come back each as its own display frame, in order"""
    model = simulate.preset_model("pinhole-small")
    rt = simulate.random_poses(model, PAPER, 1, np.random.default_rng(3))[0]
    E = half(loop_irradiance(PAPER, model, rt, supersample=2))
    n = len(player_loop(PAPER.frames()))
    assert n == 29  # marker, 8 rotating-star, 10 identity, 8 phase, the checkerboard, the star
    sched = player_schedule(n, hold=20, duration=2.2 * n / 3)
    frames, _ = camera_stream(E, sched, int(25 * 2.1 * n / 3), fps=25, exposure_s=0.01, noise=0.004, bits=8, rng=1)
    seg = segment(frames, PAPER.frames(), PAPER, 255.0)
    assert seg.loop.ok, [v.reason for v in seg.loops]
    for k, f in enumerate(PAPER.frames()):  # a phase step swapped with its neighbour would be a quarter period off
        want = np.clip(GAIN * E[k + 1], 0, 1) * 255
        assert np.sqrt(np.mean((seg.images[f["file"]] - want) ** 2)) < 2 * 0.004 * 255, f["file"]

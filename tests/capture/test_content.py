"""Segmentation by content: any window of the loop, short holds, blends left out, a missing frame named

The recordings are the capture's simulated camera (capture.simulated) filming
the default sequence (20 loop entries) on a small screen at a quarter of the
pinhole-small camera's size (tiny images: fast), held 6 refreshes at 60 Hz
(100 ms, two or three camera frames at 25 fps, the ones near a change blend
two displayed frames row by row). Truth per camera frame: which entry it
mostly shows and how much of another it carries (impurity, the largest
difference at any pixel from the clean entry, in units of the screen's white).
"""

from __future__ import annotations

import dataclasses
import json
import os

import cv2
import numpy as np
import pytest

from rotstar_mrcal import simulate
from rotstar_mrcal.capture.pose import write_segmented
from rotstar_mrcal.capture.content import gain_residual, segment_content, step_time
from rotstar_mrcal.capture.segment import Options, SegmentError, segment
from rotstar_mrcal.capture.simulated import blend_weights, camera_stream, loop_irradiance, player_schedule
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.pattern.loop import player_loop

LAYOUT = make_layout(screen=(800, 600), pitch=100, band=24)
LOOP = player_loop(LAYOUT.frames())
N = len(LOOP)
FPS, EXPOSURE, SCAN = 25.0, 0.008, 1 / 60
OPTS = Options(hold=6)  # the player held every entry 6 refreshes
BLEND = 0.1  # a camera frame carrying more than this of another displayed frame at any pixel is a blend


@pytest.fixture(scope="module")
def E():
    model = simulate.preset_model("pinhole-small")
    rt = simulate.random_poses(model, LAYOUT, 1, np.random.default_rng(3))[0]
    E = loop_irradiance(LAYOUT, model, rt, supersample=2)
    return np.stack([cv2.resize(e, (e.shape[1] // 4, e.shape[0] // 4), interpolation=cv2.INTER_AREA) for e in E])


def truth(E, sched, T, t0=0.0):
    """[(entry, impurity)] of every camera frame"""
    out = []
    for i in range(T):
        a = t0 + i / FPS
        w = blend_weights(sched, a, a + EXPOSURE, E.shape[1], SCAN)
        e = max(w, key=lambda k: w[k].mean())
        out.append((e, float(np.abs(sum(w[k][:, None] * E[k] for k in w) - E[e]).max())))
    return out


def record(E, hold=6, start_entry=7, start_phase=0.3, loops=1.0, seed=0, **kw):
    dur = loops * N * hold / 60 + 2 * hold / 60
    sched = player_schedule(N, hold, duration=dur + 1, start_entry=start_entry, start_phase=start_phase,
                            drop=kw.pop("drop", ()))
    T = int(dur * FPS)
    frames, seq = camera_stream(E, sched, T, fps=FPS, exposure_s=EXPOSURE, scan_s=SCAN, noise=0.01, rng=seed, **kw)
    return frames, seq, truth(E, sched, T)


def check_clean(seg, tr, seq):
    """Every camera frame averaged for a file shows that file's entry, and no blend"""
    for k, e in enumerate(LOOP[1:], 1):
        used = seg.used[e["file"]]
        assert used, e["file"]
        for i in used:
            entry, imp = tr[seq[i]]  # (truth is indexed by the camera's sequence number)
            assert entry == k and imp <= BLEND, (e["file"], int(seq[i]), entry, imp)


def test_one_pass_from_mid_loop(E, tmp_path):
    """A window of one loop (plus two entries) starting in the middle: no two start markers, split by content"""
    frames, seq, tr = record(E)
    with pytest.raises(SegmentError):  # between start markers it cannot be done
        segment(frames, LAYOUT.frames(), LAYOUT, 65535.0, Options(method="loop"))
    seg = segment(frames, LAYOUT.frames(), LAYOUT, 65535.0, OPTS, times=seq / FPS)  # 'auto': content
    assert seg.method == "content" and len(seg.images) == N - 1
    check_clean(seg, tr, seq)
    assert "found by their content" in seg.summary()
    folder = write_segmented(str(tmp_path), "pose000", seg, LAYOUT.to_dict(), 65535.0)
    info = json.loads((tmp_path / "pose000" / "segment.json").read_text())
    assert info["method"] == "content" and info["frames_used"]["checkerboard.png"] == seg.used["checkerboard.png"]
    assert sorted(os.listdir(folder)) == sorted([e["file"] for e in LOOP[1:]] + ["segment.json"])


def test_window_without_the_marker(E):
    """The recording starts just after the start marker and ends before it comes again"""
    sched = player_schedule(N, 6, duration=4, start_entry=1)
    T = int((N - 1) * 6 / 60 * FPS) + 1  # the last camera frame ends as the marker comes on
    frames, seq = camera_stream(E, sched, T, fps=FPS, exposure_s=EXPOSURE, scan_s=SCAN, noise=0.01, rng=1)
    seg = segment_content(frames, LAYOUT.frames(), LAYOUT, 65535.0, OPTS, times=seq / FPS)
    assert not seg.markers.any()
    check_clean(seg, truth(E, sched, T), seq)


def test_pwm_brightness_and_several_loops(E):
    """Brightness changing 4 % from frame to frame (a gain, not a picture), 2.5 loops: every visit is averaged"""
    frames, seq, tr = record(E, loops=2.5, start_entry=15, seed=4)
    rng = np.random.default_rng(5)
    gains = 1 + 0.04 * rng.uniform(-1, 1, len(frames))
    frames = np.clip(frames * gains[:, None, None], 0, 65535).astype(np.uint16)
    seg = segment_content(frames, LAYOUT.frames(), LAYOUT, 65535.0, OPTS, times=seq / FPS)
    check_clean(seg, tr, seq)
    assert min(len(u) for u in seg.used.values()) >= 4  # two or three passes of every frame


def lose(E, files: list[str]):
    """A recording from which the camera lost every frame that saw these files (gaps in its sequence numbers)"""
    ks = {i for i, e in enumerate(LOOP) if e["file"] in files}
    _, _, tr = record(E, start_entry=3)
    lost = [i for i, (e, _) in enumerate(tr) if e in ks]
    frames, seq, _ = record(E, start_entry=3, drop_frames=lost)
    assert len(frames) == len(tr) - len(lost)
    return frames, seq


def test_a_missing_frame_is_named(E):
    """The camera lost every frame that saw identity_03 and identity_05: more than the pose can spare, refused
    naming both; a rotating-star frame lost alone is refused too"""
    frames, seq = lose(E, ["identity_03.png", "identity_05.png"])
    with pytest.raises(SegmentError, match=r"2 frame\(s\) of pattern.json not seen clean: identity_03\.png, "
                                           r"identity_05\.png"):
        segment_content(frames, LAYOUT.frames(), LAYOUT, 65535.0, OPTS, times=seq / FPS)
    frames, seq = lose(E, ["rotstar_04.png"])
    with pytest.raises(SegmentError, match=r"1 frame\(s\) of pattern.json not seen clean: rotstar_04\.png"):
        segment_content(frames, LAYOUT.frames(), LAYOUT, 65535.0, OPTS, times=seq / FPS)


def test_one_identity_frame_and_the_checkerboard_are_spared(E):
    """One identity frame and the checkerboard lost: the pose is split without them (pattern.layout.SPARE_KINDS),
    every other frame clean and in its place; with content_spare=False it is refused, naming them"""
    frames, seq = lose(E, ["identity_03.png", "checkerboard.png"])
    seg = segment_content(frames, LAYOUT.frames(), LAYOUT, 65535.0, OPTS, times=seq / FPS)
    assert seg.missing == ["identity_03.png", "checkerboard.png"]
    assert set(seg.images) == {f["file"] for f in LAYOUT.frames()} - set(seg.missing)
    assert "not seen: identity_03.png, checkerboard.png" in seg.summary()
    strict = dataclasses.replace(OPTS, content_spare=False)
    with pytest.raises(SegmentError, match=r"2 frame\(s\) .*: identity_03\.png, checkerboard\.png"):
        segment_content(frames, LAYOUT.frames(), LAYOUT, 65535.0, strict, times=seq / FPS)


def test_another_pattern_is_refused(E):
    """The player shows 8 rotating-star frames, pattern.json has 6: more displayed frames than entries"""
    six = make_layout(screen=(800, 600), pitch=100, band=24, nframes=6)
    frames, seq, _ = record(E, loops=1.5)
    with pytest.raises(SegmentError):
        segment_content(frames, six.frames(), six, 65535.0, OPTS, times=seq / FPS)


def test_pieces():
    x = np.linspace(0, 1, 200)
    assert np.abs(gain_residual(x, 1.03 * x - 0.01)).max() < 1e-9
    assert np.abs(gain_residual(x, 1 - x)).max() > 0.3  # the inverse picture is no gain
    assert step_time(np.ones(4), 3, 0) == 1.0 and step_time(np.ones(4), 1, 1) == 4.0

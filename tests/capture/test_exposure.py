"""The exposure picked from a short look at the playing screen (capture.exposure), on synthetic frames and on the
capture's simulated camera, and rotstar-capture's auto exposure end to end"""

from __future__ import annotations

import json
import math
import re

import cv2
import numpy as np
import pytest

from conftest import SMALL_LAYOUT

from rotstar_mrcal import simulate
from rotstar_mrcal.capture.exposure import (
    MEASURABLE, TARGET, TOLERANCE, choose_exposure, longest_exposure_us, look_frames, measure_look, next_exposure,
)
from rotstar_mrcal.capture.simulated import ALL_FLAWS, Flaws, SimulatedCamera, loop_irradiance
from rotstar_mrcal.cli.capture import main as rotstar_capture
from rotstar_mrcal.cli.detect import main as rotstar_detect
from rotstar_mrcal.pattern.loop import entry_holds, player_loop

FS = 65535.0
LONGEST = 38000.0
LAYOUT = SMALL_LAYOUT  # (the pattern_dir fixture's) the default sequence: 8 + 10 identity frames + 1
HOLDS = entry_holds(player_loop(LAYOUT.frames()))  # the short holds: the star 11 refreshes, the rest 6 (marker 3)
FULL_SCALE_US = 13300.0  # SimulatedCamera's default: irradiance 1 at full scale


def screen_look(white: float, frames: int = 8, hot: int = 0, flicker=None, seed: int = 0) -> np.ndarray:
    """(frames, 120, 160) 16-bit frames: a dark room (2 %, noise 1 %), a screen of 16-px squares whose colours change
    every frame, frame 0 the black start marker; white in fractions of full scale (above 1: clipped); hot: that many
    hot pixels at full scale (a few of them in clusters, like a specular glint); flicker: the light of each frame"""
    rng = np.random.default_rng(seed)
    f = rng.normal(0.02, 0.01, (frames, 120, 160))
    yy, xx = np.mgrid[0:80, 0:128] // 16
    gains = np.ones(frames) if flicker is None else np.asarray(flicker, float)
    for t in range(1, frames):
        f[t, 20:100, 16:144] += white * gains[t] * ((yy + xx + t) % 2)
    if hot:
        ys, xs = rng.integers(0, 120, hot), rng.integers(0, 160, hot)
        f[:, ys, xs] = 1.0
        f[:, 50:53, 60:63] = 1.0  # a glint
    return np.rint(np.clip(f, 0, 1) * FS).astype(np.uint16)


# ---- one look ---------------------------------------------------------------------------------
def test_a_right_look_is_kept():
    look = measure_look(screen_look(0.74), FS)
    assert look.screen and not look.clipped and look.white == pytest.approx(0.74 + 0.02, abs=0.01)
    step = next_exposure(look, 6200, 20, LONGEST)
    assert step.done and step.exposure_us == 6200 and not step.failure


def test_dark_look_scales_up_and_clipped_look_steps_down():
    look = measure_look(screen_look(0.10), FS)  # the white at 12 % of full scale (the room's 2 % included)
    step = next_exposure(look, 1000, 20, LONGEST)
    assert not step.done and step.exposure_us == pytest.approx(1000 * TARGET / look.white, rel=0.05)
    # clipped: the white only says "at least full scale": 4 times shorter, not the proportional guess
    look = measure_look(screen_look(3.0), FS)
    assert look.clipped and next_exposure(look, 30000, 20, LONGEST).exposure_us == 7500
    assert "clipped even at the shortest exposure, 20 us" in next_exposure(look, 20, 20, LONGEST).failure
    # a dim screen, clamped at the longest exposure: kept when its white there is enough ...
    look = measure_look(screen_look(0.10), FS)
    assert next_exposure(look, 10000, 20, LONGEST).exposure_us == LONGEST
    # ... else one line: too dark
    fail = next_exposure(measure_look(screen_look(0.08), FS), LONGEST, 20, LONGEST).failure
    assert fail.startswith("the screen is too dark: its white would reach only 10% of full scale at the longest "
                           "exposure, 38000 us") and "\n" not in fail


def test_hot_pixels_and_a_glint_neither_set_the_white_nor_clip_it():
    clean, hot = measure_look(screen_look(0.6), FS), measure_look(screen_look(0.6, hot=200), FS)
    assert not hot.clipped and hot.white == pytest.approx(clean.white, abs=0.005)
    assert next_exposure(hot, 5000, 20, LONGEST).exposure_us == pytest.approx(5000 * TARGET / clean.white, rel=0.03)


def test_flicker_takes_the_brightest_frame():
    """A PWM backlight through a short exposure: every frame another light; the brightest frame must not clip"""
    gains = [1, 0.55, 1.0, 0.7, 1.25, 0.6, 0.9, 0.8]
    look = measure_look(screen_look(0.5, flicker=gains), FS)
    assert look.white == pytest.approx(0.5 * 1.25 + 0.02, abs=0.01) and look.spread > 0.4
    got = next_exposure(look, 4000, 20, LONGEST).exposure_us
    assert 0.5 * 1.25 * got / 4000 <= 0.78  # the brightest frame at the target, not the mean one


def test_no_screen_steps_up_then_says_so():
    rng = np.random.default_rng(1)
    still = np.rint(np.clip(rng.normal(0.3, 0.01, (8, 120, 160)), 0, 1) * FS).astype(np.uint16)  # a lit wall
    still[:, 40:60, 40:60] = FS  # a lamp, clipped, but not the screen
    look = measure_look(still, FS)
    assert not look.screen and look.contrast < MEASURABLE and math.isnan(look.white)
    assert next_exposure(look, 4000, 20, LONGEST).exposure_us == 32000
    fail = next_exposure(look, LONGEST, 20, LONGEST).failure
    assert fail.startswith("no screen in view (or it is black)") and "38000 us" in fail


# ---- looks at the simulated camera --------------------------------------------------------------
@pytest.fixture(scope="module")
def scene():
    """The loop's irradiance as the pinhole-small camera sees the screen (full size, and a quarter for speed)"""
    model = simulate.preset_model("pinhole-small")
    rt = simulate.random_poses(model, LAYOUT, 1, np.random.default_rng(3))[0]
    E = loop_irradiance(LAYOUT, model, rt, supersample=2)
    small = np.stack([cv2.resize(e, (e.shape[1] // 4, e.shape[0] // 4), interpolation=cv2.INTER_AREA) for e in E])
    return E, small


def true_white(E: np.ndarray, exposure_us: float) -> float:
    """The white a look would measure without noise, clipping or flaws (the sensor is linear)"""
    return measure_look(np.asarray(E) * FS, FS).white * exposure_us / FULL_SCALE_US


@pytest.mark.parametrize("flaws", [Flaws(), ALL_FLAWS], ids=["clean", "all-flaws"])
@pytest.mark.parametrize("start", [500, 4000, 30000])
def test_choose_exposure_on_the_simulated_camera(scene, start, flaws):
    E = scene[1]
    cam = SimulatedCamera(E, HOLDS, flaws=flaws, seed=start)
    got = choose_exposure(cam, start, look_frames(HOLDS, 60, cam.fps), 8, 20, longest_exposure_us(cam.fps))
    assert not got.failure and got.looks <= 3 and cam.exposure_at(cam.i) == got.exposure_us
    assert abs(true_white(E, got.exposure_us) / TARGET - 1) <= TOLERANCE + 0.03, got
    assert abs(got.white / TARGET - 1) <= TOLERANCE
    assert got.seconds == pytest.approx(got.frames / 25.0) and got.seconds <= 3 * (8 + 9) / 25.0  # 2.04 s
    assert got.history[0][0] == start


def test_a_black_screen_and_a_dim_one_fail_in_one_line(scene):
    E = scene[1]
    got = choose_exposure(SimulatedCamera(0 * E, HOLDS), 8000, 8, 8, 20, LONGEST)
    assert math.isnan(got.exposure_us) and got.summary().startswith("no screen in view") and got.looks == 2
    assert [e for e, _ in got.history] == [8000, LONGEST]  # 8 times longer, limited to the longest
    got = choose_exposure(SimulatedCamera(0.05 * E, HOLDS), 8000, 8, 8, 20, LONGEST)
    assert got.summary().startswith("the screen is too dark") and "\n" not in got.summary()


# ---- rotstar-capture -----------------------------------------------------------------------------
def capture(argv, cam, capsys):
    code = rotstar_capture([str(a) for a in argv] + ["--hold", "short", "--camera", "generic"], source=cam)
    out, err = capsys.readouterr()
    return code, out, err


def test_capture_picks_its_exposure_then_records(scene, pattern_dir, tmp_path, capsys):
    """No --exposure: a look from 8000 us picks one, says it, and the pose is recorded at it into OUT/exp<us>us"""
    E = scene[0]
    cam = SimulatedCamera(E, HOLDS, flaws=ALL_FLAWS, exposure_us=30000, seed=5)
    code, out, err = capture(["--pattern", pattern_dir, "--out", tmp_path / "seq", "--auto", "--poses", 1], cam,
                             capsys)
    assert code == 0, err
    m = re.search(r"rotstar-capture: exposure: (\d+) us \(white at (\d+) % of full scale after (\d) looks?, "
                  r"([\d.]+) s\)\n", err)
    assert m, err
    us, white = int(m[1]), int(m[2]) / 100
    assert abs(white / TARGET - 1) <= TOLERANCE and abs(true_white(E, us) / TARGET - 1) <= TOLERANCE + 0.03
    assert out.split() == [str(tmp_path / "seq" / f"exp{us}us" / "pose000")]
    assert f"pose000 at {us} us: board complete (24/24)" in err
    assert cam.exposures[-1][1] == us and cam.exposure_at(cam.i - 1) == us  # recorded at the exposure picked
    log = json.loads((tmp_path / "seq" / "capture.json").read_text())
    assert log["auto_exposure"]["exposure_us"] == us and log["auto_exposure"]["history"][0][0] == 8000
    seg = json.loads((tmp_path / "seq" / f"exp{us}us" / "pose000" / "segment.json").read_text())
    assert seg["exposure_us"] == us and (tmp_path / "seq" / f"exp{us}us" / "pattern.json").exists()
    # the written star frame's white: where the look put it (the averages are 16-bit, full scale 65535)
    img = cv2.imread(str(tmp_path / "seq" / f"exp{us}us" / "pose000" / "rotstar_00.png"), cv2.IMREAD_UNCHANGED)
    assert 0.6 < np.percentile(img, 99.5) / FS < 0.9
    # and rotstar-detect reads the dataset as one given by --exposure
    assert rotstar_detect([str(tmp_path / "seq" / f"exp{us}us")]) == 0
    corners = [ln for ln in capsys.readouterr().out.splitlines() if ln and not ln.startswith("#")]
    assert len(corners) == 24 and all("/pose000/rotstar_00.png " in ln for ln in corners)


def test_capture_keep_leaves_the_exposure_alone(scene, pattern_dir, tmp_path, capsys):
    cam = SimulatedCamera(scene[0], HOLDS, exposure_us=9000, seed=6)
    code, out, err = capture(["--pattern", pattern_dir, "--out", tmp_path / "seq", "--auto", "--poses", 1,
                              "--exposure", "keep"], cam, capsys)
    assert code == 0, err
    assert out.split() == [str(tmp_path / "seq" / "pose000")] and "exposure:" not in err
    assert cam.exposures == [(0, 9000.0)]


def test_capture_black_screen_fails_in_one_line(scene, pattern_dir, tmp_path, capsys):
    cam = SimulatedCamera(0 * scene[1], HOLDS)
    code, out, err = capture(["--pattern", pattern_dir, "--out", tmp_path / "seq", "--auto"], cam, capsys)
    lines = [ln for ln in err.splitlines() if "exposure auto" in ln]
    assert code == 1 and out == "" and "Traceback" not in err
    assert len(lines) == 1 and lines[0].startswith("rotstar-capture: exposure auto: no screen in view")
    assert "exit status: 0 done; 1 a camera that cannot be opened or set, a screen the exposure look" in \
        " ".join(help_text(capsys).split())


def help_text(capsys) -> str:
    with pytest.raises(SystemExit):
        rotstar_capture(["--help"])
    return capsys.readouterr().out


def test_help_and_replay(capsys):
    text = " ".join(help_text(capsys).split())
    assert "--exposure auto|keep|US[,US...]" in text and "keep: leave the camera's exposure alone" in text
    with pytest.raises(SystemExit) as e:  # a replay has its own exposure: no look
        rotstar_capture(["--backend", "replay", "--device", "x.npy", "--pattern", "p", "--out", "o", "--exposure",
                         "auto"])
    assert e.value.code == 2 and "a replay has the exposure it was recorded with" in capsys.readouterr().err

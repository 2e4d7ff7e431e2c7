"""The simulator's cover glass: rays refracted at the glass surface on their way to the emitting layer"""

from __future__ import annotations

import mrcal
import numpy as np
import pytest

from rotstar_mrcal.cli.simulate import parse_args, settings_of
from rotstar_mrcal.optics.refraction import Glass, apparent_points, emitting_hits
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.simulate import Settings, exact_frames, make_screen, preset_model, render_irradiance
from rotstar_mrcal.simulate.irradiance import board_hits

LAYOUT = make_layout(screen=(800, 600), pitch=100, band=24)
H = 0.3  # camera height above the emitting layer, metres
T = 0.0012  # glass thickness, metres


def ray_at(theta_deg: float, azimuth_deg: float = 0.0) -> np.ndarray:
    th, az = np.radians(theta_deg), np.radians(azimuth_deg)
    return np.array((np.sin(th) * np.cos(az), np.sin(th) * np.sin(az), np.cos(th)))


def test_a_ray_along_the_normal_is_not_moved():
    c = np.array((0.01, -0.02, -H))
    p = emitting_hits(c, np.array((0.0, 0.0, 2.0)), Glass(T, 1.5))
    assert np.array_equal(p, c[:2])
    # and through the renderer: the board point under a head-on camera's optical axis stays put
    rt = np.array((0, 0, 0, -0.03, -0.02, H))
    straight = board_hits(np.array((0.0, 0.0, 1.0)), rt, LAYOUT)
    bent = board_hits(np.array((0.0, 0.0, 1.0)), rt, LAYOUT, Glass(T, 1.5))
    assert np.allclose(straight, bent, atol=1e-9)


@pytest.mark.parametrize("theta", [10.0, 30.0, 45.0, 60.0, 75.0])
@pytest.mark.parametrize("n", [1.5, 1.8])
def test_the_shift_is_t_tan_theta_g_toward_the_camera(theta, n):
    """Closed form: the ray crosses the glass surface at (H - T) tan(theta) from the camera's foot, then runs
    T tan(theta_g) on, sin(theta) = n sin(theta_g); a straight ray would run T tan(theta) on"""
    theta_g = np.arcsin(np.sin(np.radians(theta)) / n)
    c = np.array((0.004, 0.002, -H))
    for az in (0.0, 37.0, 200.0):
        d = ray_at(theta, az)
        u = d[:2] / np.linalg.norm(d[:2])
        p = emitting_hits(c, 3.7 * d, Glass(T, n))
        surface = c[:2] + (H - T) * np.tan(np.radians(theta)) * u  # where the ray crosses the glass surface
        straight = c[:2] + H * np.tan(np.radians(theta)) * u
        assert np.allclose(p - surface, T * np.tan(theta_g) * u, atol=1e-12)
        assert np.allclose(straight - p, T * (np.tan(np.radians(theta)) - np.tan(theta_g)) * u, atol=1e-12)


def test_the_renderer_uses_the_refracted_hit():
    """board_hits with glass, in display pixels, against the closed form of a head-on camera's tilted ray"""
    rt = np.array((0, 0, 0, -0.03, -0.02, H))
    theta, n = 40.0, 1.5
    d = ray_at(theta, 0.0)
    u0, v0 = board_hits(d, rt, LAYOUT)
    u1, v1 = board_hits(d, rt, LAYOUT, Glass(T, n))
    theta_g = np.arcsin(np.sin(np.radians(theta)) / n)
    shift_px = T * (np.tan(np.radians(theta)) - np.tan(theta_g)) / LAYOUT.pixel_pitch_m
    assert float(u0 - u1) == pytest.approx(shift_px, rel=1e-9)
    assert float(v0 - v1) == pytest.approx(0.0, abs=1e-9)


def test_apparent_points_invert_the_forward_trace():
    """A camera ray traced through the glass to P; apparent_points(c, P) lies on that ray, in the board's plane"""
    rng = np.random.default_rng(3)
    c = np.array((0.05, -0.03, -0.35))
    d = np.column_stack((rng.uniform(-1, 1, (50, 2)), np.ones(50)))
    p = emitting_hits(c, d, Glass(T, 1.5))
    a = apparent_points(c, np.column_stack((p, np.zeros(50))), Glass(T, 1.5))
    straight = c[:2] + (-c[2] / d[:, 2])[:, None] * d[:, :2]
    assert np.max(np.abs(a[:, :2] - straight)) < 1e-12
    assert np.all(a[:, 2] == 0)
    assert np.array_equal(apparent_points(c, np.column_stack((p, np.zeros(50))), Glass(0.0)),
                          np.column_stack((p, np.zeros(50))))


def test_no_glass_renders_byte_identical():
    screen = make_screen(exact_frames(LAYOUT)[-1:], LAYOUT, room=0.02)
    model = preset_model("pinhole-small")
    rt = mrcal.compose_rt(np.array((0, 0, 0, -0.0385, -0.0289, 0.12)), np.array((0.3, -0.2, 0.1, 0, 0, 0)))
    plain = render_irradiance(screen, model, rt, supersample=2, psf=1.0)
    assert np.array_equal(plain, render_irradiance(screen, model, rt, supersample=2, psf=1.0, glass=Glass(0.0)))
    assert Settings().glass is None and Settings(glass_mm=0.0).glass is None
    bent = render_irradiance(screen, model, rt, supersample=2, psf=1.0, glass=Glass(0.001))
    assert np.abs(bent - plain).max() > 0.05  # a 1 mm glass moves the edges at this tilt


def test_cli_glass_options():
    a = parse_args(["--out", "x", "--glass", "0.7", "--glass-index", "1.52"])
    s = settings_of(a)
    assert (s.glass_mm, s.glass_index) == (0.7, 1.52) and s.glass == Glass(0.0007, 1.52)
    assert settings_of(parse_args(["--out", "x"])).glass is None


@pytest.mark.parametrize("bad", [["--glass", "-0.1"], ["--glass", "5.5"], ["--glass", "thin"], ["--glass", "nan"],
                                 ["--glass-index", "0.9"], ["--glass-index", "x"]])
def test_cli_bad_glass(bad, capsys):
    with pytest.raises(SystemExit) as e:
        parse_args(["--out", "x", *bad])
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("rotstar-simulate: error: argument ") and bad[0] in err[-1] and bad[1] in err[-1]

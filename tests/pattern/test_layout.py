"""The display sequence: layout contract and exact rendering"""

import json
import re
import math

import cv2
import numpy as np
import pytest

from conftest import run_command
from rotstar_mrcal.pattern.layout import choose_marker, layout_from_dict, make_layout, marker_orbit
from rotstar_mrcal.pattern.render import checker_coverage, decode_display, encode_display, render_frame


@pytest.fixture(scope="module")
def small():
    return make_layout(screen=(800, 600), pitch=100, band=24)


def supersampled_checker(dx, dy, theta, n=128):
    t = (np.arange(n) + 0.5) / n - 0.5
    sy, sx = np.meshgrid(t, t, indexing="ij")
    px, py = dx[..., None, None] + sx, dy[..., None, None] + sy
    c, s = math.cos(theta), math.sin(theta)
    prod = (c * px + s * py) * (-s * px + c * py)
    return np.mean(np.where(np.abs(prod) < 1e-9, 0.5, prod < 0), axis=(-1, -2))  # samples on a line count half


@pytest.mark.parametrize("k", range(8))
def test_checker_coverage_is_area_fraction(k):
    dy, dx = np.mgrid[-12:12, -12:12] + 0.5
    theta = k * math.pi / 16
    exact = checker_coverage(dx, dy, theta)
    # 128x128 supersampling is itself accurate to ~1/128 of an edge pixel
    assert np.abs(exact - supersampled_checker(dx, dy, theta)).max() < 2e-3


def test_frame0_is_pixel_aligned(small):
    x0, y0, x1, y1 = small.board_extent()
    board = render_frame(small, small.frames()[0])[y0:y1, x0:x1]
    # corners, element edges and bands lie on pixel boundaries: no pixel is split
    assert set(np.unique(board)) == {0.0, 1.0}
    # a rotated frame has anti-aliased pixels along its lines
    rotated = render_frame(small, small.frames()[1])[y0:y1, x0:x1]
    assert ((rotated > 0) & (rotated < 1)).sum() > 4 * small.nx * small.ny * small.half_element


def test_corners_on_pixel_boundaries_and_point_symmetric(small):
    for f in small.frames()[: small.nframes]:
        img = render_frame(small, f)
        for (x, y) in small.corner_screen_xy().reshape(-1, 2).astype(int):
            h = small.half_element
            patch = img[y - h : y + h, x - h : x + h]
            # point symmetry about the corner (x, y): pixel (x+a, y+b) <-> (x-1-a, y-1-b)
            assert np.allclose(patch, patch[::-1, ::-1], atol=1e-9)


def test_bands_alternate_and_checkerboard_matches_frame0(small):
    f = small.frames()
    x0, y0, x1, y1 = small.board_extent()
    for k in range(small.nframes):
        img = render_frame(small, f[k])
        assert img[y0 + 2, x0 + 2] == (1.0 if k % 2 == 0 else 0.0)
    rs0, cb = render_frame(small, f[0]), render_frame(small, f[-1])
    assert f[-1]["kind"] == "checkerboard"
    # away from the marker, frame 0's quadrants have the checkerboard's colours
    for (i, j), (x, y) in zip(np.ndindex(small.ny, small.nx), small.corner_screen_xy().reshape(-1, 2).astype(int)):
        i, j = j, i
        d = small.half_element // 2
        same = rs0[y + d, x + d] == cb[y + d, x + d]
        assert same == ((i, j) != small.marker)


def test_default_layout_fits_ipad_and_d435():
    L = make_layout()
    assert (L.screen_width, L.screen_height) == (2360, 1640)
    assert 110 <= L.nx * L.ny <= 150
    x0, y0, x1, y1 = L.checkerboard_extent()
    assert x0 >= 0 and y0 >= 0 and x1 <= 2360 and y1 <= 1640
    assert L.spacing_m == pytest.approx(150 * 0.0254 / 264)


@pytest.mark.parametrize("nx,ny", [(14, 9), (9, 9), (6, 4), (11, 8), (3, 3)])
def test_marker_orbit_is_full(nx, ny):
    m = choose_marker(nx, ny) if (nx, ny) != (3, 3) else None
    if m is None:
        with pytest.raises(ValueError):
            choose_marker(nx, ny)
        return
    assert len(marker_orbit(m, nx, ny)) == (8 if nx == ny else 4)
    assert 0 < m[0] < nx - 1 and 0 < m[1] < ny - 1


def test_pattern_json_contract_roundtrip(small):
    d = json.loads(small.to_json())
    assert d["screen"] == {"width": 800, "height": 600, "pixel_pitch_m": small.pixel_pitch_m}
    assert d["grid"]["nx"] == small.nx and d["grid"]["origin"] == list(small.origin)
    kinds = [f["kind"] for f in d["frames"]]
    assert kinds == ["rotstar"] * 8 + ["identity"] * 10 + ["checkerboard"]  # 6x4 corners: 10 identity frames
    assert [f["band"] for f in d["frames"][:3]] == ["white", "black", "white"]
    assert d["frames"][3]["angle_rad"] == pytest.approx(3 * math.pi / 16)
    ids = d["frames"][8:18]
    assert [f["file"] for f in ids] == [f"identity_{b:02d}.png" for b in range(10)]
    assert [f["index"] for f in ids] == list(range(10)) and all("bit" in f["encodes"] for f in ids)
    assert d["identity"]["frames"] == 10 and len(d["identity"]["codewords"]) == 24
    assert layout_from_dict(d) == small
    # without identity frames: as before them
    plain = json.loads(make_layout(screen=(800, 600), pitch=100, band=24, identity=False).to_json())
    assert [f["kind"] for f in plain["frames"]] == ["rotstar"] * 8 + ["checkerboard"] and "identity" not in plain
    assert not layout_from_dict(plain).identity and layout_from_dict(plain).identity_code is None
    bp = small.board_points()
    assert bp[0, 1].tolist() == pytest.approx([small.spacing_m, 0, 0])
    assert bp[1, 0].tolist() == pytest.approx([0, small.spacing_m, 0])


def test_layout_rejects_odd_or_oversized():
    with pytest.raises(ValueError, match="even"):
        make_layout(pitch=151)
    with pytest.raises(ValueError, match="fit"):
        make_layout(screen=(800, 600), pitch=100, band=24, nx=20)


def test_gamma_roundtrip():
    v = np.linspace(0, 1, 11)
    assert np.allclose(decode_display(encode_display(v)), v, atol=0.01)
    assert encode_display(np.array([0.5]))[0] == round(255 * 0.5 ** (1 / 2.2))


def test_cli_writes_sequence(tmp_path):
    out = tmp_path / "pat"
    r = run_command("rotstar-pattern", "--out", str(out),
                        "--screen", "800x600", "--pitch", "100", "--band", "24")
    assert r.returncode == 0, r.stderr
    assert "--object-spacing" in r.stderr and "--object-width-n 6" in r.stderr and "--object-height-n 4" in r.stderr
    assert "8 rotating-star frames, 10 identity frames, the checkerboard" in r.stderr
    d = json.loads((out / "pattern.json").read_text())
    layout = layout_from_dict(d)
    code = layout.identity_code
    c = layout.corner_screen_xy().astype(int)
    for f in d["frames"]:
        img = cv2.imread(str(out / f["file"]), cv2.IMREAD_UNCHANGED)
        assert img.shape == (600, 800) and img.dtype == np.uint8
        if f["kind"] == "identity":  # every element's square white where its codeword has a 1
            assert np.array_equal(img[c[..., 1] + 5, c[..., 0] + 5] == 255, code.frame_bits(f["index"]) == 1)
    assert sorted(p.name for p in out.glob("identity_*.png")) == [f"identity_{b:02d}.png" for b in range(10)]
    # --no-identity: the sequence of before
    lean = tmp_path / "lean"
    r = run_command("rotstar-pattern", "--out", str(lean),
                        "--screen", "800x600", "--pitch", "100", "--band", "24", "--no-identity")
    assert r.returncode == 0, r.stderr
    assert "no identity frames" in r.stderr and not list(lean.glob("identity_*"))
    assert [f["kind"] for f in json.loads((lean / "pattern.json").read_text())["frames"]] == \
        ["rotstar"] * 8 + ["checkerboard"]
    help_text = run_command("rotstar-pattern", "--help").stdout
    assert "--no-identity" in help_text and "partly out of view" in " ".join(help_text.split())
    # a grid too large for the code: one line, the way out named
    big = run_command("rotstar-pattern", "--out", str(tmp_path / "big"),
                          "--screen", "8000x6000", "--pitch", "40", "--band", "10")
    assert big.returncode == 2 and big.stderr.strip().count("\n") == 0 and "add --no-identity" in big.stderr
    bad = run_command("rotstar-pattern", "--out", str(out), "--pitch", "99")
    assert bad.returncode == 2 and "even" in bad.stderr and len(bad.stderr.strip().splitlines()) == 1


# ---- the paper's whole sequence: phase shifts and the star ---------------------------------
def paper():
    return make_layout(screen=(800, 600), pitch=100, band=24, phase_period=50, star_segments=16)


def test_paper_sequence_frames_and_pattern_json():
    L = paper()
    d = json.loads(L.to_json())
    assert [f["kind"] for f in d["frames"]] == ["rotstar"] * 8 + ["identity"] * 10 + ["phase"] * 8 + \
        ["checkerboard", "star"]
    ph = d["frames"][18:26]
    assert [(f["axis"], f["step"]) for f in ph] == [(a, n) for a in "xy" for n in range(4)]
    assert ph[1]["shift_rad"] == pytest.approx(math.pi / 2) and ph[0]["period_px"] == 50
    assert ph[0]["phase_origin"] == list(L.origin) and d["frames"][-1]["segments"] == 16
    assert layout_from_dict(d) == L
    assert make_layout(screen=(800, 600), pitch=100, band=24).frames() == \
        [f for f in L.frames() if f["kind"] not in ("phase", "star")]  # the default stays as it was
    # the phase at the corners: period 50 = pitch / 2, so every corner has phase 0
    assert np.allclose(np.cos(L.corner_phase()), 1)


@pytest.mark.parametrize("edit, message", [
    (lambda d: d["frames"][20].update(axis="z"), 'frames[20].axis is "z"; must be "x" or "y"'),
    (lambda d: d["frames"][21].update(period_px=2), "frames[21].period_px is 2; must be between 4"),
    (lambda d: d["frames"][21].update(period_px=60), "frames[21]: period_px 60 and phase_origin"),
    (lambda d: d["frames"][21].pop("step"), "frames[21].step missing"),
    (lambda d: d["frames"][21].update(shift_rad=0.1), "frames[21].shift_rad is 0.1; step 3 of 4 is 4.71239"),
    (lambda d: d["frames"][21].update(phase_origin=[1]), "frames[21].phase_origin is [1]; must be [x, y]"),
    (lambda d: d["frames"].pop(21), "the phase frames along x have steps [0, 1, 2]"),
    (lambda d: d["frames"][-1].update(segments=6), "frames[27].segments is 6; must be a multiple of 4"),
    (lambda d: d["frames"][-1].update(cell_px=90), "frames[27].cell_px is 90; the star's cells are the grid's "),
    (lambda d: d["frames"].append(dict(d["frames"][-1], file="star2.png")), "frames[28]: a second star frame"),
])
def test_paper_sequence_pattern_json_checked(edit, message):
    d = json.loads(paper().to_json())
    edit(d)
    with pytest.raises(ValueError, match=re.escape(message)) as e:
        layout_from_dict(d)
    assert "\n" not in str(e.value)


def test_phase_frames_emit_a_sinusoid_through_the_display_gamma(tmp_path):
    """The PNG values are gamma-encoded; the light (decode_display of the PNG) is the sinusoid, and the 4-step
    phase at the corners is the corners' phase"""
    out = tmp_path / "pat"
    r = run_command("rotstar-pattern", "--out", str(out), "--screen", "800x600",
                        "--pitch", "100", "--band", "24", "--paper-sequence")
    assert r.returncode == 0, r.stderr
    assert "8 phase-shift frames (period 100 px), the checkerboard, the 16-segment star" in r.stderr
    L = layout_from_dict(json.loads((out / "pattern.json").read_text()))
    assert L.phase_period == 100 and L.star_segments == 16
    x0, y0, x1, y1 = L.board_extent()
    for axis in "xy":
        png = [cv2.imread(str(out / f"phase_{axis}_{n}.png"), cv2.IMREAD_UNCHANGED) for n in range(4)]
        light = [decode_display(v) for v in png]
        line = (lambda im: im[y0 + 5, x0:x1]) if axis == "x" else (lambda im: im[y0:y1, x0 + 5])
        u = np.arange(x0, x1) if axis == "x" else np.arange(y0, y1)
        o = L.origin[0 if axis == "x" else 1]
        want = [0.5 + 0.5 * np.cos(2 * np.pi * (u + 0.5 - o) / 100 + n * np.pi / 2) for n in range(4)]
        for n in range(4):
            assert np.abs(line(light[n]) - want[n]).max() < 0.005  # 8-bit steps of the gamma-encoded values
            assert np.abs(line(png[n]) / 255.0 - want[n]).max() > 0.1  # the values themselves are not sinusoidal
        phi = np.arctan2(line(light[3]) - line(light[1]), line(light[0]) - line(light[2]))
        assert np.abs(np.angle(np.exp(1j * (phi - 2 * np.pi * (u + 0.5 - o) / 100)))).max() < 0.02
    star = cv2.imread(str(out / "star.png"), cv2.IMREAD_UNCHANGED)
    c = L.corner_screen_xy().astype(int)
    # point symmetric about every corner, and every cell half white
    for (x, y) in c.reshape(-1, 2):
        cell = decode_display(star[y - 50 : y + 50, x - 50 : x + 50])
        assert np.allclose(cell, 1 - cell[::-1], atol=0.01) and abs(cell.mean() - 0.5) < 0.01
        assert np.array_equal(star[y - 40 : y + 40, x - 40 : x + 40], star[y + 39 : y - 41 : -1, x + 39 : x - 41 : -1])
    bad = run_command("rotstar-pattern", "--out", str(tmp_path / "b"),
                          "--star-segments", "12")
    assert bad.returncode == 2 and "need --paper-sequence" in bad.stderr

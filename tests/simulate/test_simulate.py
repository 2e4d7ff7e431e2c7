"""Tests of rotstar_mrcal.simulate: the screen seen by a camera (ground truth)"""

from __future__ import annotations

import json
import math
import os

import cv2
import mrcal
import numpy as np
import pytest
from scipy.special import ndtr

from rotstar_mrcal import dataset as ds
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.simulate import (
    Settings, camera_rays, exact_frames, expose, load_truth, look_at_pose,
    make_screen, pose_ok, preset_model, random_poses, render_irradiance, tilt_angle, true_corners,
    write_dataset,
)
from rotstar_mrcal.optics.blur import TiledPSF, gaussian_kernel, normalize_kernel
from rotstar_mrcal.simulate.poses import board_centre_m, board_extent_m
from rotstar_mrcal.simulate.screen import screen_to_board

LAYOUT = make_layout(screen=(800, 600), pitch=100, band=24)


@pytest.fixture(scope="module")
def frames():
    return exact_frames(LAYOUT)


@pytest.fixture(scope="module")
def checker(frames):
    """A screen showing only the baseline checkerboard (0/1 squares)"""
    return make_screen(frames[-1:], LAYOUT, room=0.02)


@pytest.fixture(scope="module")
def pinhole():
    return preset_model("pinhole-small")


@pytest.fixture(scope="module")
def opencv8():
    """A small distorted camera, 640x400"""
    return mrcal.cameramodel(
        intrinsics=(
            "LENSMODEL_OPENCV8",
            np.array((330.0, 325.0, 322.3, 197.6, -0.06, 0.05, 8e-4, -5e-4, -0.012, 0.0, 0.0, 0.0)),
        ),
        imagersize=np.array((640, 400)),
    )


# Head-on, 10 cm away (a display pixel is 0.3079 camera pixels), offsets that
# put the edges at generic sub-pixel phases
HEADON = np.array((0, 0, 0, -0.0385 + 0.00123, -0.0289 + 0.00077, 0.1))


def project_screen(model, rt, uv):
    return mrcal.project(mrcal.transform_point_rt(rt, screen_to_board(uv, LAYOUT)), *model.intrinsics())


def edge_profiles(img, model, rt, halfwin=3):
    """Measured vs true x of the vertical checkerboard edges, one per image row

    Uses rows through the middle of square rows (away from the corners). The
    measured edge is b + 0.5 - sum of the normalised values over pixels a..b
    (exact for a straight edge crossing a pixel row).
    """
    meas, true = [], []
    for k in range(1, 7):
        ue = 50 + 100 * k  # the screen u of an edge between two squares
        v = np.linspace(50, 550, 4001)
        q = project_screen(model, rt, np.stack((np.full_like(v, ue), v), -1))
        order = np.argsort(q[:, 1])
        for y in range(int(np.ceil(q[:, 1].min())), int(q[:, 1].max())):
            vv = np.interp(y, q[order, 1], v[order])
            if abs((vv - 50) % 100 - 50) > 30:
                continue
            xe = np.interp(y, q[order, 1], q[order, 0])
            a, b = int(xe) - halfwin, int(xe) + halfwin
            row = img[y, a : b + 1]
            lo, hi = row[0], row[-1]
            if abs(hi - lo) < 0.9:
                continue
            meas.append(b + 0.5 - np.sum((row - lo) / (hi - lo)))
            true.append(xe)
    return np.array(meas), np.array(true)


# ---- (a) geometry of the rendered edges ------------------------------------------
def test_headon_pinhole_edges_exact(checker, pinhole):
    img = render_irradiance(checker, pinhole, HEADON, supersample=4, psf=None)[0]
    meas, true = edge_profiles(img, pinhole, HEADON)
    assert len(meas) > 200
    # sub-pixel phases are generic: a half-pixel or a 1/s quantisation error would show
    assert np.ptp(true % 1) > 0.5
    assert np.max(np.abs(meas - true)) < 1e-3
    # horizontal edges too, per column (transpose the problem)
    ve = 50 + 100 * 2
    x0 = project_screen(pinhole, HEADON, np.array((200.0, ve)))
    col = img[int(x0[1]) - 3 : int(x0[1]) + 4, int(x0[0])]  # crosses one horizontal edge
    lo, hi = col[0], col[-1]
    e = int(x0[1]) + 3 + 0.5 - np.sum((col - lo) / (hi - lo))
    assert abs(e - x0[1]) < 1e-3


def test_point_sampling_is_quantised(checker, pinhole):
    """The 'point' sampler lands edges on the 1/s sub-pixel grid; 'area' does not"""
    img = render_irradiance(checker, pinhole, HEADON, supersample=4, psf=None, sampling="point")[0]
    meas, true = edge_profiles(img, pinhole, HEADON)
    err = np.abs(meas - true)
    assert err.max() > 0.05 and err.max() <= 0.125 + 1e-6
    # on the 0/1 checkerboard each pixel is a count of 16 white sub-pixel centres
    (x0, y0), (x1, y1) = project_screen(pinhole, HEADON, np.array(((60.0, 60.0), (740.0, 540.0))))
    inner = img[int(y0) + 1 : int(y1), int(x0) + 1 : int(x1)]
    assert np.allclose(np.round(inner * 16) / 16, inner, atol=1e-6)
    area = render_irradiance(checker, pinhole, HEADON, supersample=4, psf=None)[0]
    inner = area[int(y0) + 1 : int(y1), int(x0) + 1 : int(x1)]
    assert not np.allclose(np.round(inner * 16) / 16, inner, atol=1e-3)


def test_tilted_distorted_edges(checker, opencv8):
    rt = look_at_pose(opencv8, LAYOUT, (300.0, 210.0), 0.13, tilt=math.radians(40), tilt_axis=0.7, roll=0.3)
    img = render_irradiance(checker, opencv8, rt, supersample=4, psf=None)[0]
    meas, true = edge_profiles(img, opencv8, rt)
    assert len(meas) > 100
    assert np.max(np.abs(meas - true)) < 0.015
    assert np.sqrt(np.mean((meas - true) ** 2)) < 0.005


# ---- (b) truth -----------------------------------------------------------------
def test_truth_corners_match_independent_projection(pinhole, opencv8):
    rng = np.random.default_rng(5)
    rts = random_poses(opencv8, LAYOUT, 3, rng)
    for model in (pinhole, opencv8):
        c = true_corners(model, LAYOUT, rts)
        assert c.shape == (3, LAYOUT.ny, LAYOUT.nx, 2)
        for rt, ci in zip(rts, c):
            p = LAYOUT.board_points().reshape(-1, 3)
            lensmodel, intr = model.intrinsics()
            K = np.array(((intr[0], 0, intr[2]), (0, intr[1], intr[3]), (0, 0, 1)))
            dist = intr[4:] if lensmodel == "LENSMODEL_OPENCV8" else np.zeros(5)
            q, _ = cv2.projectPoints(p, rt[:3], rt[3:], K, dist)
            assert np.allclose(ci.reshape(-1, 2), q.reshape(-1, 2), atol=1e-6)
    # mrcal order: corners[j, i]; head-on, i runs along +x, j along +y
    c = true_corners(pinhole, LAYOUT, HEADON)
    assert c[0, 1, 0] > c[0, 0, 0] + 20 and abs(c[0, 1, 1] - c[0, 0, 1]) < 1e-9
    assert c[1, 0, 1] > c[0, 0, 1] + 20


def test_rendered_corner_matches_truth(checker, pinhole):
    """The checkerboard corner in the image is where the truth says"""
    img = render_irradiance(checker, pinhole, HEADON, supersample=4, psf=1.0)[0]
    c = true_corners(pinhole, LAYOUT, HEADON)[1, 2]
    # a checker corner is point-symmetric: img(c + d) = img(c - d)
    ys, xs = np.mgrid[-4:5, -4:5]
    from scipy.ndimage import map_coordinates

    def asym(cc):
        a = map_coordinates(img, [cc[1] + ys, cc[0] + xs], order=3)
        b = map_coordinates(img, [cc[1] - ys, cc[0] - xs], order=3)
        return np.sum((a - b) ** 2)

    # asym grows as the square of the offset: this bounds the error to ~0.01 px
    assert asym(c) < 0.02 * asym(c + (0.05, 0.0))
    assert asym(c) < 0.02 * asym(c + (0.0, 0.05))


# ---- (c) PSF ---------------------------------------------------------------------
def test_psf_delta_and_normalisation(checker, pinhole):
    none = render_irradiance(checker, pinhole, HEADON, psf=None)
    delta = render_irradiance(checker, pinhole, HEADON, psf=np.ones((1, 1)))
    assert np.allclose(none, delta, atol=1e-6)
    k = gaussian_kernel(1.0, 4)
    a = render_irradiance(checker, pinhole, HEADON, psf=k)
    b = render_irradiance(checker, pinhole, HEADON, psf=7.5 * k)
    g = render_irradiance(checker, pinhole, HEADON, psf=1.0)
    assert np.allclose(a, b, atol=1e-6) and np.allclose(a, g, atol=1e-6)
    assert np.max(np.abs(a - none)) > 0.2  # the blur does change the edges
    assert abs(a.sum() - none.sum()) < 1e-4 * none.sum()  # and keeps the light
    assert np.isclose(normalize_kernel(7.5 * k).sum(), 1.0)
    with pytest.raises(ValueError):
        normalize_kernel(np.ones((4, 5)))


def test_gaussian_edge_profile(checker, pinhole):
    """Across a vertical edge: pixel box (x) Gaussian (x) step, in closed form"""
    sigma = 1.5
    img = render_irradiance(checker, pinhole, HEADON, psf=sigma)[0]
    sharp = render_irradiance(checker, pinhole, HEADON, psf=None)[0]
    meas, true = edge_profiles(sharp, pinhole, HEADON)
    ue = 250.0
    xe, ye = project_screen(pinhole, HEADON, np.array((ue, 200.0)))  # mid-square row
    y = int(round(ye))
    x = np.arange(int(xe) - 6, int(xe) + 7)

    def G(z):  # antiderivative of the normal CDF
        return z * ndtr(z) + np.exp(-0.5 * z * z) / math.sqrt(2 * math.pi)

    rising = sharp[y, x[-1]] > sharp[y, x[0]]
    frac = sigma * (G((x + 0.5 - xe) / sigma) - G((x - 0.5 - xe) / sigma))  # bright fraction if rising
    model = frac if rising else 1 - frac
    assert np.max(np.abs(img[y, x] - model)) < 0.004
    # a sigma given in sub-pixels instead of pixels would be 4x narrower:
    wrong = sigma / 4 * (G((x + 0.5 - xe) / (sigma / 4)) - G((x - 0.5 - xe) / (sigma / 4)))
    wrong = wrong if rising else 1 - wrong
    assert np.max(np.abs(img[y, x] - wrong)) > 0.05


def test_psf_is_a_convolution_not_a_correlation(checker, pinhole):
    """A kernel whose only tap is s sub-pixels right of centre moves light 1 pixel right"""
    s = 4
    k = np.zeros((1, 2 * s + 1))
    k[0, -1] = 1
    ref = render_irradiance(checker, pinhole, HEADON, supersample=s, psf=None)[0]
    moved = render_irradiance(checker, pinhole, HEADON, supersample=s, psf=k)[0]
    assert np.allclose(moved[:, 1:], ref[:, :-1], atol=1e-6)
    assert not np.allclose(moved, ref, atol=1e-3)


def test_tiled_psf_matches_fixed_kernel(checker, pinhole):
    k = gaussian_kernel(1.2, 4)
    fixed = render_irradiance(checker, pinhole, HEADON, psf=k)
    tiled = render_irradiance(checker, pinhole, HEADON, psf=TiledPSF(lambda x, y, s: k, tile_px=16, radius_px=5))
    assert np.allclose(fixed, tiled, atol=1e-5)
    # a field-varying PSF: blurrier on the right half
    vary = render_irradiance(
        checker,
        pinhole,
        HEADON,
        psf=TiledPSF(lambda x, y, s: gaussian_kernel(0.5 if x < 320 else 2.0, s), tile_px=16, radius_px=8),
    )
    left = np.s_[:, 60:260, :300]
    right = np.s_[:, 60:260, 340:]
    assert np.abs(np.diff(vary[left], axis=-1)).max() > np.abs(np.diff(vary[right], axis=-1)).max() + 0.1


# ---- (d) exposure -----------------------------------------------------------------
def test_exposure_saturation_dtypes_noise():
    E = np.full((200, 300), 0.5)
    E[:, :100] = 3.0  # overexposed
    img8 = expose(E, gain=0.9, noise=0.0, bits=8)
    img16 = expose(E, gain=0.9, noise=0.0, bits=16)
    assert img8.dtype == np.uint8 and img16.dtype == np.uint16
    assert np.all(img8[:, :100] == 255) and np.all(img16[:, :100] == 65535)
    assert img8[0, 200] == round(0.45 * 255) and img16[0, 200] == round(0.45 * 65535)
    # black level adds
    assert expose(E, gain=0.9, black=0.05, noise=0.0, bits=16)[0, 200] == round(0.5 * 65535)
    # noise sigma on a flat patch, in fractions of full scale
    flat = np.full((400, 400), 0.5)
    for sigma in (0.005, 0.02):
        n = expose(flat, gain=1.0, noise=sigma, bits=16, rng=1) / 65535.0
        assert abs(n.mean() - 0.5) < 3 * sigma / 400
        assert abs(n.std() / sigma - 1) < 0.02
    # saturation clips the noise too
    assert expose(np.full((50, 50), 2.0), gain=1.0, noise=0.05, bits=16, rng=2).min() == 65535
    # shot noise grows with the signal
    dark = expose(np.full((300, 300), 0.1), gain=1.0, noise=0.0, shot=1e-3, bits=16, rng=3) / 65535.0
    bright = expose(np.full((300, 300), 0.8), gain=1.0, noise=0.0, shot=1e-3, bits=16, rng=3) / 65535.0
    assert abs(dark.std() / math.sqrt(1e-3 * 0.1) - 1) < 0.03
    assert abs(bright.std() / math.sqrt(1e-3 * 0.8) - 1) < 0.03


def test_exposure_value_bits_and_seed():
    E = np.linspace(0, 1.2, 100000).reshape(200, 500)
    img = expose(E, gain=1.0, noise=0.0, bits=16, value_bits=10)
    vals = np.unique(img)
    assert len(vals) == 1024 and vals[-1] == 65535 and vals[0] == 0
    assert np.allclose(vals, np.round(np.arange(1024) * 65535 / 1023))
    a = expose(E, noise=0.01, rng=7)
    assert np.array_equal(a, expose(E, noise=0.01, rng=7))
    assert not np.array_equal(a, expose(E, noise=0.01, rng=8))
    with pytest.raises(ValueError):
        expose(E, bits=12)


# ---- (e) dataset + truth ------------------------------------------------------------
def test_write_dataset_loads_and_truth_roundtrips(tmp_path, pinhole, frames):
    rts = random_poses(pinhole, LAYOUT, 2, np.random.default_rng(3))
    seq = str(tmp_path / "seq")
    log = []
    truth = write_dataset(
        seq, LAYOUT, pinhole, rts, Settings(bits=16, value_bits=12, seed=4), frames=frames, progress=log.append
    )
    assert len(log) == 2
    _, layout = ds.read_pattern(seq)
    assert layout == LAYOUT
    assert ds.list_poses(seq) == ["pose000", "pose001"]
    for name in ds.list_poses(seq):
        pose = ds.load_pose(seq, name, layout)
        assert pose.rotstar.shape == (8, 400, 640) and pose.checkerboard.shape == (400, 640)
        assert pose.identity.shape == (10, 400, 640)  # the default sequence: 10 identity frames for 6x4 corners
        assert pose.full_scale == 65535.0
        # the board is bright where the truth says, the room is dark
        c = truth.corners[name]
        # the identity frames, read at the true corners (the centres of the elements), name every element
        xy = np.round(c.reshape(-1, 2)).astype(int)
        index, _ = layout.identity_code.decode(pose.identity[:, xy[:, 1], xy[:, 0]].T)
        assert index.tolist() == list(range(LAYOUT.nx * LAYOUT.ny))
        assert pose.checkerboard.max() > 0.8 * 65535
        assert np.median(pose.rotstar[0][:5, :5]) < 0.06 * 65535
        assert np.all((c >= 0) & (c <= (639, 399)))
    back = load_truth(seq)
    assert back.poses == truth.poses == ["pose000", "pose001"]
    for n in truth.poses:
        assert np.array_equal(back.rt_cam_board[n], truth.rt_cam_board[n])
        assert np.array_equal(back.corners[n], truth.corners[n])
        assert np.allclose(back.corners[n], true_corners(back.model, back.layout, back.rt_cam_board[n]))
    assert np.array_equal(back.model.intrinsics()[1], pinhole.intrinsics()[1])
    assert back.settings["value_bits"] == 12 and back.settings["psf"] == {"kind": "gaussian", "sigma_px": 1.0}
    with open(os.path.join(seq, "truth.json")) as f:
        d = json.load(f)
    assert np.array(d["poses"]["pose001"]["corners"]).shape == (LAYOUT.ny, LAYOUT.nx, 2)


@pytest.mark.slow  # make test-slow: an end-to-end run, left out of make test
def test_dataset_does_not_depend_on_jobs(tmp_path, pinhole, frames):
    rts = random_poses(pinhole, LAYOUT, 2, np.random.default_rng(9))
    a, b = str(tmp_path / "a"), str(tmp_path / "b")
    s = Settings(bits=8, seed=11)
    write_dataset(a, LAYOUT, pinhole, rts, s, frames=frames, jobs=1)
    write_dataset(b, LAYOUT, pinhole, rts, s, frames=frames, jobs=2)
    for name in ("pose000", "pose001"):
        for f in LAYOUT.frames():
            ia = cv2.imread(os.path.join(a, name, f["file"]), cv2.IMREAD_UNCHANGED)
            ib = cv2.imread(os.path.join(b, name, f["file"]), cv2.IMREAD_UNCHANGED)
            assert ia.dtype == np.uint8 and np.array_equal(ia, ib)


# ---- (f) a camera that moves during the sequence --------------------------------------
def test_per_frame_poses(checker, pinhole):
    nf = 4
    screen = make_screen(np.repeat(exact_frames(LAYOUT)[-1:], nf, axis=0), LAYOUT)  # 4 equal frames
    static = render_irradiance(screen, pinhole, HEADON, psf=1.0)
    assert all(np.array_equal(static[0], static[k]) for k in range(nf))
    drift = np.repeat(HEADON[None], nf, axis=0)
    drift[:, 3] += 0.0002 * np.arange(nf)  # 0.2 mm per frame = 0.64 px
    moved = render_irradiance(screen, pinhole, drift, psf=1.0)
    assert np.array_equal(moved[0], static[0])
    for k in range(1, nf):
        assert np.abs(moved[k] - moved[k - 1]).max() > 0.15
        single = render_irradiance(checker, pinhole, drift[k], psf=1.0)[0]
        assert np.allclose(moved[k], single, atol=1e-6)
    # the truth of a moved camera: one set of corners per frame
    c = true_corners(pinhole, LAYOUT, drift)
    assert c.shape == (nf, LAYOUT.ny, LAYOUT.nx, 2)
    assert np.allclose(np.diff(c[..., 0], axis=0), 320 * 0.0002 / 0.1, atol=1e-9)
    with pytest.raises(ValueError):
        render_irradiance(screen, pinhole, drift[:3])


# ---- (g) poses --------------------------------------------------------------------
def test_random_poses_d435():
    model = preset_model("d435")
    layout = make_layout()
    n, max_tilt, margin = 24, 60.0, 20.0
    rts = random_poses(model, layout, n, np.random.default_rng(1), max_tilt_deg=max_tilt, margin_px=margin)
    assert np.array_equal(rts, random_poses(model, layout, n, np.random.default_rng(1), max_tilt_deg=max_tilt, margin_px=margin))
    W, H = model.imagersize()
    (x0, y0), (x1, y1) = board_extent_m(layout)
    outline = np.array([(x, y, 0.0) for x in np.linspace(x0, x1, 9) for y in (y0, y1)]
                       + [(x, y, 0.0) for y in np.linspace(y0, y1, 9) for x in (x0, x1)])
    q = mrcal.project(mrcal.transform_point_rt(rts[:, None], outline), *model.intrinsics())
    assert np.all(q >= margin) and np.all(q[..., 0] <= W - 1 - margin) and np.all(q[..., 1] <= H - 1 - margin)
    tilt = np.degrees(tilt_angle(rts, layout))
    assert np.all(tilt <= max_tilt + 1e-9) and np.sum(tilt > max_tilt / 2) >= n // 4
    # distances within the default range
    d = np.linalg.norm(mrcal.transform_point_rt(rts, board_centre_m(layout)), axis=-1)
    assert np.all((d >= 0.3 - 1e-9) & (d <= 0.6 + 1e-9))
    # centres spread over the imager: every quadrant, and most of the width and height
    c = mrcal.project(mrcal.transform_point_rt(rts, board_centre_m(layout)), *model.intrinsics())
    quad = (c[:, 0] > W / 2) * 2 + (c[:, 1] > H / 2)
    assert len(np.unique(quad)) == 4
    assert np.ptp(c[:, 0]) > 0.55 * W and np.ptp(c[:, 1]) > 0.55 * H
    # the union of the boards reaches close to every image edge
    assert q[..., 0].min() < 0.1 * W and q[..., 0].max() > 0.9 * W
    assert q[..., 1].min() < 0.1 * H and q[..., 1].max() > 0.9 * H


def test_pose_ok_rejects_bad_poses(pinhole):
    good = look_at_pose(pinhole, LAYOUT, (320, 200), 0.2)
    assert pose_ok(pinhole, LAYOUT, good)
    behind = good.copy()
    behind[:3] = mrcal.r_from_R(mrcal.R_from_r(good[:3]) @ np.diag((1.0, -1.0, -1.0)))  # screen turned away
    assert not pose_ok(pinhole, LAYOUT, behind)
    assert not pose_ok(pinhole, LAYOUT, look_at_pose(pinhole, LAYOUT, (320, 200), 0.03))  # too close: off the image
    assert not pose_ok(pinhole, LAYOUT, look_at_pose(pinhole, LAYOUT, (20, 200), 0.2))  # off the left edge


def test_d435_preset_does_not_fold():
    model = preset_model("d435")
    W, H = model.imagersize()
    lensmodel, intr = model.intrinsics()
    assert lensmodel == "LENSMODEL_OPENCV8" and tuple(int(v) for v in (W, H)) == (1280, 800)
    assert 600 < intr[0] < 680 and 600 < intr[1] < 680 and abs(intr[2] - 640) < 20 and abs(intr[3] - 400) < 20
    # the radial map is monotonic out past the image corners
    r = np.linspace(0, 1.5 * math.hypot(W / 2, H / 2) / intr[0], 400)
    p = np.stack((r, np.zeros_like(r), np.ones_like(r)), -1)
    qx = mrcal.project(p, lensmodel, intr)[:, 0]
    assert np.all(np.diff(qx) > 0)
    # and unprojection inverts projection on the image border
    t = np.linspace(0, 1, 50)
    border = np.concatenate([np.stack((t * (W - 1), np.full_like(t, e)), -1) for e in (0, H - 1)]
                            + [np.stack((np.full_like(t, e), t * (H - 1)), -1) for e in (0, W - 1)])
    back = mrcal.project(mrcal.unproject(border, lensmodel, intr), lensmodel, intr)
    assert np.allclose(back, border, atol=1e-6)


def test_ray_cache_reused(pinhole):
    assert camera_rays(pinhole) is camera_rays(preset_model("pinhole-small"))


# ---- CLI ------------------------------------------------------------------------------
def test_cli(tmp_path, capsys):
    from rotstar_mrcal.cli.simulate import main

    pat = tmp_path / "pat"
    ds.write_pattern(str(pat), LAYOUT)
    out = str(tmp_path / "seq")
    rc = main(["--out", out, "--pattern", str(pat), "--camera", "pinhole-small", "--poses", "2",
               "--bits", "8", "--seed", "2", "--noise", "0.02"])
    cap = capsys.readouterr()
    assert rc == 0 and cap.out == out + "\n"
    assert "pose001" in cap.err
    assert ds.list_poses(out) == ["pose000", "pose001"]
    assert ds.load_pose(out, "pose001", LAYOUT).full_scale == 255.0
    t = load_truth(out)
    assert t.settings["camera"] == "pinhole-small" and t.settings["noise"] == 0.02
    assert main(["--out", out, "--pattern", str(pat), "--camera", "pinhole-small", "--poses", "1"]) == 2  # exists
    with pytest.raises(SystemExit) as e:
        main(["--help"])
    assert e.value.code == 0
    assert "--supersample" in capsys.readouterr().out
    # --no-identity: the sequence without identity frames, in the dataset's pattern.json and in every pose
    lean = str(tmp_path / "lean")
    assert main(["--out", lean, "--pattern", str(pat), "--camera", "pinhole-small", "--poses", "1", "--no-identity"]) == 0
    assert "(9 frames each)" in capsys.readouterr().err
    d, layout = ds.read_pattern(lean)
    assert not layout.identity and "identity" not in d and [f["kind"] for f in d["frames"]].count("identity") == 0
    assert sorted(os.listdir(os.path.join(lean, "pose000"))) == sorted(f["file"] for f in layout.frames())
    assert ds.load_pose(lean, "pose000", layout).identity is None


def test_png_frames_decode_display(tmp_path, frames):
    from rotstar_mrcal.pattern.render import encode_display
    from rotstar_mrcal.simulate import png_frames

    for f, img in zip(LAYOUT.frames(), frames):
        cv2.imwrite(str(tmp_path / f["file"]), encode_display(img))
    back = png_frames(str(tmp_path), LAYOUT)
    assert back.shape == frames.shape
    # 8-bit gamma-encoded: exact at 0 and 1, within a display step elsewhere
    assert np.array_equal(back[frames == 1], frames[frames == 1])
    assert np.max(np.abs(back - frames)) < 0.01


def test_cli_paper_sequence(tmp_path, capsys):
    """rotstar-simulate renders every frame of the paper's sequence: at the true corners the 4-step phase of both
    fringes is the corners' phase (0: the period is the pitch), and the star frame is bright and dark around them"""
    from rotstar_mrcal.cli.simulate import main

    paper = make_layout(screen=(800, 600), pitch=100, band=24, phase_period=100, star_segments=16)
    pat = tmp_path / "pat"
    ds.write_pattern(str(pat), paper)
    out = str(tmp_path / "seq")
    assert main(["--out", out, "--pattern", str(pat), "--camera", "pinhole-small", "--poses", "1", "--noise", "0.002"]) == 0
    assert "(28 frames each)" in capsys.readouterr().err
    d, layout = ds.read_pattern(out)
    assert layout == paper
    pose = ds.load_pose(out, "pose000", layout)
    assert pose.phase.shape == (2, 4, 400, 640) and pose.star.shape == (400, 640)
    c = load_truth(out).corners["pose000"].reshape(-1, 2)
    i0, j0 = np.floor(c).astype(int).T
    fx, fy = (c - np.floor(c)).T

    def at(img):  # bilinear at the true corners
        return ((1 - fy) * ((1 - fx) * img[j0, i0] + fx * img[j0, i0 + 1])
                + fy * ((1 - fx) * img[j0 + 1, i0] + fx * img[j0 + 1, i0 + 1]))

    for axis in range(2):
        s = [at(pose.phase[axis, n]) for n in range(4)]
        phi = np.arctan2(s[3] - s[1], s[0] - s[2])
        assert np.abs(phi).max() < 0.15, (axis, phi)  # rad: a twentieth of a pixel's worth of the period
    (x0, y0), (x1, y1) = np.floor(c.min(axis=0)).astype(int), np.ceil(c.max(axis=0)).astype(int)
    assert pose.star[y0:y1, x0:x1].std() > 0.15 * 65535  # black and white wedges over the grid (~20 px cells)
    with pytest.raises(SystemExit):
        main(["--out", str(tmp_path / "x"), "--pattern", str(pat), "--paper-sequence"])

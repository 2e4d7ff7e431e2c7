"""Tests of rotstar_mrcal.peers.checkerboard on synthetic checkerboards with known corners

The test images are drawn here, independently of the package's renderer: a
checkerboard of (nx+1) x (ny+1) unit squares (board coordinates: square
(a, b) covers [a, a+1) x [b, b+1), black where a + b is even, white outside)
mapped into the image by a homography H. Each pixel is the mean of 8 x 8
point samples spread uniformly over it (pixel (u, v) covers
[u-0.5, u+0.5] x [v-0.5, v+0.5], mrcal's convention), then the image is
blurred with a Gaussian of sigma 1 px. The true position of corner (i, j) is
H (i+1, j+1, 1), in mrcal coordinates by construction; test_renderer_convention
checks that.

Bounds were set from measurements (noted next to each) with margin.
"""

from __future__ import annotations

import os
import shutil

import cv2
import numpy as np
import pytest
import scipy.ndimage

from rotstar_mrcal.peers import checkerboard as B

LO, HI = 20.0, 230.0  # black and white levels, 8-bit units
SHAPE = (300, 400)
NX, NY = 9, 6


# ---------------------------------------------------------------------------
# synthetic boards
# ---------------------------------------------------------------------------
def board_homography(shape, nx, ny, tilt=0.2, rot=0.35, scale=None, centre=None):
    """Board (square units) -> image (mrcal pixels): centred, turned, tilted"""
    h, w = shape
    s = scale or 0.7 * min(w / (nx + 1), h / (ny + 1))
    c, sn = np.cos(rot), np.sin(rot)
    T = np.array([[1, 0, -(nx + 1) / 2], [0, 1, -(ny + 1) / 2], [0, 0, 1.0]])
    R = np.array([[c * s, -sn * s, 0], [sn * s, c * s, 0], [0, 0, 1.0]])
    P = np.array([[1, 0, 0], [0, 1, 0], [tilt / max(w, h), 0.15 * tilt / max(w, h), 1.0]])
    cx, cy = centre or ((w - 1) / 2, (h - 1) / 2)
    C = np.array([[1, 0, cx], [0, 1, cy], [0, 0, 1.0]])
    return C @ P @ R @ T


def render_board(shape, H, nx, ny, ss=8, blur=1.0, lo=LO, hi=HI):
    """Area-sampled (ss x ss per pixel), Gaussian-blurred checkerboard image"""
    h, w = shape
    Hi = np.linalg.inv(H)
    t = (np.arange(ss) + 0.5) / ss - 0.5
    xs = (np.arange(w)[:, None] + t).ravel()
    out = np.empty(shape)
    for v0 in range(0, h, 32):  # in bands, to bound the memory
        v1 = min(h, v0 + 32)
        X, Y = np.meshgrid(xs, (np.arange(v0, v1)[:, None] + t).ravel())
        z = Hi[2, 0] * X + Hi[2, 1] * Y + Hi[2, 2]
        bx = (Hi[0, 0] * X + Hi[0, 1] * Y + Hi[0, 2]) / z
        by = (Hi[1, 0] * X + Hi[1, 1] * Y + Hi[1, 2]) / z
        inside = (bx >= 0) & (bx < nx + 1) & (by >= 0) & (by < ny + 1)
        black = inside & ((np.floor(bx) + np.floor(by)) % 2 == 0)
        out[v0:v1] = np.where(black, lo, hi).reshape(v1 - v0, ss, w, ss).mean(axis=(1, 3))
    if blur:
        out = scipy.ndimage.gaussian_filter(out, blur, mode="nearest")
    return out.astype(np.float32)


def board_truth(H, nx, ny):
    """(ny, nx, 2) true corners, mrcal order and convention"""
    j, i = np.mgrid[0:ny, 0:nx]
    p = np.stack((i + 1.0, j + 1.0, np.ones((ny, nx))), axis=-1) @ H.T
    return p[..., :2] / p[..., 2:]


def rms(e):
    return float(np.sqrt(np.mean(np.sum(np.asarray(e) ** 2, axis=-1))))


def bias(e):
    return np.mean(np.asarray(e).reshape(-1, 2), axis=0)


@pytest.fixture(scope="module")
def board():
    """A 9 x 6 board, tilted and turned, noise-free; and a noisy copy"""
    H = board_homography(SHAPE, NX, NY)
    img = render_board(SHAPE, H, NX, NY)
    noisy = img + np.random.default_rng(0).normal(0, 2.0, img.shape).astype(np.float32)
    truth = board_truth(H, NX, NY)
    spacing = np.median(np.linalg.norm(np.diff(truth, axis=1), axis=-1))
    start = truth + np.random.default_rng(1).uniform(-1.5, 1.5, truth.shape)
    return dict(img=img, noisy=noisy, truth=truth, start=start, spacing=spacing)


@pytest.fixture(scope="module")
def aligned():
    """Axis-aligned 7 x 7 board, 20 px squares on pixel boundaries 40, 60, ...

    In mrcal's convention the boundary between pixels 39 and 40 is x = 39.5,
    so the corners are at 39.5 + 20 (i, j): a 0.5 px convention error shows
    up as a 0.5 px offset.
    """
    n = 7
    H = np.array([[20.0, 0, 19.5], [0, 20.0, 19.5], [0, 0, 1]])  # board x = 0 at pixel boundary 19.5
    img = render_board((200, 200), H, n, n, ss=4)
    j, i = np.mgrid[0:n, 0:n]
    truth = np.stack((39.5 + 20 * i, 39.5 + 20 * j), axis=-1).astype(float)
    return dict(img=img, truth=truth, n=n)


# ---------------------------------------------------------------------------
# the test images themselves
# ---------------------------------------------------------------------------
def test_renderer_convention(aligned):
    img, truth = aligned["img"], aligned["truth"]
    np.testing.assert_allclose(board_truth(np.array([[20.0, 0, 19.5], [0, 20.0, 19.5], [0, 0, 1]]), 7, 7), truth)
    sharp = render_board((200, 200), np.array([[20.0, 0, 19.5], [0, 20.0, 19.5], [0, 0, 1]]), 7, 7, ss=4, blur=0)
    # square (0, 0) (black) covers pixels 20..39 exactly, i.e. mrcal x in [19.5, 39.5]
    assert np.all(sharp[20:40, 20:40] == LO) and np.all(sharp[20:40, 40:60] == HI)
    assert np.all(sharp[:20, :] == HI) and np.all(sharp[:, :20] == HI)
    # the blurred image is point-symmetric about every corner, e.g. (39.5, 39.5)
    patch = img[30:50, 30:50]
    np.testing.assert_allclose(patch, patch[::-1, ::-1], atol=1e-3)


# ---------------------------------------------------------------------------
# refiners from initial corners
# ---------------------------------------------------------------------------
def test_opencv_subpix(board):
    c = B.opencv_subpix(board["img"], board["start"])
    e = c - board["truth"]
    assert c.shape == board["start"].shape
    assert rms(e) < 0.05  # measured 0.016
    assert np.all(np.abs(bias(e)) < 0.01)
    e = B.opencv_subpix(board["noisy"], board["start"]) - board["truth"]
    assert rms(e) < 0.07  # measured 0.026


def test_opencv_subpix_border_and_nan():
    img = np.full((50, 60), 100, np.float32)
    starts = np.array([[[3.0, 25.0], [30.0, 25.0]], [[np.nan, 25.0], [30.0, 45.0]]])
    c = B.opencv_subpix(img, starts, win=5)
    assert c.shape == (2, 2, 2)
    assert np.all(np.isnan(c[0, 0])) and np.all(np.isnan(c[1, 0])) and np.all(np.isnan(c[1, 1]))
    assert np.all(np.isfinite(c[0, 1]))


@pytest.mark.parametrize("cone_radius", [None, 2])
def test_saddle_refine(board, cone_radius):
    c = B.saddle_refine(board["img"], board["start"], cone_radius=cone_radius)
    e = c - board["truth"]
    assert c.shape == board["start"].shape
    assert rms(e) < 0.02  # measured 0.0025 (no cone), 0.0023 (cone 2)
    assert np.all(np.abs(bias(e)) < 0.005)
    e = B.saddle_refine(board["noisy"], board["start"], cone_radius=cone_radius) - board["truth"]
    assert rms(e) < 0.05  # measured 0.013 (no cone), 0.011 (cone 2)


def test_saddle_refine_rejects():
    y, x = np.mgrid[0:40, 0:40].astype(float)
    blob = 100 * np.exp(-((x - 20) ** 2 + (y - 20) ** 2) / 30)
    flat = np.zeros((40, 40))
    corner = 128 + 100 * np.tanh(x - 20.2) * np.tanh(y - 19.7)
    assert np.all(np.isnan(B.saddle_refine(blob, [20.0, 20.0], win=4)))  # a peak
    assert np.all(np.isnan(B.saddle_refine(flat, [20.0, 20.0], win=4)))  # nothing
    assert np.all(np.isnan(B.saddle_refine(corner, [3.0, 20.0], win=4)))  # window off the image
    assert np.all(np.isnan(B.saddle_refine(corner, [28.0, 20.0], win=4)))  # would move > win
    np.testing.assert_allclose(B.saddle_refine(corner, [[[21.0, 19.0]]], win=4), [[[20.2, 19.7]]], atol=2e-3)


# ---------------------------------------------------------------------------
# OpenCV chessboard finders
# ---------------------------------------------------------------------------
def test_find_chessboard_sb(board):
    truth, sp = board["truth"], board["spacing"]
    # The brief's flags, NORMALIZE_IMAGE | EXHAUSTIVE | ACCURACY. Histogram
    # equalisation of this two-level image amplifies the noise ~10x and, on
    # the noise-free image, throws one corner 4 px off: SB is then an order of
    # magnitude worse than without it.
    c = B.opencv_find_chessboard(board["img"], NX, NY, 255.0, method="sb")
    assert c is not None and c.shape == (NY, NX, 2)
    assert B.match_to_reference(c, truth, sp / 3) is not None
    e = B.match_to_reference(B.opencv_find_chessboard(board["noisy"], NX, NY, 255.0), truth, sp / 3) - truth
    assert rms(e) < 0.4  # measured 0.23
    assert np.all(np.abs(bias(e)) < 0.06)  # measured (-0.022, -0.015)
    # EXHAUSTIVE | ACCURACY
    flags = cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
    for im in (board["img"], board["noisy"]):
        c = B.opencv_find_chessboard(im, NX, NY, 255.0, method="sb", flags=flags)
        e = B.match_to_reference(c, truth, sp / 3) - truth
        assert rms(e) < 0.08  # measured 0.036 (noise-free), 0.038 (noisy)
        assert np.all(np.abs(bias(e)) < 0.04)  # measured (-0.019, -0.004)


def test_find_chessboard_classic(board):
    c = B.opencv_find_chessboard(board["img"], NX, NY, 255.0, method="classic")
    assert c is not None and c.shape == (NY, NX, 2)
    e = B.match_to_reference(c, board["truth"], board["spacing"] / 3) - board["truth"]
    assert rms(e) < 0.05  # measured 0.016 (cornerSubPix)
    assert np.all(np.abs(bias(e)) < 0.01)


def test_find_chessboard_units_and_absent(board):
    # a 16-bit recording with full_scale 65535 gives the same 8-bit image
    c8 = B.opencv_find_chessboard(board["img"], NX, NY, 255.0)
    c16 = B.opencv_find_chessboard(board["img"] * (65535 / 255), NX, NY, 65535.0)
    np.testing.assert_allclose(c16, c8, atol=1e-6)
    blank = np.full(SHAPE, 128, np.float32)
    assert B.opencv_find_chessboard(blank, NX, NY, 255.0, method="sb") is None
    assert B.opencv_find_chessboard(blank, NX, NY, 255.0, method="classic") is None
    with pytest.raises(ValueError):
        B.opencv_find_chessboard(blank, NX, NY, 255.0, method="harris")


# ---------------------------------------------------------------------------
# pixel convention: corners on pixel boundaries at 39.5 + 20 k
# ---------------------------------------------------------------------------
def test_pixel_convention(aligned):
    img, truth, n = aligned["img"], aligned["truth"], aligned["n"]
    start = np.round(truth)  # 0.5 px off in x and y
    found = {
        "subpix": B.opencv_subpix(img, start),
        "saddle": B.saddle_refine(img, start),
        "sb": B.opencv_find_chessboard(img, n, n, 255.0, method="sb"),
        "classic": B.opencv_find_chessboard(img, n, n, 255.0, method="classic"),
    }
    for name, c in found.items():
        assert c is not None, name
        m = B.match_to_reference(c, truth, 5.0)
        assert m is not None, name
        b = bias(m - truth)
        # measured |bias| <= 1e-4 px, except sb: (0.063, 0.027) (its large
        # filters pull the outermost corners 0.2 px outward on 20 px squares)
        tol = 0.1 if name == "sb" else 0.01
        assert np.all(np.abs(b) < tol), (name, b)


# ---------------------------------------------------------------------------
# relabelling
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("n", [(NX, NY), (7, 7)])
def test_match_to_reference(board, n):
    nx, ny = n
    truth = board_truth(board_homography(SHAPE, nx, ny), nx, ny)
    noisy = truth + np.random.default_rng(2).normal(0, 0.1, truth.shape)
    names = []
    for name, g in B.relabelled_boards(noisy):
        if g.shape != truth.shape:
            continue
        m, got = B.match_to_reference(g, truth, 1.0, return_name=True)
        np.testing.assert_array_equal(m, noisy)
        names.append(name)
        # every relabelling is its own inverse except the quarter turns
        quarter = {"transpose+flip_x": "transpose+flip_y", "transpose+flip_y": "transpose+flip_x"}
        assert got == quarter.get(name, name)
    assert len(names) == (8 if nx == ny else 4)
    # relabelling a grid found as OpenCV would (rot180) with NaNs in both
    det = np.array(noisy[::-1, ::-1])
    det[0, 0] = np.nan
    ref = np.array(truth)
    ref[1, 2] = np.nan
    m = B.match_to_reference(det, ref, 1.0)
    assert np.isnan(m[-1, -1]).all() and np.isfinite(m[1, 2]).all()


def test_match_to_reference_refuses(board):
    truth = board["truth"]
    sp = board["spacing"]
    assert B.match_to_reference(truth + 0.3 * sp, truth, 0.2 * sp) is None  # too far
    shifted = np.concatenate((truth[:, 1:], 2 * truth[:, -1:] - truth[:, -2:-1]), axis=1)
    assert B.match_to_reference(shifted, truth, sp / 3) is None  # off by one column
    assert B.match_to_reference(truth[:, :-1], truth, sp / 3) is None  # wrong size
    assert B.match_to_reference(np.full_like(truth, np.nan), truth, sp / 3) is None  # nothing found
    assert B.match_to_reference(None, truth, sp / 3) is None  # a finder's None passes through
    # a 9 x 6 grid can be relabelled by a transpose only to a 6 x 9 reference
    m, name = B.match_to_reference(truth.swapaxes(0, 1), truth, 1e-9, return_name=True)
    assert name == "transpose" and np.array_equal(m, truth)


# ---------------------------------------------------------------------------
# averaging
# ---------------------------------------------------------------------------
def test_average_frames(board):
    clean = board["img"]
    rng = np.random.default_rng(3)
    sigma, N = 3.0, 16
    frames = [clean + rng.normal(0, sigma, clean.shape).astype(np.float32) for _ in range(N)]
    avg = B.average_frames(frames)
    assert avg.shape == clean.shape and avg.dtype == np.float32
    s1 = np.std(frames[0] - clean)
    sN = np.std(avg - clean)
    assert s1 / sN == pytest.approx(np.sqrt(N), rel=0.05)
    np.testing.assert_allclose(B.average_frames(np.stack(frames)), avg)
    with pytest.raises(ValueError):
        B.average_frames([])


# ---------------------------------------------------------------------------
# mrgingham
# ---------------------------------------------------------------------------
def test_mrgingham_missing(monkeypatch):
    monkeypatch.setattr(B.shutil, "which", lambda name: None)
    with pytest.raises(B.MrginghamNotInstalled, match="mrgingham"):
        B.mrgingham_detect(["x.png"], 7)


def test_mrgingham_parse():
    text = "## generated\n# filename x y level\nnone.png - - -\n" + "".join(
        f"a b.png {x}.25 {y}.5 0\n" for y in range(3) for x in range(3)
    ) + "short.png 1 2 0\n"
    out = B._parse_mrgingham_vnlog(text, 3)
    assert out["none.png"] is None and out["short.png"] is None
    assert out["a b.png"].shape == (3, 3, 2)
    np.testing.assert_array_equal(out["a b.png"][2, 1], [1.25, 2.5])


@pytest.mark.skipif(shutil.which("mrgingham") is None, reason="mrgingham is not installed (Debian package mrgingham)")
def test_mrgingham(tmp_path, aligned):
    n = 7
    H = board_homography(SHAPE, n, n, tilt=0.3, rot=0.2)
    truth = board_truth(H, n, n)
    img = render_board(SHAPE, H, n, n)
    img = img + np.random.default_rng(4).normal(0, 1.0, img.shape)
    paths = [str(tmp_path / "tilted[1].png"), str(tmp_path / "aligned.png"), str(tmp_path / "blank.png")]
    cv2.imwrite(paths[0], np.clip(np.round(img), 0, 255).astype(np.uint8))
    cv2.imwrite(paths[1], np.round(aligned["img"]).astype(np.uint8))
    cv2.imwrite(paths[2], np.full((100, 100), 128, np.uint8))
    out = B.mrgingham_detect(paths, n, jobs=2)
    assert set(out) == set(paths)
    assert out[paths[2]] is None
    c = out[paths[0]]
    assert c is not None and c.shape == (n, n, 2)
    m = B.match_to_reference(c, truth, 2.0)
    assert m is not None
    assert rms(m - truth) < 0.3  # measured 0.10
    assert np.all(np.abs(bias(m - truth)) < 0.05)
    # pixel convention: corners on pixel boundaries at 39.5 + 20 k
    m = B.match_to_reference(out[paths[1]], aligned["truth"], 2.0)
    assert np.all(np.abs(bias(m - aligned["truth"])) < 0.02)  # measured 0.0003 (RMS 0.034)
    with pytest.raises(FileNotFoundError):
        B.mrgingham_detect([os.fspath(tmp_path / "missing.png")], n)

"""Tests of rotstar_mrcal.optics: Seidel wavefront PSFs and the Cramer-Rao bound"""

from __future__ import annotations

import math

import numpy as np
import pytest

from rotstar_mrcal.optics import (
    Optics, Seidel, SeidelPSF, asymmetry, centroid_px, closed_form_corner_bound, crlb_rms,
    fisher_information, gaussian_psf, radial_psf, second_moment_px, wavefront_psf,
)
from rotstar_mrcal.optics.wavefront import wavefront
from rotstar_mrcal.optics.crlb import crlb_cov
from rotstar_mrcal.optics.blur import KernelPSF, SmoothPSF
from rotstar_mrcal.synth.bound import pattern_bounds

OPTICS = Optics()  # F/2, 3 um, 550 nm: lambda N / p = 0.3667 px
K = OPTICS.lambda_fnum_px

SYMMETRIC = {
    "focus": Seidel(focus=2.0),
    "spherical": Seidel(spherical=1.5),
    "astigmatism": Seidel(astigmatism=3.0, astigmatism_angle=0.4),
    "mixed": Seidel(focus=-1.0, spherical=1.0, astigmatism=0.7, astigmatism_angle=1.1),
}


# ---- the wavefront --------------------------------------------------------
def test_wavefront_standard_terms():
    """Wyant and Creath's assignment: spherical rho^4, astigmatism rho^2 cos^2 (not the paper's swap)"""
    rho, theta = 0.5, 0.0
    assert wavefront(Seidel(spherical=1.0), rho, theta) == pytest.approx(rho**4)
    assert wavefront(Seidel(astigmatism=1.0), rho, theta) == pytest.approx(rho**2)
    assert wavefront(Seidel(astigmatism=1.0), rho, math.pi / 2) == pytest.approx(0.0)
    assert wavefront(Seidel(coma=1.0), rho, math.pi) == pytest.approx(-(rho**3))
    assert wavefront(Seidel(focus=1.0), rho, 2.0) == pytest.approx(rho**2)
    # rotationally symmetric spherical term: independent of theta
    assert np.ptp(wavefront(Seidel(spherical=3.0), 0.7, np.linspace(0, 6, 9))) == pytest.approx(0.0)


# ---- the PSF ---------------------------------------------------------------
@pytest.mark.parametrize("s", [2, 4, 8])
@pytest.mark.parametrize("seidel", [Seidel(), Seidel(coma=4.0), Seidel(spherical=1.5), Seidel(focus=2, tilt=0.5)])
def test_psf_unit_sum_odd_centred(seidel, s):
    k = wavefront_psf(seidel, OPTICS, s)
    assert k.ndim == 2 and k.shape[0] == k.shape[1] and k.shape[0] % 2 == 1
    assert k.sum() == pytest.approx(1.0, abs=1e-12)
    assert np.all(k >= 0)


@pytest.mark.parametrize("name", sorted(SYMMETRIC))
def test_symmetric_aberration_point_symmetric_psf(name):
    k = wavefront_psf(SYMMETRIC[name], OPTICS, 4)
    assert asymmetry(k) < 1e-9
    assert np.allclose(k, k[::-1, ::-1], atol=1e-12 * k.max())
    assert np.abs(centroid_px(k, 4)).max() < 1e-9


@pytest.mark.parametrize("waves", [1.0, 4.0])
def test_coma_is_not_point_symmetric(waves):
    k = wavefront_psf(Seidel(coma=waves), OPTICS, 4)
    assert asymmetry(k) > 0.2
    assert centroid_px(k, 4)[0] > 0.3 * waves  # light moves toward the tail


def test_coma_comet_geometry():
    """W_coma = 4: head at the ideal image point, tail along +x about 3 * 2 k W = 8.8 px long"""
    s = 8
    k = wavefront_psf(Seidel(coma=4.0), OPTICS, s)
    h = k.shape[0] // 2
    r, c = np.unravel_index(np.argmax(k), k.shape)
    assert abs(r - h) / s < 0.1 and -0.1 < (c - h) / s < 1.0  # the bright head
    x = (np.arange(k.shape[1]) - h) / s
    prof = k.sum(axis=0)
    assert prof[x < -1.0].sum() < 0.01  # nothing ahead of the head
    assert prof[x > 3 * 2 * K * 4 + 1.0].sum() < 0.01  # the tail ends where geometric optics says
    assert prof[x > 3.0].sum() > 0.2  # and it is long
    # mirror symmetric about the tail's axis (coma_angle = 0)
    assert np.allclose(k, k[::-1, :], atol=1e-12)


@pytest.mark.parametrize("angle", [0.0, 0.7, 2.5, -1.9])
def test_coma_direction_parameter(angle):
    c = centroid_px(wavefront_psf(Seidel(coma=2.0, coma_angle=angle), OPTICS, 4), 4)
    assert math.atan2(c[1], c[0]) == pytest.approx(angle, abs=0.02)


def test_psf_scale_tilt_moves_by_2k_per_wave():
    """The pixel scale of the FFT sampling: a tilt of t waves moves the PSF by 2 t lambda N / p px"""
    for t in (0.5, 2.0):
        c = centroid_px(wavefront_psf(Seidel(tilt=t, tilt_angle=math.pi / 2), OPTICS, 8, tail=1e-4), 8)
        assert c[1] == pytest.approx(2 * K * t, rel=0.03)
        assert abs(c[0]) < 1e-6


def test_airy_core_width():
    """The aberration-free PSF is the Airy pattern: FWHM 1.03 lambda N"""
    s = 16
    k = wavefront_psf(Seidel(), OPTICS, s)
    h = k.shape[0] // 2
    prof = k[h] / k[h, h]
    x = (np.arange(k.shape[1]) - h) / s
    right = np.interp(0.5, prof[h:][::-1], x[h:][::-1])
    assert 2 * right == pytest.approx(1.03 * K, rel=0.12)  # sub-pixel binning widens it a little


def test_gaussian_psf_moments():
    k = gaussian_psf(1.5, 4)
    M = second_moment_px(k, 4)
    assert k.sum() == pytest.approx(1.0)
    assert M[0, 0] == pytest.approx(1.5**2 + 1 / (12 * 16), rel=1e-3)
    assert abs(M[0, 1]) < 1e-12 and asymmetry(k) < 1e-12


def test_seidel_psf_plugs_into_the_renderer_interface():
    """SeidelPSF behaves like the foundation's KernelPSF of the same kernel (renderer's psf=)"""
    rng = np.random.default_rng(0)
    sub = rng.random((2, 96, 96)).astype(np.float32)
    psf = SeidelPSF(Seidel(coma=2.0))
    ref = KernelPSF(wavefront_psf(Seidel(coma=2.0), OPTICS, 4))
    assert psf.radius_for(4) == ref.radius_for(4)
    assert np.allclose(psf(sub, (0, 0), 4), ref(sub, (0, 0), 4))
    assert psf.describe()["kind"] == "seidel"


@pytest.mark.parametrize("s", [2, 3, 4])
@pytest.mark.parametrize("coma,angle", [(0.5, 0.3), (1.5, 2.0), (2.5, -1.0)])
def test_zero_centroid_puts_the_light_on_the_chief_ray(coma, angle, s):
    """tilt = -coma centres the whole PSF; the crop of coma's tail moves it 0.01-0.02 px, differently per s"""
    seidel = Seidel(coma=coma, tilt=-coma, focus=0.2, coma_angle=angle, tilt_angle=angle)
    assert np.hypot(*centroid_px(wavefront_psf(seidel, OPTICS, s), s)) > 0.002  # what the crop leaves
    k = wavefront_psf(seidel, OPTICS, s, zero_centroid=True)
    assert np.hypot(*centroid_px(k, s)) < 5e-4
    assert np.allclose(second_moment_px(k, s), second_moment_px(wavefront_psf(seidel, OPTICS, s), s), rtol=0.02, atol=2e-3)


def test_lens_psf_kernels_have_their_centroid_on_the_chief_ray():
    from rotstar_mrcal.optics.psf import LensPSF

    lens = LensPSF(Seidel(coma=1.5, focus=0.3), (1280, 800))
    for x, y in ((1100.0, 650.0), (100.0, 90.0), (700.0, 450.0)):
        for s in (2, 4):
            assert np.hypot(*centroid_px(lens.local_kernel(x, y, s), s)) < 1e-3
    assert not LensPSF(Seidel(coma=1.5), (1280, 800), tilt=0.0).centred  # a given tilt is the lens's own


def test_radial_psf_points_coma_away_from_the_centre():
    """SmoothPSF with per-node orientation: the blurred dot's centroid moves radially outward"""
    s, tile = 4, 32
    H = W = 192
    sub = np.zeros((1, H * s, W * s), np.float32)
    centre = (96.0, 96.0)
    pts = [(40, 96), (160, 96), (96, 40), (150, 150)]
    yy, xx = (np.mgrid[0 : H * s, 0 : W * s] + 0.5) / s - 0.5
    at = []
    for x, y in pts:
        r, c = int((y + 0.5) * s), int((x + 0.5) * s)
        sub[0, r, c] = 1.0
        at.append((xx[r, c], yy[r, c]))
    out = radial_psf(Seidel(coma=3.0), centre, OPTICS, node_px=tile)(sub, (0, 0), s)[0]
    for x, y in at:
        m = (abs(xx - x) < 12) & (abs(yy - y) < 12)
        w = out * m
        shift = np.array(((w * xx).sum(), (w * yy).sum())) / w.sum() - (x, y)
        u = (np.array((x, y)) - centre) / np.hypot(x - centre[0], y - centre[1])
        assert np.dot(shift, u) > 1.0  # > 1 px outward
        assert abs(u[0] * shift[1] - u[1] * shift[0]) < 0.2  # and not sideways


# ---- the Cramer-Rao bound -------------------------------------------------
def test_fisher_adds_and_scales():
    rng = np.random.default_rng(1)
    g1, g2 = rng.normal(size=(50, 2)), rng.normal(size=(30, 2))
    F1, F2 = fisher_information(g1, 2.0), fisher_information(g2, 2.0)
    assert np.allclose(fisher_information(np.concatenate((g1, g2)), 2.0), F1 + F2)
    assert np.allclose(fisher_information(g1, 1.0), 4 * F1)
    assert crlb_rms(4 * F1) == pytest.approx(crlb_rms(F1) / 2)
    assert np.allclose(crlb_cov(F1) @ F1, np.eye(2))
    assert crlb_rms(np.zeros((2, 2))) == np.inf


@pytest.mark.parametrize("sigma_b", [1.0, 2.0])
def test_bound_matches_closed_form_for_gaussian_corner(sigma_b):
    """Pixel-integrated gradients of the blurred corner vs sigma_n / C sqrt(sqrt(pi) sigma_b / W)"""
    b = pattern_bounds(gaussian_psf(sigma_b, 8), 8, window=10, contrast=200.0, sigma_n=2.0,
                       patterns=("checkerboard",))["checkerboard"]
    cf = closed_form_corner_bound(2.0, 200.0, sigma_b, 10)
    assert b == pytest.approx(cf, rel=0.2)
    assert b >= cf * 0.98  # pixel integration and the finite window only lose information


def test_bound_per_pattern_reproduces_the_notes():
    """refinement.md section 7: rotated frames beat one frame; the 16-star loses under heavy blur"""
    sharp = pattern_bounds(gaussian_psf(0.5, 8), 8)
    blurred = pattern_bounds(gaussian_psf(3.0, 8), 8)
    assert sharp["star16"] < sharp["checkerboard"]
    assert blurred["star16"] > blurred["checkerboard"]
    for b in (sharp, blurred):
        # 8 rotated frames: about sqrt(8) less than one checkerboard frame
        assert b["checkerboard"] / b["rotstar"] == pytest.approx(math.sqrt(8), rel=0.15)
    assert blurred["rotstar"] == pytest.approx(0.0029, rel=0.15)  # the notes' number


def test_bound_is_a_floor_for_the_symmetric_refiner():
    """Monte Carlo: the refiner's RMS error over noisy repeats is >= the bound, and within 2x of it"""
    from rotstar_mrcal.detect.refine import symmetric_refine
    from rotstar_mrcal.synth.patterns import Star
    from rotstar_mrcal.synth.imaging import ViewRenderer

    s, T, W, C, sig = 4, 30, 10, 200.0, 6.0
    apex = np.array((15.3, 14.7))
    img, grad = ViewRenderer(gaussian_psf(1.5, s), s, T)([Star.regular(4, 0.3)], apex)
    c = np.arange(T)
    win = (abs(c[None, :] - apex[0]) <= W) & (abs(c[:, None] - apex[1]) <= W)
    bound = crlb_rms(fisher_information((C * grad[0][win]).reshape(-1, 2), sig))
    R = 150
    rng = np.random.default_rng(3)
    mosaic = np.tile(28 + C * img[0], (1, R)) + rng.normal(0, sig, (T, T * R))
    offs = np.stack((np.arange(R) * T, np.zeros(R)), axis=-1)
    q = symmetric_refine(mosaic[None], apex + offs + rng.uniform(-1, 1, (R, 2)), window=W).corners - offs
    rms = np.sqrt(np.mean(np.sum((q - apex) ** 2, axis=-1)))
    assert rms >= 0.85 * bound  # a lower bound (0.85: Monte Carlo error of 150 repeats)
    assert rms <= 2.0 * bound


def test_smooth_psf_is_continuous_exact_and_independent_of_the_region():
    """SmoothPSF: a point's light has the blended kernel's centroid (continuous in the point, 0 for the lens's
    tilt-compensated coma), its camera pixels are the reference's block means, and they do not depend on where
    the rendered region starts (TiledPSF's tiles did)"""
    s, N = 4, 16
    psf = radial_psf(Seidel(coma=1.5, tilt=-1.5), (40.0, 40.0), OPTICS, node_px=N, field_radius_px=60.0)
    for x in (50.0, 55.3, 61.9):  # across a node at 63.5: the centroid stays put (tilt + coma = 0)
        assert np.abs(centroid_px(psf.local_kernel(x, 45.0, s), s)).max() < 0.02
    sub = np.zeros((1, 32 * s, 40 * s), np.float32)
    sub[0, 12 * s + 1, 14 * s + 2] = 1.0  # the light of image point (54.125, 41.875), region at (40, 30)
    yy, xx = np.mgrid[0:32, 0:40]
    cs = []
    for dx, dy in ((0, 0), (-3, -5)):  # the same light in a region that starts elsewhere
        moved = np.roll(sub, (-4 * dy, -4 * dx), axis=(1, 2))
        px = psf.pixels(moved, (40 + dx, 30 + dy), s)
        assert np.abs(px - psf(moved, (40 + dx, 30 + dy), s).reshape(1, 32, s, 40, s).mean(axis=(2, 4))).max() < 1e-6
        cs.append(((px[0] * (xx + 40 + dx)).sum() / px.sum(), (px[0] * (yy + 30 + dy)).sum() / px.sum()))
    assert np.allclose(cs[0], cs[1], atol=1e-5)
    full = psf(sub, (40, 30), s)[0]  # the supersampled light's centroid: the point's (the pixels' is not quite)
    ys, xs = 30 - 0.5 + (np.arange(32 * s) + 0.5) / s, 40 - 0.5 + (np.arange(40 * s) + 0.5) / s
    c = ((full.sum(axis=0) * xs).sum(), (full.sum(axis=1) * ys).sum())
    assert abs(full.sum() - 1) < 1e-5 and np.allclose(c, (54.125, 41.875), atol=0.02)

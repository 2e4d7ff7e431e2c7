"""Bias by simulation (detect/psfbias.py): the symmetric fit's offset under coma, found and taken off"""

import copy

import numpy as np
import pytest

from rotstar_mrcal.detect import psfbias
from rotstar_mrcal.detect.pipeline import PoseCorners
from rotstar_mrcal.detect.psfbias import (bias_correct, coma_samples, render_star, render_star_fft, seidel_kernel,
                                         simulated_bias, star_normals)
from rotstar_mrcal.detect.refine import lowpass_for, prefilter, symmetric_refine
from rotstar_mrcal.detect.pipeline import correct_with_dataset
from rotstar_mrcal.optics.psf import centroid_px, gaussian_psf
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.peers.registry import REFINERS, Found, pooled

ANGLES = np.arange(8) * np.pi / 16


def star_mosaic(kernel, jac, n=4, half=14, s=4, seed=0):
    """(frames (8, H, W) of n x n local stars through kernel (by FFT), their centres (n*n, 2)); random phases"""
    frac = np.random.default_rng(seed).uniform(-0.5, 0.5, (n * n, 2))
    normals = star_normals(np.broadcast_to(jac, (n * n, 2, 2)), ANGLES)
    p = render_star_fft(np.broadcast_to(kernel, (n * n,) + kernel.shape), s, normals, frac, half)
    P = 2 * half + 1
    frames = np.zeros((8, n * P, n * P), np.float32)
    centres = np.empty((n * n, 2))
    for k in range(n * n):
        r, c = divmod(k, n)
        frames[:, r * P:(r + 1) * P, c * P:(c + 1) * P] = p[k]
        centres[k] = (c * P + half + frac[k, 0], r * P + half + frac[k, 1])
    return frames, centres


def test_a_symmetric_psf_leaves_no_bias():
    jac = np.array([[[1.0, 0.3], [-0.1, 0.8]]] * 3)
    g = gaussian_psf(1.2, 4)
    b = simulated_bias(np.broadcast_to(g, (3,) + g.shape), 4, star_normals(jac, ANGLES),
                       np.array([[5.2, 7.9], [3.0, 3.5], [0.4, 0.1]]), np.array([4.0, 6.0, 8.0]), 1.0)
    assert np.abs(b).max() < 0.004, b


def test_coma_bias_points_against_the_tail_and_is_taken_off():
    kernel = seidel_kernel(1.5, 0.0, np.radians(30))
    assert np.linalg.norm(centroid_px(kernel, 4)) < 0.03  # the kernel's centre is where its light's centroid is
    jac = np.array([[1.0, 0.2], [0.1, 0.9]])
    frames, truth = star_mosaic(kernel, jac)
    w = np.full(len(truth), 6.0)
    q = symmetric_refine(prefilter(frames, lowpass_for(w)), truth + 0.2, w).corners
    e0 = q - truth
    assert np.linalg.norm(e0, axis=1).min() > 0.04  # the symmetric fit is off under 1.5 waves of coma ...
    assert (e0 @ np.array([np.cos(np.radians(30)), np.sin(np.radians(30))]) < 0).all()  # ... toward the head
    e = bias_correct(frames, q, w) - truth  # the edges' normals measured (the dataset test gives the Jacobians)
    assert np.sqrt((e ** 2).sum(1).mean()) < 0.25 * np.sqrt((e0 ** 2).sum(1).mean()), (e, e0)
    e = REFINERS["psf-sim"].refine(frames, truth + 0.2, w) - truth
    assert np.sqrt((e ** 2).sum(1).mean()) < 0.25 * np.sqrt((e0 ** 2).sum(1).mean()), (e, e0)


def test_too_few_corners_are_left_as_they_are():
    q = np.array([[10.0, 10.0], [np.nan, np.nan]])
    out = bias_correct(np.zeros((8, 30, 30), np.float32), q, np.array([6.0, 6.0]))
    assert np.array_equal(out, q, equal_nan=True)


def test_the_binned_rendering_is_the_fft_one(monkeypatch):
    monkeypatch.setattr(psfbias, "TAP_FLOOR", 1e-6)  # every tap: the binning alone (the default drops the far tail)

    rng = np.random.default_rng(1)
    normals = star_normals(np.eye(2) + rng.normal(0, 0.2, (3, 2, 2)), ANGLES)
    k = psfbias._padded([seidel_kernel(c, 0.0, 0.0) for c in (0.0, 1.0, 2.0)])
    frac = rng.uniform(-0.5, 0.5, (3, 2))
    a, b = render_star(k, 4, normals, frac, 10), render_star_fft(k, 4, normals, frac, 10)
    assert np.abs(a - b).mean() < 2e-3 and np.abs(a - b).max() < 0.08


def test_a_dataset_lends_its_coma_to_a_pose_that_shows_none():
    """pipeline.correct_with_dataset (and registry.pooled): the pooled coma corrects a pose whose own edges measured nothing"""
    frames, truth = star_mosaic(seidel_kernel(1.5, 0.0, np.radians(30)), np.array([[1.0, 0.2], [0.1, 0.9]]))
    w = np.full(len(truth), 6.0)
    q = symmetric_refine(prefilter(frames, lowpass_for(w)), truth + 0.2, w).corners
    layout = make_layout(screen=(800, 600), pitch=30, band=4)  # (the Jacobians' scale does not matter)

    def pose(samples):
        return PoseCorners(q.reshape(4, 4, 2).copy(), window=w.reshape(4, 4), prefilter_px=lowpass_for(w),
                           samples=samples, correction=np.zeros((4, 4, 2)))

    seen, blind = pose(coma_samples(frames, q, w)), pose((np.zeros((0, 2)), np.zeros((0, 2))))
    e0 = np.sqrt(((q - truth) ** 2).sum(1).mean())
    # registry.pooled (the demo's and rotstar-crossval's path) on copies; then the same poses here
    found = [Found(p.corners.copy(), pose=copy.deepcopy(p)) for p in (seen, blind)] + [Found(None, why="no board")]
    got = pooled("rotstar-psf-sim", layout, found)
    correct_with_dataset(layout, [seen, blind], REFINERS["psf-sim"])
    for p, f in zip((seen, blind), got):
        e = p.corners.reshape(-1, 2) - truth
        assert np.sqrt((e ** 2).sum(1).mean()) < 0.25 * e0
        assert np.allclose(p.correction.reshape(-1, 2), p.corners.reshape(-1, 2) - q)
        assert np.array_equal(f.corners, p.corners)
    assert got[2].corners is None and pooled("rotstar", layout, found) is found  # a method that does not pool


def test_each_corner_s_sub_pixel_phase_is_simulated(monkeypatch):
    """PHASE: every corner on its node's star at its own phase takes off what a smooth field of 12 nodes cannot"""
    monkeypatch.setattr(psfbias, "TAP_FLOOR", 1e-6)  # (the stars below are rendered with every tap)
    angle = np.radians(30)
    jac = np.array([[1.0, 0.2], [0.1, 0.9]])
    frames, truth = star_mosaic(seidel_kernel(1.5, 0.0, angle), jac, n=5, seed=3)
    w = np.full(len(truth), 6.0)
    # (started where the simulation starts its fit: the fit stops within about 0.001 px of its optimum, and where
    # depends on where it started)
    q = symmetric_refine(prefilter(frames, lowpass_for(w)), truth, w).corners
    coma = (truth, np.tile(1.5 * np.array([np.cos(angle), np.sin(angle)]), (len(truth), 1)))  # the true coma
    opts = dict(jac=np.broadcast_to(jac, (len(q), 2, 2)), angles=ANGLES, samples=coma)
    old = bias_correct(frames, q, w, phase=False, **opts) - truth
    new = bias_correct(frames, q, w, phase=True, **opts) - truth
    rms_old, rms_new = (float(np.sqrt((e ** 2).sum(1).mean())) for e in (old, new))
    assert rms_old > 0.001 and rms_new < 0.5 * rms_old, (rms_old, rms_new)


@pytest.mark.parametrize("reach", [2.0])
def test_the_shipped_coma_tables_are_what_the_code_computes(reach):
    """detect/coma_tables.py (scripts/coma_tables.py) is stale once the moments' reading or the kernels change

    (to 1e-5 of the table's range: FFTs on another machine move the last digits by some 1e-6 relative)"""
    from rotstar_mrcal.detect import coma_tables
    from rotstar_mrcal.optics.psf import Optics

    assert reach in coma_tables.TABLES
    want = psfbias.computed_coma_table(reach, Optics())
    assert np.allclose(psfbias.coma_table(reach, Optics()), want, rtol=0, atol=1e-5 * float(np.ptp(want))), \
        "run scripts/coma_tables.py"


def test_the_coma_read_at_any_phase_and_direction_is_the_lens_s_on_average():
    """coma_table averages over directions and phases: corners at random ones read 0.95-0.97 of the coma on
    average (a table read at one phase and direction, along a pixel row: 0.86)"""
    from rotstar_mrcal.detect.edgespread import local_psf
    from rotstar_mrcal.detect.psfbias import REACH_PER_WINDOW, local_coma

    rng = np.random.default_rng(7)
    n, reach, coma = 48, 3.0, 1.0
    w = reach / REACH_PER_WINDOW
    half = int(np.ceil(w)) + 4
    P = 2 * half + 1
    ang = rng.uniform(-np.pi, np.pi, n)
    frac = rng.uniform(-0.5, 0.5, (n, 2))
    k = psfbias._padded([seidel_kernel(coma, 0.0, a) for a in ang])
    stars = render_star(k, 4, star_normals(np.broadcast_to(np.eye(2), (n, 2, 2)), ANGLES), frac, half)
    at = np.stack((np.arange(n) * P + half + frac[:, 0], half + frac[:, 1]), -1)
    e = local_psf(np.concatenate(list(stars), axis=-1), at, w, reach=reach)[1]
    got = local_coma(e.coma, reach)
    assert 0.93 < got.mean() / coma < 1.05, got.mean()
    off = np.degrees(np.abs(np.angle(np.exp(1j * (e.coma_angle - ang)))))
    assert np.median(off) < 5, off

"""The symmetric refinement's batch forms: per-frame shifts and each frame alone"""

import numpy as np
import pytest

from rotstar_mrcal.detect.refine import refine_each_frame, symmetric_refine, symmetric_step

CORNER = np.array([29.6, 30.3])  # x, y


def star_frames(shifts=None, size=60, n=8):
    """The refine doctest's rotating corner, frame k centred at CORNER + shifts[k]"""
    shifts = np.zeros((n, 2)) if shifts is None else shifts
    yy, xx = np.mgrid[0:size, 0:size].astype(float)
    out = []
    for t, s in zip(np.arange(n) * np.pi / 16, shifts):
        x, y = xx - CORNER[0] - s[0], yy - CORNER[1] - s[1]
        out.append(np.tanh((np.cos(t) * x + np.sin(t) * y) * (-np.sin(t) * x + np.cos(t) * y) / 4))
    return np.stack(out).astype(np.float32)


def test_shifts_undo_displaced_frames():
    shifts = np.random.default_rng(1).uniform(-2.5, 2.5, (8, 2))
    frames = star_frames(shifts)
    start = np.array([[31.0, 29.0], [29.0, 31.0]])
    res = symmetric_refine(frames, start, window=8, shifts=np.repeat(shifts[:, None], 2, axis=1))
    assert res.ok.all(), res.reason
    assert np.abs(res.corners - CORNER).max() < 0.01
    plain = symmetric_refine(frames, start, window=8)
    err = np.linalg.norm(plain.corners - CORNER, axis=-1)
    assert not plain.ok.all() or err.min() > 0.2  # without the shifts the frames disagree


def test_zero_shifts_are_the_plain_refinement():
    frames = star_frames() + np.random.default_rng(2).normal(0, 0.05, (8, 60, 60)).astype(np.float32)
    start = np.array([[31.0, 29.0], [28.5, 30.0], [30.0, 31.2]])
    w = np.array([8.0, 5.5, 3.0])
    a = symmetric_refine(frames, start, w)
    b = symmetric_refine(frames, start, w, shifts=np.zeros((8, 3, 2)))
    np.testing.assert_array_equal(a.corners, b.corners)
    np.testing.assert_array_equal(a.cov, b.cov)


def test_shifts_per_corner_and_frame():
    """Two corners of one image (a second corner 25 px away), each with its own shifts"""
    rng = np.random.default_rng(3)
    s1, s2 = rng.uniform(-1, 1, (8, 2)), rng.uniform(-1, 1, (8, 2))
    f1 = star_frames(s1, size=100)
    f2 = np.roll(star_frames(s2, size=100), (40, 45), axis=(1, 2))  # corner 2 at CORNER + (45, 40)
    frames = np.where(np.hypot(*np.mgrid[0:100, 0:100][::-1] - CORNER[:, None, None]) < 25, f1, f2)
    truth = np.array([CORNER, CORNER + (45, 40)])
    res = symmetric_refine(frames, truth + 0.7, window=6, shifts=np.stack((s1, s2), axis=1))
    assert res.ok.all(), res.reason
    assert np.abs(res.corners - truth).max() < 0.01


def test_shifts_shape_is_checked():
    with pytest.raises(ValueError, match="shifts"):
        symmetric_refine(star_frames(), np.array([[31.0, 29.0]]), 8, shifts=np.zeros((8, 2)))


def test_refine_each_frame_is_each_frame_alone():
    frames = star_frames() + np.random.default_rng(4).normal(0, 0.05, (8, 60, 60)).astype(np.float32)
    start = np.array([[31.0, 29.0], [28.5, 30.0], [1.0, 1.0]])  # the last leaves the image
    w = np.array([8.0, 5.5, 3.0])
    both = refine_each_frame(frames, start, w, max_iter=15)
    for k, f in enumerate(frames):
        one = symmetric_refine(f[None], start, w, max_iter=15)
        np.testing.assert_array_equal(both.corners[k], one.corners)
        np.testing.assert_array_equal(both.ok[k], one.ok)
        np.testing.assert_array_equal(both.sigma[k], one.sigma)
        assert both.reason[k].tolist() == one.reason.tolist()
    assert not both.ok[:, 2].any()


def test_one_gauss_newton_step_from_near_the_optimum_is_the_whole_fit():
    """symmetric_step (psfbias' per-corner simulated fits start it a few thousandths of a px off): to a few percent"""
    frames = star_frames() + np.random.default_rng(3).normal(0, 0.02, (8, 60, 60)).astype(np.float32)
    start = np.array([[29.0, 31.0], [30.0, 30.0]])
    full = symmetric_refine(frames, start, window=[8, 6], tol=1e-6)
    assert full.ok.all()
    near = full.corners + np.array([[0.01, -0.006], [-0.008, 0.0]])
    got = near + symmetric_step(frames, near, [8, 6])
    assert np.abs(got - full.corners).max() < 5e-4
    far = full.corners + 0.5  # (it is one step: from far off it is not there)
    assert np.abs(far + symmetric_step(frames, far, [8, 6]) - full.corners).max() > 1e-3
    assert np.isnan(symmetric_step(frames, np.array([[3.0, 30.0]]), 8)).all()  # the window leaves the frames

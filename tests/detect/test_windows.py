"""The refinement windows from the labelled grid (elements.grid_windows, issue 23)

A window measured on an element's region of pixels jumped by a pixel's worth
when the frames' noise moved one pixel of the region's edge; with small
elements the symmetric fit's corner depends on the window (0.01 px for
0.4 px of window on the bench's half-size D435 views), which gave the short
capture's corners a heavy tail. The window from the grid's local homography
follows the corners, which the noise barely moves.
"""

from __future__ import annotations

import cv2
import mrcal
import numpy as np
import pytest

from rotstar_mrcal import simulate
from rotstar_mrcal.capture.simulated import loop_irradiance
from rotstar_mrcal.detect.elements import MIN_WINDOW, WINDOW_FRACTION, by_identity, grid_windows, square_in_quad
from rotstar_mrcal.pattern.layout import make_layout

LAYOUT = make_layout(screen=(800, 600), pitch=100, band=24)  # 6 x 4 corners, identity frames


def labels_of(layout) -> np.ndarray:
    return np.array([[i, j] for j in range(layout.ny) for i in range(layout.nx)])


def exact_windows(H: np.ndarray, layout, labels: np.ndarray) -> np.ndarray:
    """0.65 x the square inside each element's quadrilateral as the homography H (grid units -> px) maps it"""
    h = layout.half_element / layout.pitch
    out = []
    for lab in labels:
        p = cv2.perspectiveTransform((lab + np.array([[0, 0], [-h, -h], [h, -h], [h, h], [-h, h]]))[None], H)[0]
        out.append(WINDOW_FRACTION * square_in_quad(p[1:], p[0]))
    return np.array(out)


def test_grid_windows_follow_a_perspective_grid():
    """Under a perspective map the windows are the elements' inscribed squares, shrinking with the depth"""
    lab = labels_of(LAYOUT).astype(float)
    H = np.array([[30.0, 6.0, 100.0], [-4.0, 33.0, 80.0], [0.05, 0.03, 1.0]])
    q = cv2.perspectiveTransform(lab[None], H)[0]
    w = grid_windows(lab, q, LAYOUT, 10.0)
    assert np.allclose(w, np.clip(exact_windows(H, LAYOUT, lab), MIN_WINDOW, 10.0), atol=1e-6)
    assert w[0] > w[-1]  # the far corner's element is smaller


def test_grid_windows_need_a_neighbourhood():
    """NaN (the region's window is used) where fewer than 4 corners, or one line of them, are labelled nearby"""
    lab = np.array([[0, 0], [1, 0], [2, 0], [5, 3]])
    w = grid_windows(lab, lab * 20.0 + 30, LAYOUT, 10.0)
    assert np.isnan(w).all()
    assert np.isnan(grid_windows(lab[:1], np.array([[np.nan, np.nan]]), LAYOUT, 10.0)).all()


@pytest.fixture(scope="module")
def small_view():
    """The loop's rotating-star and identity frames of a half-size D435 view with small elements (window 2-5 px)"""
    model = mrcal.cameramodel(intrinsics=("LENSMODEL_PINHOLE", np.array([320.0, 320, 319.5, 199.5])),
                              imagersize=np.array([640, 400]))
    rt = simulate.random_poses(model, LAYOUT, 3, np.random.default_rng([23, 0]))[2]
    E = loop_irradiance(LAYOUT, model, rt, supersample=2) * 0.9 * 65535
    kinds = [f["kind"] for f in LAYOUT.frames()]
    star = np.stack([E[1 + k] for k, kind in enumerate(kinds) if kind == "rotstar"]).astype(np.float32)
    ident = np.stack([E[1 + k] for k, kind in enumerate(kinds) if kind == "identity"]).astype(np.float32)
    return star, ident


def test_windows_do_not_follow_the_noise(small_view):
    """Three draws of noise at the short capture's level: the windows within 0.1 px of the noise-free ones"""
    star, ident = small_view
    clean = by_identity(star, ident, LAYOUT, 10.0)
    assert len(clean.labels) == LAYOUT.nx * LAYOUT.ny and np.median(clean.window) < 4
    rng = np.random.default_rng(5)
    for _ in range(3):  # about 0.01 of full scale per camera frame, two camera frames averaged
        noisy = [a + rng.normal(0, 0.007 * 65535, a.shape).astype(np.float32) for a in (star, ident)]
        got = by_identity(*noisy, LAYOUT, 10.0)
        assert np.array_equal(got.labels, clean.labels)
        assert np.abs(got.window - clean.window).max() < 0.1

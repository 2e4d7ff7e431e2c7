"""The partial-view benchmark's machinery: ChArUco board and labels, in-view corners, hanging poses, a few views"""

from __future__ import annotations

import math

import cv2
import mrcal
import numpy as np
import pytest

from rotstar_mrcal import simulate
from rotstar_lab.benchmark import partial
from rotstar_mrcal.peers.charuco import charuco_board, detect_charuco, render_charuco
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.simulate.visibility import half_spacing, in_view, seen, true_windows


@pytest.fixture(scope="module")
def layout():
    return make_layout()


# ---- the ChArUco board ----------------------------------------------------------
def test_render_is_opencvs_board(layout):
    """Our exact render is OpenCV's own image of the board, pixel for pixel, with its corners on the grid's"""
    img = render_charuco(layout)
    x0, y0, x1, y1 = layout.checkerboard_extent()
    ref = charuco_board(layout).generateImage((x1 - x0, y1 - y0), marginSize=0, borderBits=1)
    assert np.array_equal(img[y0:y1, x0:x1] * 255, ref)
    assert np.all(img[:y0] == 1) and np.all(img[:, :x0] == 1)  # white around it
    # OpenCV's chessboard corners, from the board's top-left, are the grid corners on the screen
    c = charuco_board(layout).getChessboardCorners()[:, :2] + (x0, y0)
    assert np.array_equal(c.reshape(layout.ny, layout.nx, 2), layout.corner_screen_xy())


def test_charuco_labels_on_whole_boards(layout):
    """Every corner of whole boards found, each at the true corner of its (i, j) label"""
    model = simulate.preset_model("d435")
    screen = simulate.make_screen(render_charuco(layout)[None].astype(np.float32), layout)
    for rt in simulate.random_poses(model, layout, 2, np.random.default_rng(7), distance=(0.25, 0.3), max_tilt_deg=30):
        E = simulate.render_irradiance(screen, model, rt, supersample=2, psf=1.0)[0]
        img = simulate.expose(E, gain=0.9, noise=0.005, bits=8, rng=0)
        c = detect_charuco(img, layout, 255.0)
        truth = simulate.true_corners(model, layout, rt)
        assert np.isfinite(c).all()
        assert np.max(np.linalg.norm(c - truth, axis=-1)) < 0.5


# ---- in view -------------------------------------------------------------------
@pytest.mark.slow  # make test-slow: the partial-view benchmark's machinery, which make bench runs whole
def test_true_windows_are_the_detectors():
    """The refinement windows from the true geometry against detect_pose's on whole boards: within 1.5 px"""
    from rotstar_mrcal.detect.pipeline import detect_pose

    lay = make_layout(identity=False)
    screen = simulate.make_screen(simulate.exact_frames(lay, lay.frames()[:lay.nframes]), lay)
    model = simulate.preset_model("wide")
    rt = simulate.random_poses(model, lay, 1, np.random.default_rng(5))[0]
    E = simulate.render_irradiance(screen, model, rt, supersample=2, psf=1.0)
    r = detect_pose(simulate.expose(E, noise=0.01, bits=16, rng=0), lay, 65535.0)
    w = true_windows(model, lay, rt)
    assert r.found and np.isfinite(w).all()
    assert np.max(np.abs(r.window - w)) < 1.5
    assert 0.85 < np.median(r.window / w) <= 1.0  # the detected element lies a little inside the true square


def test_a_corner_beyond_the_fold_is_not_in_view():
    """68 degrees off axis, past the D435 lens's fold, mrcal.project lands inside the image: not seen"""
    model = simulate.preset_model("d435")
    p = np.array((math.tan(math.radians(68.2)), 0.0, 1.0))
    q = mrcal.project(p, *model.intrinsics())
    W, H = model.imagersize()
    assert 0 <= q[0] < W and 0 <= q[1] < H  # the polynomial folds back into the image
    assert not seen(model, p)[1]
    assert seen(model, np.array((0.5, 0.2, 1.0)))[1]


def test_in_view_at_the_image_edge_and_from_behind(layout):
    """Corner (0, 0) moved to the left edge: in view with its window inside, not with the window across"""
    model = simulate.preset_model("d435")
    rt = simulate.look_at_pose(model, layout, (639.5, 400.0), 0.4)
    assert in_view(model, layout, rt).all()
    w = true_windows(model, layout, rt)[0, 0]
    assert 5 < w < 10

    def moved_to(x):  # the board moved sideways until corner (0, 0) is at image x (secant steps)
        a, b = 0.0, 0.01
        fa, fb = (simulate.true_corners(model, layout, rt + (0, 0, 0, s, 0, 0))[0, 0, 0] - x for s in (a, b))
        while abs(fb) > 1e-9:
            a, fa, b = b, fb, b - fb * (b - a) / (fb - fa)
            fb = simulate.true_corners(model, layout, rt + (0, 0, 0, b, 0, 0))[0, 0, 0] - x
        return rt + (0, 0, 0, b, 0, 0)

    for x, expected in ((1.2 * w, True), (0.8 * w, False), (-5.0, False)):
        r = moved_to(x)
        assert abs(simulate.true_corners(model, layout, r)[0, 0, 0] - x) < 1e-6
        assert in_view(model, layout, r)[0, 0] == expected, x
        assert in_view(model, layout, r)[0, 1]  # its neighbour, a spacing further in
    # seen from behind: nothing in view
    behind = simulate.look_at_pose(model, layout, (639.5, 400.0), 0.4, tilt=math.radians(120))
    assert not in_view(model, layout, behind).any()


def test_hanging_poses_hang_over_the_edges(layout):
    model = simulate.preset_model("wide")
    rts = simulate.hanging_poses(model, layout, 12, np.random.default_rng(1))
    f = np.array([in_view(model, layout, r).mean() for r in rts])
    assert np.all((f >= 0.3) & (f <= 0.75))
    assert not any(simulate.pose_ok(model, layout, r) for r in rts)  # none whole in the image
    assert np.degrees(simulate.tilt_angle(rts, layout)).max() <= 60


# ---- scoring and a few views end to end ----------------------------------------
def test_half_spacing_and_wrong_labels():
    t = np.stack(np.meshgrid(np.arange(4.0) * 30, np.arange(3.0) * 30), axis=-1)
    half = half_spacing(t)
    assert np.all(half == 15)
    c = t.copy()
    c[0, 0] += (14.0, 0.0)  # inside half a spacing: right
    c[0, 1] += (16.0, 0.0)  # beyond: wrong
    c[2, 3] = np.nan
    s = partial.score_view(c, t, np.ones((3, 4), bool), half)
    assert (s["reported"], s["wrong"], s["in_view"], s["complete"]) == (11, 1, 12, False)
    assert max(s["errors_px"]) == 14.0
    t2 = t.copy()
    t2[1, 1] = np.nan  # a corner the camera does not see, reported: wrong
    assert partial.score_view(t, t2, np.ones((3, 4), bool), half_spacing(t2))["wrong"] == 1


@pytest.fixture
def restore_threads():
    """run_views with jobs=1 sets the worker up in this process (one OpenCV thread): undo it after the test"""
    threads = cv2.getNumThreads()
    yield
    cv2.setNumThreads(threads)


@pytest.mark.slow  # make test-slow: an end-to-end run, left out of make test
def test_a_few_views(layout, restore_threads):
    """One hanging view per lens and a whole board on the wide lens: no wrong label"""
    views = partial.make_views(1, 1, seed=0, layout=layout)
    pick = [v for v in views if (v.lens, v.kind, v.condition) in
            (("d435", "hanging", "clean"), ("wide", "hanging", "saturated"), ("wide", "whole", "read noise 6 DN"))]
    res = partial.run_views(pick, seed=0, jobs=1, layout=layout)
    assert [r.view.key for r in res] == [v.key for v in pick]
    for r in res:
        ch = r.scores["charuco"]
        assert ch["wrong"] == 0 and r.scores["rotstar"]["wrong"] == 0, r.view.key
        assert 0.3 * 126 <= ch["in_view"] <= (0.75 if r.view.kind == "hanging" else 1) * 126
    assert all(r.scores["charuco"]["reported"] > 0.3 * r.scores["charuco"]["in_view"] for r in res[:2])
    whole = res[-1].scores["rotstar"]
    assert whole["complete"] and whole["in_view"] == 126 and max(whole["errors_px"]) < 0.5
    s = partial.summarize(res)
    assert s[("all", "hanging", "all", "charuco")]["views"] == 2
    tab = partial.hanging_table(s)
    assert tab.count("\n") == 4 and "| d435 | clean | 1 |" in tab and "**all**" in tab
    assert "| wide | read noise 6 DN | 1 | 1/1 | 100.0 % | 0 |" in partial.whole_table(s)
    assert "**FAIL**" in partial.goal_lines(s)  # 2 hanging views are not 200
    assert partial.summary_sentence(s).startswith("On 2 simulated views")

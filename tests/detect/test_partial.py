"""Identity frames at work: boards over the image edge, turned, mirrored (refused), occluded, corrupted (issue 13)

Every reported corner must be the right corner (within a fraction of a pixel
of the truth of its label); corners are allowed to be missing, never wrong.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from rotstar_mrcal import dataset
from rotstar_mrcal.detect.pipeline import detect_pose
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.simulate import Settings, look_at_pose, preset_model
from rotstar_mrcal.simulate.dataset import render_pose, true_corners
from rotstar_mrcal.simulate.screen import exact_frames, make_screen

from conftest import TEST_SUPERSAMPLE

deg = math.radians
HANGING = {  # target pixel of the board centre, distance m, tilt, tilt axis, roll
    "top-left corner": ((80, 60), 0.25, deg(30), deg(10), 0.6),
    "right edge": ((1250, 420), 0.22, deg(45), deg(80), -0.3),
    "bottom edge": ((700, 790), 0.3, deg(10), 0.0, 2.5),
    "bottom-right corner": ((1200, 760), 0.3, deg(50), deg(120), -2.0),
}


def in_view(truth: np.ndarray, shape, margin: float = 12.0) -> np.ndarray:
    """(ny, nx) corners far enough inside the image for a full refinement window"""
    H, W = shape
    x, y = truth[..., 0], truth[..., 1]
    return (x >= margin) & (y >= margin) & (x <= W - 1 - margin) & (y <= H - 1 - margin)


@pytest.fixture(scope="module")
def hanging():
    """{name: (rotstar frames, identity frames, truth)} of boards hanging over the D435 imager's edges"""
    model, layout = preset_model("d435"), make_layout()
    screen = make_screen(exact_frames(layout), layout, 0.02)
    out = {}
    for k, (name, (xy, d, t, ta, r)) in enumerate(HANGING.items()):
        rt = look_at_pose(model, layout, xy, d, tilt=t, tilt_axis=ta, roll=r)
        imgs = render_pose(screen, model, rt, Settings(seed=k, supersample=TEST_SUPERSAMPLE), np.random.default_rng(k)).astype(np.float32)
        out[name] = (imgs[:8], imgs[8:21], true_corners(model, layout, rt))
    return layout, out


def check_corners(r, truth, tol=0.1):
    """Every reported corner is its label's corner"""
    ok = np.isfinite(r.corners[..., 0])
    err = np.linalg.norm(r.corners - truth, axis=-1)[ok]
    assert np.all(err < tol), f"corner {err.max():.2f} px from the truth of its label"
    return ok


def test_boards_over_the_edge_give_the_corners_in_view(hanging):
    layout, views = hanging
    for name, (rot, ident, truth) in views.items():
        view = in_view(truth, rot.shape[1:])
        assert 0.3 <= view.mean() <= 0.75, name
        r = detect_pose(rot, layout, 65535.0, identity=ident)
        assert r.found, (name, r.error)
        ok = check_corners(r, truth)
        assert (ok & view).sum() >= 0.85 * view.sum(), (name, (ok & view).sum(), view.sum())
        assert not (ok & ~in_view(truth, rot.shape[1:], margin=2.0)).any(), "a corner whose window leaves the image"
        # without the identity frames the same view is skipped, with the reason
        assert "partly out of view" in detect_pose(rot, layout, 65535.0).error


def test_turned_views_are_labelled_by_their_codes_and_mirrored_ones_refused(hanging, d435_seq):
    """A turned view is labelled by its codes; a mirrored one (np.fliplr of every frame) is refused, with why:
    its codes would label it, but mrcal's board pose is a rotation and cannot fit a mirrored board"""
    layout, views = hanging
    p = dataset.load_pose(d435_seq.path, "pose000", d435_seq.layout)
    cases = [(p.rotstar, p.identity, d435_seq.corners("pose000"))] + [views["top-left corner"]]
    for rot, ident, truth in cases:
        H, W = rot.shape[1:]
        turned = (rot[:, ::-1, ::-1], ident[:, ::-1, ::-1], (W - 1, H - 1) - truth)
        r_, i_, t_ = turned
        r = detect_pose(np.ascontiguousarray(r_), layout, 65535.0, identity=np.ascontiguousarray(i_))
        assert r.found, r.error
        ok = check_corners(r, t_)
        assert ok.sum() >= 0.85 * in_view(t_, (H, W)).sum()
        mirrored = [np.ascontiguousarray([np.fliplr(f) for f in frames]) for frames in (rot, ident)]
        r = detect_pose(mirrored[0], layout, 65535.0, identity=mirrored[1])
        assert not r.found and r.error.startswith("board seen mirrored (the image flipped, or the screen seen "
                                                  "through a mirror)"), r.error
        assert np.all(np.isnan(r.corners))


@pytest.fixture(scope="module")
def whole(d435_seq):
    p = dataset.load_pose(d435_seq.path, "pose000", d435_seq.layout)
    return d435_seq.layout, p.rotstar, p.identity, d435_seq.corners("pose000")


def test_whole_board_with_identities_matches_the_graph(whole):
    layout, rot, ident, truth = whole
    a = detect_pose(rot, layout, 65535.0, identity=ident)
    b = detect_pose(rot, layout, 65535.0)
    assert a.n_valid == b.n_valid == layout.nx * layout.ny
    assert np.nanmax(np.abs(a.corners - b.corners)) < 0.01
    check_corners(a, truth, tol=0.05)


def _element_disk(truth, i, j, shape, frac=0.3):
    """Pixels within frac x the local corner spacing of corner (i, j)"""
    s = np.linalg.norm(truth[j, i] - truth[j, i + (1 if i == 0 else -1)])
    yy, xx = np.mgrid[0 : shape[0], 0 : shape[1]]
    return np.hypot(xx - truth[j, i, 0], yy - truth[j, i, 1]) < frac * s


def _write_code(ident, disk, word):
    """The identity frames with `word` shown in the pixels of disk"""
    hi, lo = ident.max(axis=0), ident.min(axis=0)
    out = ident.copy()
    out[:, disk] = lo[disk] + (hi[disk] - lo[disk]) * np.asarray(word, float)[:, None]
    return out


def test_swapped_codes_are_caught_by_the_neighbours(whole):
    # two elements show each other's codewords: each identity reads as a valid index, in the wrong place
    layout, rot, ident, truth = whole
    code = layout.identity_code
    a, b = (3, 2), (10, 6)
    da, db = (_element_disk(truth, *e, ident.shape[1:]) for e in (a, b))
    bad = _write_code(_write_code(ident, da, code.codewords[b[1] * layout.nx + b[0]]), db,
                      code.codewords[a[1] * layout.nx + a[0]])
    r = detect_pose(rot, layout, 65535.0, identity=bad)
    assert r.found, r.error
    check_corners(r, truth)
    for i, j in (a, b):
        assert not np.isfinite(r.corners[j, i]).any()
        assert "disagrees with its neighbours" in r.reasons[j, i]
    assert r.n_valid == layout.nx * layout.ny - 2


def test_a_misread_element_is_dropped_with_its_reason(whole):
    layout, rot, ident, truth = whole
    disk = _element_disk(truth, 5, 5, ident.shape[1:])
    word = layout.identity_code.codewords[5 * layout.nx + 5].copy()
    word[np.flatnonzero(word == 0)[0]] = 1  # one frame misread: seven white frames
    r = detect_pose(rot, layout, 65535.0, identity=_write_code(ident, disk, word))
    assert r.found and r.n_valid == layout.nx * layout.ny - 1
    assert not np.isfinite(r.corners[5, 5]).any()
    assert any("7 white frames" in u for u in r.unplaced)
    check_corners(r, truth)


@pytest.mark.parametrize("fault", ["inverted", "dropped", "repeated", "noise", "occluder"])
def test_corrupted_identity_frames_never_mislabel(whole, fault):
    layout, rot, ident, truth = whole
    bad = ident.copy()
    rng = np.random.default_rng(7)
    if fault == "inverted":  # frame 4 shown in negative
        bad[4] = ident.max(axis=0) + ident.min(axis=0) - ident[4]
    elif fault == "dropped":  # the display skipped frame 4: the rest come one early, the last is black
        bad[4:-1] = ident[5:]
        bad[-1] = ident.min(axis=0)
    elif fault == "repeated":  # frame 4 shows frame 3 again
        bad[4] = ident[3]
    elif fault == "noise":  # identity frames drowned in noise
        bad = ident + rng.normal(0, 0.25 * float(np.percentile(ident, 99)), ident.shape).astype(np.float32)
    elif fault == "occluder":  # a hand in front of part of the board, in every frame
        H, W = ident.shape[1:]
        c = truth[4, 6]
        yy, xx = np.mgrid[0:H, 0:W]
        hand = np.hypot(xx - c[0], yy - c[1]) < 60
        bad[:, hand] = 3000.0
        rot = rot.copy()
        rot[:, hand] = 3000.0
    r = detect_pose(rot, layout, 65535.0, identity=bad)
    if r.found:
        check_corners(r, truth)
        assert r.n_valid < layout.nx * layout.ny
        missing = ~np.isfinite(r.corners[..., 0])
        named = (r.reasons != "") & missing
        if fault != "occluder":  # hidden elements are just missing; misread ones are dropped with a reason
            assert named.sum() + len(r.unplaced or []) >= missing.sum(), "every element dropped has a reason"
    else:
        assert "identit" in r.error, r.error


@pytest.mark.parametrize("fault", ["inverted", "inverted-file", "swapped"])
def test_inverted_or_swapped_identity_frames_are_named(whole, fault):
    """One identity frame inverted (shown in negative, or its file inverted: the surround white too), or two
    swapped (on disk or in pattern.json): the pose is refused naming the frames, not as 'identities of 0 of 1
    elements read' nor with most of the board silently lost"""
    layout, rot, ident, truth = whole
    bad = ident.copy()
    if fault.startswith("inverted"):  # frame 4 shown in negative, or written as an inverted 16-bit image
        bad[4] = ident.max(axis=0) + ident.min(axis=0) - ident[4] if fault == "inverted" else 65535 - ident[4]
        want = r"identity frame 4 \(identity_04\.png\) inverted \(its white and black exchanged\): as recorded " \
               r"the codes of \d+ of 12\d elements read, with it inverted 12\d"
    else:  # frames 3 and 9 in each other's place
        bad[[3, 9]] = ident[[9, 3]]
        want = r"identity frames 3 and 9 \(identity_03\.png, identity_09\.png\) swapped, on disk or in pattern\.json: " \
               r"as recorded the codes of \d+ of 12\d elements read, with the two exchanged 12\d"
    r = detect_pose(rot, layout, 65535.0, identity=bad)
    assert not r.found and np.all(np.isnan(r.corners))
    assert re.match(want, r.error), r.error

"""rotstar-capture's coverage picture: where corners have been seen, the latest board, the zones still missing"""

from __future__ import annotations

import math

import numpy as np
import pytest

from rotstar_mrcal.capture.coverage import (
    GREY, RED, YELLOW, ZONES, coverage_counts, coverage_image, describe, missing_zones, zone_cells,
)
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.simulate import look_at_pose, preset_model, true_corners

SIZE = (1280, 800)
MODEL, LAYOUT = preset_model("d435"), make_layout()


def board(target, distance=0.45, tilt_deg=0.0, roll=0.0):
    """The true corners of a board centred at pixel target; corners outside the imager are NaN (a partial board)"""
    g = true_corners(MODEL, LAYOUT, look_at_pose(MODEL, LAYOUT, target, distance, tilt=math.radians(tilt_deg),
                                                 roll=roll))
    W, H = SIZE
    out = (g[..., 0] < 0) | (g[..., 0] > W - 1) | (g[..., 1] < 0) | (g[..., 1] > H - 1)
    g[out] = np.nan
    return g


def sparse(g, n=14):
    g = g.copy().reshape(-1, 2)
    g[n:] = np.nan
    return g.reshape(LAYOUT.ny, LAYOUT.nx, 2)


def near(img, colour, tol=40):
    return np.all(np.abs(img.astype(int) - colour) < tol, axis=-1)


def test_counts_only_the_boards_mrcal_uses():
    centre, corner = board((640, 400)), board((60, 50), distance=0.3)
    assert np.isnan(corner).any() and np.isfinite(corner).sum() > 2 * 18  # the premise: hanging over the corner
    n = coverage_counts([centre, sparse(corner)], SIZE)
    assert n.sum() == np.isfinite(centre[..., 0]).sum()  # the 14-corner board does not count ...
    assert "top-left corner" in missing_zones(n)
    n2 = coverage_counts([centre, corner], SIZE)
    assert n2[0, 0] > 0 and "top-left corner" not in missing_zones(n2)  # ... the partial board with 60+ does
    assert describe(n2).startswith(f"corners in {int((n2 > 0).sum())} of 40 imager cells")


def test_every_zone_is_named_until_reached():
    n = coverage_counts([board((640, 400))], SIZE)
    assert missing_zones(n) == list(ZONES)
    full = np.ones((5, 8), int)
    for z, (r, c) in zone_cells(full.shape).items():
        one_gap = full.copy()
        one_gap[r, c] = 0
        assert missing_zones(one_gap) == [z]
    assert missing_zones(full) == [] and "every border zone reached" in describe(full)


def test_picture_frames_the_missing_zones_in_red():
    """Red frames around exactly the zones still missing; a board in the top-left corner removes that one"""
    def red_in(img, zone):
        r, c = zone_cells((5, 8))[zone]
        h, w = img.shape[:2]
        y0, y1 = r.start * h // 5, r.stop * h // 5
        x0, x1 = c.start * w // 8, c.stop * w // 8
        return near(img[y0:y1, x0:x1], RED).sum()

    img = coverage_image([board((640, 400))], SIZE)
    assert img.shape == (800, 1280, 3)
    assert all(red_in(img, z) > 200 for z in ZONES)
    img = coverage_image([board((640, 400)), board((60, 50), distance=0.3)], SIZE)
    assert red_in(img, "top-left corner") == 0 and red_in(img, "bottom-right corner") > 200


def test_latest_board_in_yellow_earlier_ones_in_grey():
    a, b = board((350, 250)), board((930, 560), tilt_deg=40)
    img = coverage_image([a, b], SIZE, names=["pose000", "pose001"])

    def colour_at(g, colour):
        p = np.round(g[np.isfinite(g[..., 0])]).astype(int)
        return near(img[p[:, 1], p[:, 0]], colour).mean()

    assert colour_at(b, YELLOW) > 0.9 and colour_at(a, GREY) > 0.9
    assert colour_at(a, YELLOW) == 0 and colour_at(b, GREY) == 0
    img2 = coverage_image([a, b], SIZE, latest=0)
    p = np.round(a[np.isfinite(a[..., 0])]).astype(int)
    assert near(img2[p[:, 1], p[:, 0]], YELLOW).mean() > 0.9
    small = coverage_image([a, b], SIZE, width=640)  # scaled for a smaller window
    assert small.shape == (400, 640, 3) and near(small, YELLOW).any()


def test_boards_mrcal_ignores_are_red_and_not_counted():
    a, s = board((640, 400)), sparse(board((200, 600)))
    img = coverage_image([a, s], SIZE, latest=0)
    p = np.round(s[np.isfinite(s[..., 0])]).astype(int)
    assert near(img[p[:, 1], p[:, 0]], RED).mean() > 0.9
    assert near(img, GREY).any()
    # a cell that holds only the ignored board's corners stays unshaded (black under the crosses)
    col, row = int(p[0, 0] * 8 // 1280), int(p[0, 1] * 5 // 800)
    assert coverage_counts([a, s], SIZE)[row, col] == 0


@pytest.mark.parametrize("latest", [None, -1])
def test_empty_and_single(latest):
    assert coverage_image([], SIZE, latest=latest).shape == (800, 1280, 3)
    assert coverage_counts([], SIZE).sum() == 0

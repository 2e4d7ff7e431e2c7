"""Which parts of the imager the detected corners cover so far, and the picture of it

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.capture.coverage import coverage_counts, missing_zones, coverage_image, describe
    >>> c = np.array([[[100., 100.], [600., 380.], [10., 200.]]])   # one board, three corners
    >>> n = coverage_counts([c], (640, 400), cells=(4, 3), used=[True])
    >>> n.tolist()
    [[1, 0, 0, 0], [1, 0, 0, 0], [0, 0, 0, 1]]
    >>> missing_zones(n)
    ['top-right corner', 'bottom-left corner', 'right edge', 'top edge', 'bottom edge']
    >>> coverage_image([c], (640, 400), used=[True]).shape
    (400, 640, 3)

mrcal needs corners near the edges and corners of the imager to pin down
the distortion; a calibration from boards in the middle only extrapolates
there. The imager is cut into cells (default 8 x 5); a cell is covered when
a corner that mrcal will use falls into it. missing_zones names the
uncovered border zones (the four corners and the four edges, each the
outer ring of cells) that a user should fill next.

Only the boards mrcal will use count (`used`; by default vnl.mrcal_keeps:
a board with at most 2 * min(nx, ny) corners is dropped by mrcal). The
picture (coverage_image) is the imager at up to `width` pixels wide:

    cells       shaded green by how many corners fell into them
    missing     every uncovered border zone framed in red and named inside
    corners     every corner of the earlier boards a grey dot
    latest      the newest board's corners in yellow, its outline drawn and
                its name written next to it
    ignored     boards mrcal will not use (too few corners) as red crosses
    text        one line: boards, covered cells, how many zones are missing
"""

from __future__ import annotations

import cv2
import numpy as np

from rotstar_mrcal.vnl import mrcal_keeps

ZONES = ("top-left corner", "top-right corner", "bottom-left corner", "bottom-right corner",
         "left edge", "right edge", "top edge", "bottom edge")

GREY, YELLOW, RED, WHITE = (200, 200, 200), (0, 230, 255), (60, 60, 255), (255, 255, 255)


def _used(boards, used) -> list[bool]:
    return [mrcal_keeps(b) for b in boards] if used is None else [bool(u) for u in used]


def _points(c) -> np.ndarray:
    p = np.asarray(c, float).reshape(-1, 2)
    return p[np.isfinite(p).all(axis=1)]


def cell_of(p, imagersize, cells) -> tuple[np.ndarray, np.ndarray]:
    """(column, row) of the imager cell of each pixel p (n, 2) (mrcal coordinates: pixel centres at integers)"""
    W, H = imagersize
    cx, cy = cells
    p = np.asarray(p, float)
    i = np.clip((p[:, 0] + 0.5) * cx // W, 0, cx - 1).astype(int)
    j = np.clip((p[:, 1] + 0.5) * cy // H, 0, cy - 1).astype(int)
    return i, j


def coverage_counts(boards, imagersize, cells=(8, 5), used=None) -> np.ndarray:
    """(rows, cols) number of corners in each imager cell

    boards: (ny, nx, 2) arrays, NaN = missing; used: which boards count
    (default: those mrcal keeps).
    """
    cx, cy = cells
    n = np.zeros((cy, cx), int)
    for c, u in zip(boards, _used(boards, used)):
        if u:
            i, j = cell_of(_points(c), imagersize, cells)
            np.add.at(n, (j, i), 1)
    return n


def zone_cells(shape) -> dict[str, tuple[slice, slice]]:
    """{zone: (rows, cols)} of the border zones of a (rows, cols) cell grid (edges without the corners)"""
    rows, cols = shape
    return {"top-left corner": (slice(0, 1), slice(0, 1)), "top-right corner": (slice(0, 1), slice(cols - 1, cols)),
            "bottom-left corner": (slice(rows - 1, rows), slice(0, 1)),
            "bottom-right corner": (slice(rows - 1, rows), slice(cols - 1, cols)),
            "left edge": (slice(1, rows - 1), slice(0, 1)), "right edge": (slice(1, rows - 1), slice(cols - 1, cols)),
            "top edge": (slice(0, 1), slice(1, cols - 1)), "bottom edge": (slice(rows - 1, rows), slice(1, cols - 1))}


def missing_zones(counts: np.ndarray) -> list[str]:
    """The border zones without a corner yet (corners first, then edges)"""
    n = np.asarray(counts)
    return [z for z, (r, c) in zone_cells(n.shape).items() if n[r, c].size and n[r, c].sum() == 0]


def describe(counts: np.ndarray) -> str:
    """One line: cells covered and what is missing"""
    n = np.asarray(counts)
    miss = missing_zones(n)
    s = f"corners in {int((n > 0).sum())} of {n.size} imager cells"
    return s + (f"; nothing yet near: {', '.join(miss)}" if miss else "; every border zone reached")


def _text(img, text, org, scale, colour, thick=1):
    """Text with a dark outline, readable on any background"""
    cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0), thick + 2, cv2.LINE_AA)
    cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, colour, thick, cv2.LINE_AA)


def coverage_image(boards, imagersize, cells=(8, 5), latest: int | None = -1, width: int = 1280, used=None,
                   names=None) -> np.ndarray:
    """A BGR picture of the imager: where the corners are so far (module doc)

    boards: every pose's (ny, nx, 2) corners in capture order; latest: the
    index of the board to highlight (None: none); used: which boards mrcal
    will use (default vnl.mrcal_keeps); names: a label per board (e.g. the
    pose), written next to the latest one.
    """
    W, H = (int(v) for v in imagersize)
    s = min(1.0, width / W)
    w, h = int(round(W * s)), int(round(H * s))
    ts = 0.45 * max(w / 640, 0.8)  # text scale
    img = np.zeros((h, w, 3), np.uint8)
    use = _used(boards, used)
    n = coverage_counts(boards, imagersize, cells, use)
    cx, cy = cells
    xs = np.round(np.arange(cx + 1) * w / cx).astype(int)
    ys = np.round(np.arange(cy + 1) * h / cy).astype(int)
    for j in range(cy):
        for i in range(cx):
            if n[j, i]:
                img[ys[j]:ys[j + 1], xs[i]:xs[i + 1]] = (30, min(50 + 6 * n[j, i], 120), 30)
            cv2.rectangle(img, (xs[i], ys[j]), (xs[i + 1] - 1, ys[j + 1] - 1), (70, 70, 70), 1)
    miss = missing_zones(n)
    zones = zone_cells(n.shape)
    for z in miss:
        r, c = zones[z]
        x0, x1, y0, y1 = xs[c.start], xs[c.stop] - 1, ys[r.start], ys[r.stop] - 1
        cv2.rectangle(img, (x0 + 2, y0 + 2), (x1 - 2, y1 - 2), RED, 2)
        words = z.split()
        zs = min(ts, ts * (x1 - x0 - 10) / max(cv2.getTextSize(t, cv2.FONT_HERSHEY_SIMPLEX, ts, 1)[0][0]
                                               for t in words))
        for k, word in enumerate(words):
            size = cv2.getTextSize(word, cv2.FONT_HERSHEY_SIMPLEX, zs, 1)[0]
            _text(img, word, ((x0 + x1 - size[0]) // 2, (y0 + y1) // 2 + int((k - 0.2) * 1.6 * size[1])), zs, RED)
    k_latest = None if latest is None or not boards else latest % len(boards)
    r = max(2, int(round(2 * s + 0.5)))
    for k, (c, u) in enumerate(zip(boards, use)):
        p = _points(c) * s
        if k == k_latest:
            continue
        for x, y in np.round(p).astype(int):
            if u:
                cv2.circle(img, (x, y), r, GREY, -1, cv2.LINE_AA)
            else:
                cv2.drawMarker(img, (x, y), RED, cv2.MARKER_TILTED_CROSS, 2 * r + 2, 1)
    if k_latest is not None:
        p = _points(boards[k_latest]) * s
        colour = YELLOW if use[k_latest] else RED
        if len(p) >= 3:
            hull = cv2.convexHull(np.round(p).astype(np.int32))
            cv2.polylines(img, [hull], True, colour, 1, cv2.LINE_AA)
        for x, y in np.round(p).astype(int):
            cv2.circle(img, (x, y), r + 1, colour, -1, cv2.LINE_AA)
        if len(p) and names is not None:
            label = str(names[k_latest]) + ("" if use[k_latest] else " (too few corners for mrcal)")
            x, y = p.mean(axis=0).astype(int)
            size = cv2.getTextSize(label, cv2.FONT_HERSHEY_SIMPLEX, ts, 1)[0]
            _text(img, label, (int(np.clip(x - size[0] // 2, 2, w - size[0] - 2)), int(np.clip(y, 20, h - 30))),
                  ts, colour)
    nused, nign = sum(use), len(use) - sum(use)
    text = (f"{nused} board(s)" + (f" (+{nign} with too few corners for mrcal)" if nign else "")
            + f", corners in {int((n > 0).sum())}/{n.size} cells, "
            + (f"{len(miss)} border zone(s) missing (red)" if miss else "every border zone reached"))
    fs = min(ts, ts * (w - 16) / cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, ts, 1)[0][0])
    _text(img, text, (8, h - 8), fs, WHITE)
    return img

"""Which parts of the imager the detected corners cover so far

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.capture.coverage import coverage_counts, missing_zones, coverage_image
    >>> c = np.array([[[100., 100.], [600., 380.], [10., 200.]]])   # one board, three corners
    >>> n = coverage_counts([c], (640, 400), cells=(4, 3))
    >>> n.tolist()
    [[1, 0, 0, 0], [1, 0, 0, 0], [0, 0, 0, 1]]
    >>> missing_zones(n)
    ['top-right corner', 'bottom-left corner', 'right edge', 'top edge', 'bottom edge']
    >>> coverage_image([c], (640, 400)).shape
    (400, 640, 3)

mrcal needs corners near the edges and corners of the imager to pin down
the distortion; a calibration from boards in the middle only extrapolates
there. The imager is cut into cells (default 8 x 5); a cell is covered when
a detected corner falls into it. missing_zones names the uncovered border
zones (the four corners and the four edges) that a user should fill next.
"""

from __future__ import annotations

import cv2
import numpy as np

ZONES = ("top-left corner", "top-right corner", "bottom-left corner", "bottom-right corner",
         "left edge", "right edge", "top edge", "bottom edge")


def coverage_counts(boards, imagersize, cells=(8, 5)) -> np.ndarray:
    """(rows, cols) number of corners in each imager cell; boards: (ny, nx, 2) arrays, NaN = missing"""
    W, H = imagersize
    cx, cy = cells
    n = np.zeros((cy, cx), int)
    for c in boards:
        p = np.asarray(c, float).reshape(-1, 2)
        p = p[np.isfinite(p).all(axis=1)]
        i = np.clip((p[:, 0] + 0.5) * cx // W, 0, cx - 1).astype(int)
        j = np.clip((p[:, 1] + 0.5) * cy // H, 0, cy - 1).astype(int)
        np.add.at(n, (j, i), 1)
    return n


def missing_zones(counts: np.ndarray) -> list[str]:
    """The border zones without a corner yet (corners first, then edges)"""
    n = np.asarray(counts)
    edges = {"left edge": n[1:-1, 0], "right edge": n[1:-1, -1], "top edge": n[0, 1:-1], "bottom edge": n[-1, 1:-1]}
    zones = {"top-left corner": n[0, 0], "top-right corner": n[0, -1],
             "bottom-left corner": n[-1, 0], "bottom-right corner": n[-1, -1],
             **{k: v.sum() for k, v in edges.items() if v.size}}
    return [z for z in ZONES if z in zones and zones[z] == 0]


def describe(counts: np.ndarray) -> str:
    """One line: cells covered and what is missing"""
    n = np.asarray(counts)
    miss = missing_zones(n)
    s = f"corners in {int((n > 0).sum())} of {n.size} imager cells"
    return s + (f"; nothing yet near: {', '.join(miss)}" if miss else "; every border zone reached")


def coverage_image(boards, imagersize, cells=(8, 5), latest: int | None = -1, width: int = 1280) -> np.ndarray:
    """A BGR picture of the imager: covered cells shaded, every corner a dot, the latest board in yellow"""
    W, H = (int(v) for v in imagersize)
    s = min(1.0, width / W)
    w, h = int(round(W * s)), int(round(H * s))
    img = np.zeros((h, w, 3), np.uint8)
    n = coverage_counts(boards, imagersize, cells)
    cx, cy = cells
    for j in range(cy):
        for i in range(cx):
            x0, x1 = int(i * w / cx), int((i + 1) * w / cx)
            y0, y1 = int(j * h / cy), int((j + 1) * h / cy)
            if n[j, i]:
                img[y0:y1, x0:x1] = (40, min(60 + 15 * n[j, i], 140), 40)
            cv2.rectangle(img, (x0, y0), (x1 - 1, y1 - 1), (90, 90, 90), 1)
    for k, c in enumerate(boards):
        p = np.asarray(c, float).reshape(-1, 2)
        p = p[np.isfinite(p).all(axis=1)] * s
        is_latest = latest is not None and k == (latest % len(boards))
        for x, y in p:
            cv2.circle(img, (int(round(x)), int(round(y))), 3 if is_latest else 2,
                       (0, 230, 255) if is_latest else (230, 230, 230), -1, cv2.LINE_AA)
    miss = missing_zones(n)
    text = f"{len(boards)} board(s); " + (f"missing: {', '.join(miss)}" if miss else "all border zones reached")
    cv2.putText(img, text, (8, h - 10), cv2.FONT_HERSHEY_SIMPLEX, 0.5 * max(w / 640, 0.6), (255, 255, 255), 1,
                cv2.LINE_AA)
    return img

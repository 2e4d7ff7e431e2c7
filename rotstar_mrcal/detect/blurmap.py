"""The blur map: the lens's local PSF at every corner of a dataset, as a table and a picture (issue 24)

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.detect.blurmap import blur_rows, HEADER
    >>> blur = np.full((1, 2, 8), np.nan); blur[0, 1] = (0.8, 0.01, 0.1, 30.0, 0.4, 0.05, 45.0, 3.5)
    >>> corners = np.array([[[10.0, 20.0], [30.0, 40.0]]])
    >>> rows = blur_rows([("pose000", corners, blur)])
    >>> HEADER[:4], len(rows), rows[0][:4]
    (('pose', 'i', 'j', 'x'), 1, ('pose000', 1, 0, 30.0))

    write_blur_map("out", rows, imagersize=(1280, 800))   # out/blur_map.csv, out/blur_map.png

Per corner (rotstar-detect --blur-map DIR; detect.edgespread.blur_columns):
the PSF's width (px: its RMS extent along a direction, averaged over
directions, the pixel's own 1/12 px^2 taken off), its elongation (the
relative difference of its extent along its long and short axes) and the
long axis's direction, and its coma (the cos-phi part of the projections'
third moment, px^3) and the direction its tail points, each with a standard
deviation, and the reach the PSF was clipped to. Corners whose half-window
is under edgespread.PSF_MIN_WINDOW are left out (their edges are too short
to hold the PSF). The picture has three panels over the imager: the width
(colour), the elongation (colour, a bar along the long axis) and the coma
(colour, an arrow toward the tail); the colour scales span the 2nd to 98th
percentiles of the values. doc/blur-map.md
says how to read it.
"""

from __future__ import annotations

import csv
import os

import numpy as np

from rotstar_mrcal.detect.edgespread import BLUR_FIELDS

HEADER = ("pose", "i", "j", "x", "y") + BLUR_FIELDS
CSV_NAME, PNG_NAME = "blur_map.csv", "blur_map.png"


def blur_rows(poses) -> list[tuple]:
    """One row per measured corner from [(pose name, corners (ny, nx, 2), blur (ny, nx, 8))]; see HEADER"""
    rows = []
    for name, corners, blur in poses:
        if blur is None:
            continue
        ok = np.isfinite(blur[..., 0]) & np.isfinite(corners[..., 0])
        for j, i in zip(*np.nonzero(ok)):
            rows.append((name, int(i), int(j), float(corners[j, i, 0]), float(corners[j, i, 1]))
                        + tuple(float(v) for v in blur[j, i]))
    return rows


def write_table(path: str, rows) -> None:
    """The rows as CSV with HEADER (values to 4 decimals)"""
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(HEADER)
        for r in rows:
            w.writerow(r[:3] + tuple(f"{v:.4f}" for v in r[3:]))


def read_table(path: str) -> np.ndarray:
    """(n, len(HEADER) - 3) float array of a written table's numeric columns (x, y, width, ...)"""
    with open(path) as f:
        rows = list(csv.reader(f))[1:]
    return np.array([[float(v) for v in r[3:]] for r in rows]).reshape(-1, len(HEADER) - 3)


def colour_range(values) -> tuple[float, float]:
    """(low, high) of a colour scale that fits the values: their 2nd and 98th percentiles, never empty

    >>> colour_range([1.0, 2.0, 3.0, 100.0])
    (1.06, 94.18)
    >>> colour_range([np.nan, 2.0])
    (1.99, 2.01)
    """
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    if not v.size:
        return 0.0, 1.0
    lo, hi = (float(x) for x in np.percentile(v, [2, 98]))
    if hi - lo < 1e-9:
        lo, hi = lo - 0.01, hi + 0.01
    return round(lo, 4), round(hi, 4)


def plot_blur_map(path: str, table: np.ndarray, imagersize, title: str = "") -> None:
    """The three panels of the module doc to path (PNG); table: read_table's columns"""
    # (here, not at the top: rotstar-detect imports this module and must not pay matplotlib's start-up
    # unless --blur-map asks for the picture)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    W, H = imagersize
    x, y, width, _, elong, elong_deg, coma, _, coma_deg, _ = table.T
    fig, axes = plt.subplots(1, 3, figsize=(18, 18 * H / W / 3 + 1.2), constrained_layout=True)
    panels = (("width (px)", width, None), ("elongation (long axis)", elong, "bar"),
              ("coma (px^3, arrow: tail)", coma, "arrow"))
    scale = 0.04 * W
    for ax, (name, v, mark) in zip(axes, panels):
        lo, hi = colour_range(v)
        sc = ax.scatter(x, y, c=v, s=14, cmap="viridis", vmin=lo, vmax=hi)
        if mark == "bar":
            a = np.radians(elong_deg)
            ax.quiver(x, y, np.cos(a), np.sin(a), angles="xy", headwidth=0, headlength=0, headaxislength=0,
                      pivot="middle", scale_units="xy", scale=1 / scale, width=0.002, color="k")
        elif mark == "arrow":
            a = np.radians(coma_deg)
            n = v / max(hi, 1e-9)
            ax.quiver(x, y, np.cos(a) * n, np.sin(a) * n, angles="xy", scale_units="xy", scale=1 / scale,
                      width=0.002, color="k")
        ax.set_xlim(0, W)
        ax.set_ylim(H, 0)
        ax.set_aspect("equal")
        ax.set_title(name)
        fig.colorbar(sc, ax=ax, shrink=0.8)
    if title:
        fig.suptitle(title)
    fig.savefig(path, dpi=80)
    plt.close(fig)


def write_blur_map(outdir: str, rows, imagersize, title: str = "") -> tuple[str, str]:
    """(csv path, png path): the table and the picture of rows (blur_rows) in outdir (created)"""
    os.makedirs(outdir, exist_ok=True)
    table_path, png_path = os.path.join(outdir, CSV_NAME), os.path.join(outdir, PNG_NAME)
    write_table(table_path, rows)
    plot_blur_map(png_path, read_table(table_path), imagersize, title)
    return table_path, png_path

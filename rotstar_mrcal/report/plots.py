"""The validation figures (matplotlib, no display needed)

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.report.plots import data_range, heatmaps, per_pose, summary_bars, nice_max
    >>> q = np.stack(np.meshgrid(np.linspace(0, 1279, 8), np.linspace(0, 799, 5)), -1)
    >>> fig = heatmaps(q, [("diff", np.ones((5, 8))), ("u", np.zeros((5, 8)))], (1280, 800), cbmax=2)
    >>> len(fig.axes)                      # two panels and one colour bar
    3
    >>> fig = heatmaps(q, [("diff", np.full((5, 8), 0.3)), ("u", np.linspace(0.01, 0.03, 40).reshape(5, 8))],
    ...                (1280, 800))
    >>> len(fig.axes), fig.axes[1].collections[0].get_clim()   # a colour bar each, scaled to its data
    (4, (0.0, 0.03))
    >>> data_range(np.linspace(0.01, 0.03, 40))   # from zero to (about) the largest value
    (0.0, 0.03)
    >>> fig = per_pose([("calibrated on A, tested on B", {"rotstar": {"p0": 0.1, "p1": 0.2}})])
    >>> fig = summary_bars(["low", "high"], [("A->B", {"rotstar": [0.1, 0.2], "saddle": [0.3, None]})], "MRE, px")
    >>> nice_max(0.0337), nice_max(0.7), nice_max(3.2)
    (0.05, 1.0, 5.0)
    >>> fig = summary_bars(["seq"], [("A->B", {"rotstar": [0.0325], "saddle": [0.0348]})], "MRE, px")
    >>> ax = fig.axes[0]
    >>> ax.get_yscale(), float(ax.get_ylim()[0])   # linear from zero: a 7 % difference looks like one
    ('linear', 0.0)

Each function returns a matplotlib Figure; the caller saves it
(fig.savefig(path)) and closes it (matplotlib.pyplot.close(fig)).

    heatmaps      panels of values on a pixel grid over the imager (projection
                  diff, uncertainties, error against the truth), each with its
                  own colour scale from zero to its data's 99th percentile (or
                  one shared 0..cbmax), optional observed corners on top
    per_pose      held-out mean reprojection error of each test pose, one line
                  per method (the paper's figure), linear axis from zero
    summary_bars  one number per method and condition, grouped bars on a
                  linear axis from zero, each bar's value written on it

Legends sit outside the axes, never over the data.
"""

from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

COLOURS = {
    "rotstar": "#c0392b",
    "rotstar-weighted": "#e67e22",
    "opencv-sb": "#2471a3",
    "cornersubpix": "#17a589",
    "saddle": "#7d3c98",
    "mrgingham": "#566573",
}


def colour(method: str, k: int = 0) -> str:
    return COLOURS.get(method, f"C{k % 10}")


def nice_max(v: float) -> float:
    """The smallest of 1, 2, 5 x 10^k that is >= v"""
    if not np.isfinite(v) or v <= 0:
        return 1.0
    e = math.floor(math.log10(v))
    for m in (1, 2, 5, 10):
        if m * 10**e >= v * (1 - 1e-12):
            return float(round(m * 10**e, 12))
    return float(10 ** (e + 1))


def data_range(v) -> tuple[float, float]:
    """A colour scale for the values v: 0 to their 99th percentile (2 significant figures, rounded up)"""
    v = np.asarray(v, float)
    v = v[np.isfinite(v)]
    if not v.size or np.percentile(v, 99) <= 0:
        return 0.0, 1.0
    top = float(np.percentile(v, 99))
    e = math.floor(math.log10(top)) - 1
    return 0.0, float(round(math.ceil(top / 10**e * (1 - 1e-12)) * 10**e, 12))


def heatmaps(q, panels, imagersize, cbmax: float | None = None, points=None, title: str = "",
             ncols: int | None = None, unit: str = "px"):
    """Panels of (title, (Ny, Nx) values) on the pixel grid q (Ny, Nx, 2)

    points: optional list parallel to panels of (n, 2) pixel positions to
    draw on top (e.g. the corners a calibration saw), or None entries.
    cbmax: one colour scale 0..cbmax shared by all panels and one colour bar;
    None: each panel its own scale (data_range) and colour bar, so that a map
    of 0.01-0.03 px shows its structure beside one of 0.3 px.
    """
    W, H = (float(v) for v in imagersize)
    n = len(panels)
    ncols = ncols or min(n, 3)
    nrows = math.ceil(n / ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.2 * ncols + 0.8, 2.9 * nrows + (0.4 if title else 0)),
                             squeeze=False, constrained_layout=True)
    x, y = q[0, :, 0], q[:, 0, 1]
    im = None
    for k, ax in enumerate(axes.ravel()):
        if k >= n:
            ax.axis("off")
            continue
        name, v = panels[k]
        lo, hi = (0.0, cbmax) if cbmax is not None else data_range(v)
        im = ax.pcolormesh(x, y, np.asarray(v, float), vmin=lo, vmax=hi, cmap="viridis", shading="nearest")
        if cbmax is None:
            fig.colorbar(im, ax=ax, shrink=0.9, label=unit)
        finite = np.isfinite(v)
        if finite.any() and np.nanmax(v) > 0:
            if cbmax is None:  # contours inside this panel's own range
                levels = [lv for lv in np.linspace(lo, hi, 6)[1:-1] if np.nanmin(v) < lv < np.nanmax(v)]
            else:
                levels = [lv for lv in np.array((0.1, 0.2, 0.5)) * hi if np.nanmin(v) < lv < np.nanmax(v)]
            if levels:
                cs = ax.contour(x, y, np.asarray(v, float), levels=levels, colors="white", linewidths=0.6)
                ax.clabel(cs, fontsize=6, fmt=lambda t: f"{t:.2g}")
        if points is not None and points[k] is not None and len(points[k]):
            p = np.asarray(points[k])
            ax.plot(p[:, 0], p[:, 1], ",", color="white", alpha=0.5)
        ax.set_xlim(-0.5, W - 0.5)
        ax.set_ylim(H - 0.5, -0.5)
        ax.set_aspect("equal")
        ax.set_title(f"{name}\nmedian {np.nanmedian(v):.3g} {unit}", fontsize=9)
        ax.tick_params(labelsize=7)
    if cbmax is not None:
        fig.colorbar(im, ax=axes.ravel().tolist(), shrink=0.9, label=unit)
    if title:
        fig.suptitle(title, fontsize=10)
    return fig


def per_pose(panels, ylabel: str = "held-out MRE, px"):
    """[(title, {method: {pose name: value or None}})] -> one panel of lines per entry, linear from zero"""
    fig, axes = plt.subplots(len(panels), 1, figsize=(8, 2.9 * len(panels) + 0.3), squeeze=False,
                             constrained_layout=True)
    for ax, (title, series) in zip(axes[:, 0], panels):
        names = sorted({n for s in series.values() for n in s})
        x = np.arange(len(names))
        for k, (method, s) in enumerate(series.items()):
            y = np.array([np.nan if s.get(n) is None else s[n] for n in names], float)
            ax.plot(x, y, "o-", ms=3, lw=1.2, color=colour(method, k), label=method)
        ax.set_xticks(x)
        ax.set_xticklabels(names, rotation=60, fontsize=7)
        ax.set_ylabel(ylabel, fontsize=8)
        ax.set_ylim(bottom=0)
        ax.grid(True, alpha=0.3)
        ax.set_title(title, fontsize=9)
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1), borderaxespad=0)
    return fig


def summary_bars(conditions, panels, ylabel: str):
    """Grouped bars, conditions on x, one bar per method; panels [(title, {method: [v per condition]})]

    A linear axis from zero (bar lengths in proportion to the values), each
    bar's value written above it, the legend to the right of the panels.
    """
    fig, axes = plt.subplots(1, len(panels), figsize=(4.6 * len(panels) + 0.6, 3.4), squeeze=False,
                             constrained_layout=True, sharey=True)
    for ax, (title, values) in zip(axes[0], panels):
        m = len(values)
        width = 0.8 / max(m, 1)
        x = np.arange(len(conditions))
        for k, (method, v) in enumerate(values.items()):
            y = np.array([np.nan if a is None else a for a in v], float)
            xs = x - 0.4 + width * (k + 0.5)
            ok = np.isfinite(y) & (y > 0)
            bars = ax.bar(xs[ok], y[ok], width, color=colour(method, k), label=method)
            ax.bar_label(bars, labels=[f"{t:.3g}" for t in y[ok]], fontsize=6 if m <= 3 else 5, padding=1,
                         rotation=0 if m <= 3 else 90)  # many bars: upright numbers would overlap
            for xi in xs[~ok]:  # no number (no board, failed calibration): a cross on the axis
                ax.plot(xi, 0, "x", color=colour(method, k), transform=ax.get_xaxis_transform(), clip_on=False)
        ax.set_xticks(x)
        ax.set_xticklabels(conditions, fontsize=8)
        ax.margins(y=0.12 if m <= 3 else 0.25)  # room for the values above the bars
        ax.set_ylim(bottom=0)
        ax.grid(True, axis="y", alpha=0.3)
        ax.set_title(title, fontsize=9)
    axes[0, 0].set_ylabel(ylabel, fontsize=8)
    handles, names = axes[0, 0].get_legend_handles_labels()
    axes[0, -1].legend(handles, names, fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1), borderaxespad=0)
    return fig

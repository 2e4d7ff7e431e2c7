"""The validation figures (matplotlib, no display needed)

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.validate.plots import heatmaps, per_pose, summary_bars, nice_max
    >>> q = np.stack(np.meshgrid(np.linspace(0, 1279, 8), np.linspace(0, 799, 5)), -1)
    >>> fig = heatmaps(q, [("diff", np.ones((5, 8))), ("u", np.zeros((5, 8)))], (1280, 800), cbmax=2)
    >>> len(fig.axes)                      # two panels and one colour bar
    3
    >>> fig = per_pose([("calibrated on A, tested on B", {"rotstar": {"p0": 0.1, "p1": 0.2}})])
    >>> fig = summary_bars(["low", "high"], [("A->B", {"rotstar": [0.1, 0.2], "saddle": [0.3, None]})], "MRE, px")
    >>> nice_max(0.0337), nice_max(0.7), nice_max(3.2)
    (0.05, 1.0, 5.0)

Each function returns a matplotlib Figure; the caller saves it
(fig.savefig(path)) and closes it (matplotlib.pyplot.close(fig)).

    heatmaps      panels of values on a pixel grid over the imager (projection
                  diff, uncertainties, error against the truth), one colour
                  scale, optional observed corners on top
    per_pose      held-out mean reprojection error of each test pose, one line
                  per method (the paper's figure)
    summary_bars  one number per method and condition, grouped bars
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


def heatmaps(q, panels, imagersize, cbmax: float | None = None, points=None, title: str = "",
             ncols: int | None = None, unit: str = "px"):
    """Panels of (title, (Ny, Nx) values) on the pixel grid q (Ny, Nx, 2); one colour scale

    points: optional list parallel to panels of (n, 2) pixel positions to
    draw on top (e.g. the corners a calibration saw), or None entries.
    cbmax None: nice_max of the largest 95th percentile.
    """
    W, H = (float(v) for v in imagersize)
    n = len(panels)
    ncols = ncols or min(n, 3)
    nrows = math.ceil(n / ncols)
    if cbmax is None:
        cbmax = nice_max(max(np.nanpercentile(v, 95) for _, v in panels if np.any(np.isfinite(v))))
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.2 * ncols + 0.8, 2.9 * nrows + (0.4 if title else 0)),
                             squeeze=False, constrained_layout=True)
    x, y = q[0, :, 0], q[:, 0, 1]
    im = None
    for k, ax in enumerate(axes.ravel()):
        if k >= n:
            ax.axis("off")
            continue
        name, v = panels[k]
        im = ax.pcolormesh(x, y, np.asarray(v, float), vmin=0, vmax=cbmax, cmap="viridis", shading="nearest")
        finite = np.isfinite(v)
        if finite.any() and np.nanmax(v) > 0:
            levels = [lv for lv in np.array((0.1, 0.2, 0.5)) * cbmax if np.nanmin(v) < lv < np.nanmax(v)]
            if levels:
                cs = ax.contour(x, y, np.asarray(v, float), levels=levels, colors="white", linewidths=0.6)
                ax.clabel(cs, fontsize=6, fmt=lambda t: f"{t:g}")
        if points is not None and points[k] is not None and len(points[k]):
            p = np.asarray(points[k])
            ax.plot(p[:, 0], p[:, 1], ",", color="white", alpha=0.5)
        ax.set_xlim(-0.5, W - 0.5)
        ax.set_ylim(H - 0.5, -0.5)
        ax.set_aspect("equal")
        ax.set_title(f"{name}\nmedian {np.nanmedian(v):.3g} {unit}", fontsize=9)
        ax.tick_params(labelsize=7)
    fig.colorbar(im, ax=axes.ravel().tolist(), shrink=0.9, label=unit)
    if title:
        fig.suptitle(title, fontsize=10)
    return fig


def per_pose(panels, ylabel: str = "held-out MRE, px"):
    """[(title, {method: {pose name: value or None}})] -> one panel of lines per entry"""
    fig, axes = plt.subplots(len(panels), 1, figsize=(7, 2.9 * len(panels) + 0.3), squeeze=False,
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
        ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.3)
        ax.set_title(title, fontsize=9)
        ax.legend(fontsize=7, ncol=3)
    return fig


def summary_bars(conditions, panels, ylabel: str, log: bool = True):
    """Grouped bars, conditions on x, one bar per method; panels [(title, {method: [v per condition]})]"""
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
            ax.bar(xs[ok], y[ok], width, color=colour(method, k), label=method)
            for xi in xs[~ok]:  # no number (no board, failed calibration): a cross on the axis
                ax.plot(xi, 0, "x", color=colour(method, k), transform=ax.get_xaxis_transform(), clip_on=False)
        ax.set_xticks(x)
        ax.set_xticklabels(conditions, fontsize=8)
        if log:
            ax.set_yscale("log")
        ax.grid(True, axis="y", which="both", alpha=0.3)
        ax.set_title(title, fontsize=9)
    axes[0, 0].set_ylabel(ylabel, fontsize=8)
    axes[0, 0].legend(fontsize=7, ncol=2)
    return fig

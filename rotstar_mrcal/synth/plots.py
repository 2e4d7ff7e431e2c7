"""Figures of the experiment (matplotlib, no display needed); the CLI saves them

SYNOPSIS

    >>> import matplotlib
    >>> matplotlib.use("Agg")
    >>> from rotstar_mrcal.synth.experiment import quick_protocol
    >>> from rotstar_mrcal.synth.plots import psf_figure
    >>> fig = psf_figure(quick_protocol())
    >>> len(fig.axes)                        # one panel per aberration
    2

- range_figure: the pairwise-distance range against the tilt phi, one panel
  per aberration, one line per pattern (line style) and refiner (colour), at
  one noise level (the paper's Fig. 4 layout);
- psf_figure: the PSF of every aberration (square root of the kernel, so the
  comet's tail and the halos show), camera pixel grid;
- views_figure: what the refiners see: each pattern at one tilted view
  under each aberration, noise-free (the 16-segment star's centre turns grey
  under blur: its narrow wedges average out, the aliasing the paper argues
  against; the phase pattern's first frame is the fringes along x, step 0).
"""

from __future__ import annotations

import math

import numpy as np
from matplotlib.figure import Figure

from rotstar_mrcal.synth.experiment import Protocol, psf_kernel, render_views

COLOURS = {"opencv": "tab:blue", "saddle": "tab:orange", "symmetric": "tab:green", "phase": "tab:red"}
STYLES = {"checkerboard": "-", "rotstar": "--", "star16": ":", "phase": "-."}
MARKERS = {"checkerboard": "o", "rotstar": "s", "star16": "^", "phase": "D"}
FLOOR = 1e-4  # px: ranges below are drawn at it


def range_figure(protocol: Protocol, rows: list[dict], noise: float) -> Figure:
    """Range against phi at one noise level, rows from table.tabulate"""
    abs_ = list(protocol.aberrations)
    fig = Figure(figsize=(5.2 * len(abs_), 4.2), layout="constrained")
    axes = fig.subplots(1, len(abs_), squeeze=False)[0]
    for ax, a in zip(axes, abs_):
        for pat in protocol.patterns:
            for ref in protocol.refiners:
                pts = sorted((r["phi"], r["range"]) for r in rows
                             if r["aberration"] == a and r["noise"] == noise and r["pattern"] == pat
                             and r["refiner"] == ref and math.isfinite(r["range"]) and r["fail"] < 0.5)
                if pts:
                    x, y = zip(*pts)
                    y = np.maximum(y, FLOOR)  # a log axis has no 0 (the phase corner, noise-free, symmetric PSF)
                    ax.plot(x, y, STYLES.get(pat, "-"), marker=MARKERS.get(pat, "o"), color=COLOURS.get(ref),
                            label=f"{pat} / {ref}", ms=4)
        ax.set_yscale("log")
        ax.set_xlabel("tilt phi [deg]")
        ax.set_title(f"{a}, sigma_n = {noise:g} DN")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("pairwise-distance range [px]")
    axes[-1].legend(fontsize=7, loc="best")
    fig.suptitle(f"Mean pairwise-distance range over the alpha views (failures > 50% not drawn, "
                 f"ranges below {FLOOR:g} px drawn at {FLOOR:g})", fontsize=9)
    return fig


def psf_figure(protocol: Protocol, half_px: float = 8.0) -> Figure:
    """The PSF kernel of every aberration of the protocol"""
    s = protocol.supersample
    fig = Figure(figsize=(3.2 * len(protocol.aberrations), 3.4), layout="constrained")
    axes = fig.subplots(1, len(protocol.aberrations), squeeze=False)[0]
    for ax, a in zip(axes, protocol.aberrations):
        k = psf_kernel(protocol, a)
        c = k.shape[0] // 2
        r = min(c, int(half_px * s))
        ext = (r + 0.5) / s
        ax.imshow(np.sqrt(k[c - r : c + r + 1, c - r : c + r + 1]), cmap="magma", extent=(-ext, ext, ext, -ext))
        spec = protocol.psf_spec(a)
        sub = (f"sigma {spec['sigma_px']:g} px" if spec["kind"] == "gaussian"
               else ", ".join(f"{t} {v:g}" for t, v in spec["seidel"].items() if v and not t.endswith("angle")))
        ax.set_title(f"{a}: {sub}", fontsize=9)
        ax.set_xlabel("x [px]")
    axes[0].set_ylabel("y [px] (sqrt of the PSF)")
    return fig


def views_figure(protocol: Protocol, phi_deg: float = 50.0, alpha_deg: float = 45.0) -> Figure:
    """Each pattern's first frame at one view under each aberration (noise-free)"""
    p = protocol.replace(alphas_deg=(alpha_deg,))
    fig = Figure(figsize=(2.6 * len(p.patterns), 2.6 * len(p.aberrations)), layout="constrained")
    axes = fig.subplots(len(p.aberrations), len(p.patterns), squeeze=False)
    for i, a in enumerate(p.aberrations):
        frames, _ = render_views(p, a, phi_deg)
        for j, pat in enumerate(p.patterns):
            ax = axes[i, j]
            ax.imshow(frames[pat][0, 0], cmap="gray", vmin=p.dark, vmax=p.dark + p.contrast)
            ax.plot(*p.truth, "r+", ms=8)
            ax.set_title(f"{pat}, {a}", fontsize=8)
            ax.set_xticks([])
            ax.set_yticks([])
    fig.suptitle(f"phi = {phi_deg:g}, alpha = {alpha_deg:g} deg; red: the true corner", fontsize=9)
    return fig

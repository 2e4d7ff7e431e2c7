"""Cramer-Rao bounds of the four patterns for one PSF, one view: the physical limit per pattern

SYNOPSIS

    >>> from rotstar_mrcal.optics.psf import gaussian_psf
    >>> from rotstar_mrcal.optics.crlb import closed_form_corner_bound
    >>> from rotstar_mrcal.synth.bound import pattern_bounds
    >>> b = pattern_bounds(gaussian_psf(1.0, 4), 4, window=10, contrast=200.0, sigma_n=2.0)
    >>> round(b["checkerboard"], 4), round(closed_form_corner_bound(2.0, 200.0, 1.0, 10), 4)
    (0.0046, 0.0042)

Per-axis standard deviation sqrt(trace(F^-1) / 2), with one exposure per
distinct frame (checkerboard: 1 frame, rotstar: 8 frames, star16: 1 frame,
phase: 8 fringe frames, whose gradients imaging.fringe_subpixel gives exactly)
and the Fisher information summed over the pixels within `window` of the
corner and over the frames (optics.crlb). This is the quantity tabulated in
refinement.md section 7 (a head-on view; J turns and shears the pattern).
For the experiment's fairness rule (8 exposures per pattern) divide the
checkerboard and star16 values by sqrt(8). The phase bound counts the same
window as the others; the phase refiner fits its planes in 7 x 7 px only
(detect.phase.HALF_WINDOW), so it cannot reach it.

    >>> round(b["phase"], 4), round(b["rotstar"], 4)
    (0.0024, 0.0015)
"""

from __future__ import annotations

import numpy as np

from rotstar_mrcal.optics.crlb import crlb_cov, fisher_information
from rotstar_mrcal.synth.patterns import PATTERNS, PHASE_PERIOD, pattern_frames
from rotstar_mrcal.synth.imaging import ViewRenderer


def pattern_bounds(kernel, s: int, window: int = 10, contrast: float = 200.0, sigma_n: float = 2.0,
                   J=np.eye(2), offset=(0.3, 0.7), patterns=PATTERNS, phase_period=PHASE_PERIOD) -> dict:
    """{pattern: per-axis CRLB std (px)} for the corner seen through linear map J"""
    tile = 2 * int(window) + 10
    apex = np.array((tile // 2 + offset[0], tile // 2 + offset[1]))
    r = ViewRenderer(kernel, s, tile)
    c = np.arange(tile)
    win = (np.abs(c[None, :] - apex[0]) <= window) & (np.abs(c[:, None] - apex[1]) <= window)
    out = {}
    for name in patterns:
        _, g = r([st.mapped(J) for st in pattern_frames(name, phase_period)], apex)
        F = fisher_information((contrast * g[:, win]).reshape(-1, 2), sigma_n)
        out[name] = float(np.sqrt(np.trace(crlb_cov(F)) / 2))
    return out

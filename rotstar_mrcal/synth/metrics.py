"""The experiment's metrics: pairwise-distance range, RMS error, failures

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.synth.metrics import pairwise_range, rms_error
    >>> p = np.array([[[0.0, 0.0], [0.3, 0.4], [0.1, 0.0]],
    ...               [[0.0, 0.0], [np.nan, np.nan], [0.0, 0.2]]])   # 2 repeats x 3 views
    >>> pairwise_range(p)                    # largest distance between two views, per repeat
    array([0.5, 0.2])
    >>> round(float(rms_error(p, np.zeros(2))), 4)
    0.2449

pairwise_range is the paper's metric (4.1): enumerate all pairs of
detections of the same physical corner across the views at one tilt,
take the largest distance. Since camera and corner are fixed, a perfect
refiner would detect the corner at the same image point in every view; the
range measures how much the detection depends on the view. The experiment
averages it over the repeats. Failed detections (NaN) are left out; a set
with fewer than two detections has no range (NaN).
"""

from __future__ import annotations

import numpy as np


def pairwise_range(p: np.ndarray) -> np.ndarray:
    """Largest pairwise distance over the views axis (-2) of p (..., V, 2), ignoring NaN"""
    p = np.asarray(p, float)
    d = np.linalg.norm(p[..., :, None, :] - p[..., None, :, :], axis=-1)
    ok = np.isfinite(p).all(axis=-1)
    enough = ok.sum(axis=-1) >= 2
    d = np.where(ok[..., :, None] & ok[..., None, :], d, -np.inf)
    return np.where(enough, d.max(axis=(-1, -2)), np.nan)


def rms_error(p: np.ndarray, truth: np.ndarray) -> float:
    """sqrt(mean |p - truth|^2) over every finite detection (2-D RMS, pixels)"""
    e = np.sum((np.asarray(p, float) - truth) ** 2, axis=-1)
    e = e[np.isfinite(e)]
    return float(np.sqrt(e.mean())) if e.size else float("nan")


def failure_rate(p: np.ndarray) -> float:
    """Fraction of detections that failed (NaN)"""
    ok = np.isfinite(np.asarray(p, float)).all(axis=-1)
    return float(1.0 - ok.mean()) if ok.size else float("nan")

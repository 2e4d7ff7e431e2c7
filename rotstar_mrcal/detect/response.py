"""Response map: where the display sequence changes (paper 3.2)

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.detect.response import response_map, binarize
    >>> frames = np.zeros((8, 20, 20), np.float32); frames[::2, 5:15, 5:8] = 200
    >>> resp = response_map(frames, smooth_sigma=0)
    >>> mask, threshold = binarize(resp, smooth=1)
    >>> int(mask.sum()), bool(mask[10, 6]), bool(mask[10, 12])
    (30, True, False)

The intensity estimate is the per-pixel maximum over the frames, floored at
1/20 of its global maximum (so that dark pixels do not divide by ~0). The
response is the sum of absolute differences of adjacent frames divided by
that estimate: about (nframes - 1) * contrast on the border bands, which flip
in every frame, and about 1 * contrast inside the elements, where each
pixel is crossed by a rotating checker line at most once.

Binarisation is mean thresholding, iterated (Ridler-Calvard): the threshold
starts at the mean response and moves to the midpoint of the means of the two
classes until it settles. A single global mean is not enough when the board
fills little of the image: the dark background then pulls the mean below the
element interiors.
"""

from __future__ import annotations

import cv2
import numpy as np

FLOOR_FRACTION = 1 / 20


def pixel_noise(frames: np.ndarray) -> float:
    """Robust standard deviation of one pixel, from horizontal neighbour differences of two frames

    At least 0.3, the quantisation's.
    """
    d = np.diff(np.asarray(frames[:2, ::8, :], np.float32), axis=-1)
    return max(float(np.median(np.abs(d - np.median(d)))) * 1.4826 / np.sqrt(2), 0.3)


def intensity_estimate(frames: np.ndarray) -> np.ndarray:
    """Per-pixel maximum over frames, floored at 1/20 of the global maximum"""
    m = frames[0].copy()
    for f in frames[1:]:
        cv2.max(m, f, dst=m)  # the same maximum as frames.max(axis=0), without numpy's strided reduction
    return _floor(m)


def _floor(m: np.ndarray) -> np.ndarray:
    return np.maximum(m, FLOOR_FRACTION * float(m.max()) + 1e-12)


def response_map(frames: np.ndarray, smooth_sigma: float = 1.0) -> np.ndarray:
    """Accumulated |frame[k+1] - frame[k]|, divided by the intensity estimate

    frames: (nframes, H, W) in any units. Returns (H, W) float32. Each frame
    is smoothed by a Gaussian of smooth_sigma px first: noise in dark regions,
    divided by the floored intensity estimate, would otherwise reach the level
    of the bands (the response only needs to find the bands, a few px wide).
    One smoothed frame at a time (two buffers), with OpenCV's element-wise
    operations: the same numbers as smoothing the whole stack first.
    """
    f = np.asarray(frames, np.float32)
    acc = np.zeros(f.shape[1:], np.float32)
    if len(f) == 0:
        return acc
    prev, cur = np.empty_like(acc), np.empty_like(acc)
    diff = np.empty_like(acc)

    def smoothed(k, dst):
        if smooth_sigma > 0:
            return cv2.GaussianBlur(f[k], (0, 0), smooth_sigma, dst=dst)
        return f[k]

    prev = smoothed(0, prev)
    m = prev.copy()
    for k in range(1, len(f)):
        cur = smoothed(k, cur)
        cv2.absdiff(cur, prev, dst=diff)
        acc += diff
        cv2.max(m, cur, dst=m)
        prev, cur = cur, prev
    return acc / _floor(m)


def mean_threshold(values: np.ndarray, bins: int = 1024, max_iter: int = 100) -> float:
    """Iterated mean threshold (Ridler-Calvard / isodata) of an array

    Computed on a fine histogram, so each iteration costs O(bins).
    """
    v = np.asarray(values, np.float32).ravel()
    lo_v, hi_v = float(v.min()), float(v.max())
    if hi_v <= lo_v:
        return hi_v
    count, edges = np.histogram(v, bins=bins, range=(lo_v, hi_v))
    centre = 0.5 * (edges[1:] + edges[:-1])
    csum, msum = np.cumsum(count), np.cumsum(count * centre)
    t = float(v.mean())
    for _ in range(max_iter):
        k = int(np.clip(np.searchsorted(centre, t, side="right") - 1, 0, bins - 2))
        n_lo, n_hi = csum[k], csum[-1] - csum[k]
        if n_lo == 0 or n_hi == 0:
            break
        t_new = 0.5 * (msum[k] / n_lo + (msum[-1] - msum[k]) / n_hi)
        if abs(t_new - t) < 0.5 * (hi_v - lo_v) / bins:
            t = t_new
            break
        t = t_new
    return float(t)


def binarize(resp: np.ndarray, smooth: int = 3) -> tuple[np.ndarray, float]:
    """Binary image of the border bands: (mask uint8 0/1, threshold)

    The response is box-filtered (smooth x smooth) first, which suppresses
    isolated noisy pixels without moving the band edges.
    """
    r = cv2.blur(resp, (smooth, smooth)) if smooth > 1 else resp
    t = mean_threshold(r)
    return (r > t).astype(np.uint8), t

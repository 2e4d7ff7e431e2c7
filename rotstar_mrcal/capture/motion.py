"""Is the view still? Frame differences and a sub-pixel shift estimate

SYNOPSIS

    >>> import numpy as np, cv2
    >>> from rotstar_mrcal.capture.motion import difference_signal, image_shift
    >>> rng = np.random.default_rng(0)
    >>> a = cv2.GaussianBlur(rng.random((120, 160)).astype(np.float32), (0, 0), 3) * 4
    >>> b = cv2.warpAffine(a, np.float32([[1, 0, 0.3], [0, 1, -0.2]]), (160, 120))
    >>> np.round(image_shift(a, b), 2)
    array([ 0.3, -0.2])
    >>> d, m = difference_signal(np.stack([a, a, b]), full_scale=1.0)
    >>> bool(np.isnan(d[0])), bool(d[1] == 0), bool(d[2] > 0)
    (True, True, True)

difference_signal is what segmentation cuts on: the mean absolute
difference between consecutive frames (area-downsampled by `step`, as a
fraction of full scale), plus each frame's mean level. The rotating-star
frames all have nearly the same mean, so levels alone cannot separate them;
consecutive display frames differ everywhere on the board, so the difference
spikes at every change and sits at the noise floor in between.

Both are taken over the pixels the player changes (screen_pixels: those
whose range over the recording is a good part of the largest range), not
over the whole image: a board far from the camera covers a few per cent of
the image, and averaged over the whole image the change between two identity
frames (about half of the elements flip, a quarter of the board's area) sinks
into the noise of the room around the screen (a D435 with the default board
at 0.6 m: barely above segmentation's threshold; at 0.9 m below it). Over
the screen's pixels it is many times the noise at any distance
(tests/capture/test_segment.py, the board's corners on 1 % of the image).

image_shift measures how far the image moved between two (averaged)
frames of the same display frame: one Lucas-Kanade step for a translation
plus a gain and an offset, solved by least squares on the smoothed image.
It is linear, so it is accurate for the sub-pixel drift it is meant to catch
and an underestimate (still large) for big motion. (An affine flow was
tried: its extra terms, extrapolated to the image corners from a board that
covers part of the image, turned noise into apparent motion.)
"""

from __future__ import annotations

import cv2
import numpy as np


def downsample(img: np.ndarray, step: int) -> np.ndarray:
    """Area-average step x step blocks, float32"""
    f = np.asarray(img, np.float32)
    if step <= 1:
        return f
    H, W = f.shape
    return cv2.resize(f[: H - H % step, : W - W % step], (W // step, H // step), interpolation=cv2.INTER_AREA)


def screen_pixels(frames, full_scale: float, step: int = 4, fraction: float = 0.25,
                  min_pixels: int = 64) -> np.ndarray | None:
    """(H // step, W // step) bool: the downsampled pixels the player changes, or None (all of them)

    A pixel belongs to the screen when its range over the recording (max -
    min) is at least `fraction` of the largest range (the 99th percentile,
    so that a few hot pixels do not set it). The room around a still screen
    only shows noise; the screen goes from the black start marker to its
    brightest frame. None when fewer than min_pixels qualify, or nearly all
    do (a recording of noise alone): then the whole image is used.

    SYNOPSIS

        >>> rng = np.random.default_rng(0)
        >>> f = 100 + rng.normal(0, 2, (6, 100, 100))       # the room: noise
        >>> f[::2, 20:60, 40:80] += 5000                    # the screen flips in a 40 x 40 patch
        >>> m = screen_pixels(f, 65535)
        >>> m.shape, int(m.sum()), bool(m[10, 15]), bool(m[0, 0])
        ((25, 25), 100, True, False)
    """
    lo = hi = None
    for t in range(len(frames)):
        cur = downsample(frames[t], step)
        if lo is None:
            lo, hi = cur.copy(), cur.copy()
        else:
            np.minimum(lo, cur, out=lo)
            np.maximum(hi, cur, out=hi)
    if lo is None:
        return None
    span = hi - lo
    mask = span >= fraction * float(np.percentile(span, 99))
    if mask.sum() < min_pixels or mask.mean() > 0.95:
        return None
    return mask


def difference_signal(frames, full_scale: float, step: int = 4,
                      mask: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(d, level): d[t] = mean |f_t - f_(t-1)| / full_scale (d[0] = NaN), level[t] = mean f_t / full_scale

    frames: anything indexable by frame number giving (H, W) arrays (an
    array, a np.memmap, a lazy reader), read once, in order. mask: the
    downsampled pixels to average over (screen_pixels); None: all.
    """
    n = len(frames)
    d = np.full(n, np.nan)
    level = np.empty(n)
    prev = None
    for t in range(n):
        cur = downsample(frames[t], step)
        if mask is not None:
            cur = cur[mask]
        level[t] = float(cur.mean()) / full_scale
        if prev is not None:
            d[t] = float(np.mean(np.abs(cur - prev))) / full_scale
        prev = cur
    return d, level


def noise_floor(frame: np.ndarray, full_scale: float, step: int = 4, mask: np.ndarray | None = None) -> float:
    """What difference_signal reads between two frames of a still view: the sensor noise alone

    The noise sigma comes from the frame itself: the median absolute
    difference of horizontal neighbours (edges are a minority) is
    0.6745 * sqrt(2) sigma, with sigma at least the quantisation noise
    (0.29 of a code). Two step x step block means then differ by
    sqrt(2/pi) sqrt(2) sigma / step = 1.128 sigma / step on average.
    mask: the downsampled pixels difference_signal averages over (the
    noise of a bright screen is not that of a dark room); None: all.

    SYNOPSIS

        >>> rng = np.random.default_rng(1)
        >>> f = 1000 + 20 * rng.standard_normal((200, 300))
        >>> g = 1000 + 20 * rng.standard_normal((200, 300))
        >>> d, _ = difference_signal(np.stack([f, g]), 65535)
        >>> round(float(d[1] / noise_floor(f, 65535)), 1)
        1.0
    """
    f = np.asarray(frame, np.float32)
    diffs = np.abs(np.diff(f, axis=1))
    if mask is not None:
        s = max(step, 1)
        full = np.repeat(np.repeat(mask, s, axis=0), s, axis=1)
        pairs = full[:, 1:] & full[:, :-1]
        inside = diffs[: pairs.shape[0], : pairs.shape[1]][pairs]
        diffs = inside if inside.size >= 100 else diffs
    sigma = float(np.median(diffs)) / (0.6745 * np.sqrt(2))
    sigma = max(sigma, 0.29)
    return 1.128 * sigma / max(step, 1) / full_scale


def image_shift(a: np.ndarray, b: np.ndarray, smooth: float = 1.5, step: int = 1) -> np.ndarray:
    """(dx, dy) in pixels such that b(x) ~ gain * a(x - (dx, dy)) + offset

    One Lucas-Kanade step on the smoothed images, with a gain and an offset
    (the screen's brightness may flicker), solved by least squares; accurate
    for sub-pixel shifts, an underestimate for large ones. step > 1
    area-downsamples first (faster; the shift of an edge survives block
    averaging); the result is in full-size pixels.
    """
    a = cv2.GaussianBlur(downsample(a, step), (0, 0), smooth)
    b = cv2.GaussianBlur(downsample(b, step), (0, 0), smooth)
    H, W = a.shape
    gy, gx = np.gradient(a)
    e = 4  # keep away from the border, where the blur and gradients are one-sided
    sl = (slice(e, H - e), slice(e, W - e))
    A = np.stack([c[sl].ravel() for c in (gx, gy, a, np.ones_like(a))], axis=1).astype(np.float64)
    r = (a - b)[sl].ravel().astype(np.float64)  # a - b = grad(a) . shift - (gain - 1) a - offset
    scale = np.sqrt(np.sum(A * A, axis=0))
    scale[scale == 0] = 1
    p, *_ = np.linalg.lstsq(A / scale, r, rcond=None)
    return p[:2] / scale[:2] * max(step, 1)


def still_fraction(d: np.ndarray, tau: float) -> float:
    """Fraction of frame-to-frame differences below the stability threshold"""
    v = d[np.isfinite(d)]
    return float(np.mean(v < tau)) if len(v) else 0.0


def is_still(d: np.ndarray, tau: float, min_fraction: float = 0.7) -> bool:
    """The view is still: most consecutive frames equal up to noise

    While the player loops, a still camera sees a change only at each of its
    frame changes (one or two camera frames in ten or more); a moving camera
    sees a change in nearly every frame.
    """
    return still_fraction(d, tau) >= min_fraction

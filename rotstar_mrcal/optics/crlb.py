"""The Cramer-Rao lower bound of a corner position from the pixels that see it

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.optics.crlb import fisher_information, crlb_rms, closed_form_corner_bound
    >>> g = np.array([[1.0, 0.0], [0.0, 2.0], [0.0, 0.0]])     # d mu_i / d q of 3 pixels
    >>> F = fisher_information(g, sigma=0.5)
    >>> F
    array([[ 4.,  0.],
           [ 0., 16.]])
    >>> round(crlb_rms(F), 4)                                  # sqrt(1/4 + 1/16)
    0.559
    >>> round(closed_form_corner_bound(2.0, 200.0, 1.0, 10), 5)
    0.00421

Pixel i sees mu_i(q) + n_i with independent n_i ~ N(0, sigma_i^2). The
Fisher information of the 2-D position q is

    F = sum_i g_i g_i^T / sigma_i^2,        g_i = d mu_i / d q,

summed over the refinement window and every frame of the pattern (frames
with independent noise add their information; a frame averaged from K
captures has sigma / sqrt(K)). Any unbiased estimator has Cov(q_hat) >= F^-1:
crlb_rms is sqrt(trace F^-1), the bound on the 2-D RMS error, crlb_cov the
matrix. Contrast, offset and blur are taken as known (the position block of
a larger Fisher matrix is only slightly worse for a point-symmetric corner,
whose position decouples from them); refinement.md section 7.

g_i must be the pixel-integrated gradient of the blurred pattern (synth.imaging
computes it from the exact edge measure of the pattern), not a finite
difference of a hard-edged render.

Closed form (refinement.md 7): a checker corner of contrast C blurred by a
Gaussian of sigma_b, seen through a window of half-size W: each of its two
edge lines (length 2W) gives C^2 W / (sqrt(pi) sigma_b sigma_n^2) to the
Fisher entry of its normal, so per axis

    sigma_q = sigma_n / C * sqrt(sqrt(pi) sigma_b / W).
"""

from __future__ import annotations

import math

import numpy as np


def fisher_information(g: np.ndarray, sigma) -> np.ndarray:
    """F = sum_i g_i g_i^T / sigma_i^2: g (..., M, 2), sigma broadcasting to (..., M) -> (..., 2, 2)"""
    g = np.asarray(g, float)
    w = 1.0 / np.broadcast_to(np.asarray(sigma, float), g.shape[:-1]) ** 2
    return np.einsum("...m,...mi,...mj->...ij", w, g, g)


def crlb_cov(F: np.ndarray) -> np.ndarray:
    """F^-1, (..., 2, 2); inf where F is singular (no information, e.g. sigma = inf)"""
    F = np.asarray(F, float)
    det = F[..., 0, 0] * F[..., 1, 1] - F[..., 0, 1] * F[..., 1, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.stack((np.stack((F[..., 1, 1], -F[..., 0, 1]), -1),
                        np.stack((-F[..., 1, 0], F[..., 0, 0]), -1)), -2) / det[..., None, None]
    return np.where((det > 0)[..., None, None], inv, np.inf)


def crlb_rms(F: np.ndarray):
    """sqrt(trace F^-1): the bound on the 2-D RMS position error (pixels)"""
    c = crlb_cov(F)
    out = np.sqrt(c[..., 0, 0] + c[..., 1, 1])
    return float(out) if np.ndim(out) == 0 else out


def closed_form_corner_bound(sigma_n: float, contrast: float, sigma_b: float, window: float) -> float:
    """Per-axis bound sigma_n / C * sqrt(sqrt(pi) sigma_b / W) for a Gaussian-blurred checker corner"""
    return sigma_n / contrast * math.sqrt(math.sqrt(math.pi) * sigma_b / window)

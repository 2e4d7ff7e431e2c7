"""Point-spread functions applied to the supersampled camera image

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.optics.blur import as_psf, gaussian_kernel
    >>> k = gaussian_kernel(1.0, 4)          # sigma 1 camera pixel at 4x4 supersampling
    >>> k.shape, round(float(k.sum()), 12)
    ((33, 33), 1.0)
    >>> psf = as_psf(1.0, 4)                 # what the renderer does with psf=1.0
    >>> img = np.zeros((1, 64, 64), np.float32); img[0, 32, 32] = 1
    >>> out = psf(img, (0, 0), 4)
    >>> out.shape, round(float(out.sum()), 6)
    ((1, 64, 64), 1.0)

The renderer samples the screen on a grid of s x s sub-pixels per camera
pixel, applies the PSF to that supersampled image, then averages each s x s
block into one camera pixel. A PSF is therefore an operation on supersampled
images. The renderer's `psf` argument may be:

- None or 0: no blur;
- a number: a Gaussian of that sigma in *camera pixels* (GaussianPSF);
- a 2-D array: a kernel at sub-pixel resolution (one tap per sub-pixel, odd
  sizes, centred; it is normalised to sum 1) (KernelPSF). Orientation: tap
  [r, c] is the light that lands (r - h//2, c - w//2) sub-pixels (down,
  right) of where it would land without blur; this is a true convolution, so
  an asymmetric (coma-like) kernel is not mirrored;
- any callable `psf(sub, origin, s) -> array` with a `radius_px` attribute:
  sub is the (nframes, H*s, W*s) float32 supersampled irradiance of the
  rendered region, origin = (x0, y0) the camera pixel of its top-left block,
  s the supersampling. `subpixel_centres(sub.shape, origin, s)` gives the
  image coordinates of its samples, so a callable can vary the PSF over the
  field. radius_px (camera pixels) is how far the PSF spreads light; the
  renderer renders that margin around the screen. A callable without
  radius_px gets DEFAULT_RADIUS_PX.

Field-varying PSFs (aberrations): TiledPSF(kernel_at, tile_px) cuts the region
into tiles of tile_px camera pixels and convolves each tile with the kernel
kernel_at(x, y, s) of the tile's centre (x, y), reading the neighbouring tiles
for its margin. The PSF is piecewise constant over tiles (seams are a
tile-to-tile PSF change, not a discontinuity in the image content). A wavefront
(Seidel/Zernike) model from the paper, H = |F(exp(2 pi i W))|^2 sampled at the
sub-pixel pitch, plugs in as kernel_at.
"""

from __future__ import annotations

import math
from typing import Callable

import cv2
import numpy as np

DEFAULT_RADIUS_PX = 4.0


def normalize_kernel(kernel) -> np.ndarray:
    """A float64 copy of a PSF kernel scaled to sum 1; ValueError if unusable

    SYNOPSIS

        >>> normalize_kernel([[0, 1, 0], [1, 4, 1], [0, 1, 0]]).sum()
        np.float64(1.0)
    """
    k = np.array(kernel, dtype=float)
    if k.ndim != 2 or k.shape[0] % 2 == 0 or k.shape[1] % 2 == 0:
        raise ValueError(f"a PSF kernel must be 2-D with odd sizes (it is centred), not {k.shape}")
    if not np.all(np.isfinite(k)):
        raise ValueError("PSF kernel has non-finite values")
    total = k.sum()
    if not total > 0:
        raise ValueError("PSF kernel must have a positive sum")
    return k / total


def gaussian_taps(sigma_px: float, s: int, truncate: float = 4.0) -> np.ndarray:
    """1-D Gaussian sampled at sub-pixel centres, sigma in camera pixels, sum 1"""
    sig = sigma_px * s
    r = max(1, int(math.ceil(truncate * sig)))
    t = np.arange(-r, r + 1, dtype=float)
    g = np.exp(-0.5 * (t / sig) ** 2)
    return g / g.sum()


def gaussian_kernel(sigma_px: float, s: int, truncate: float = 4.0) -> np.ndarray:
    """2-D Gaussian kernel at sub-pixel resolution, sigma in camera pixels"""
    g = gaussian_taps(sigma_px, s, truncate)
    return np.outer(g, g)


def convolve(img: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """True 2-D convolution of (..., H, W) images, replicated borders

    Rank-1 (separable) kernels use cv2.sepFilter2D, others cv2.filter2D (which
    switches to a DFT for large kernels).
    """
    k = np.asarray(kernel, float)[::-1, ::-1]
    total = k.sum()
    ky, kx = k.sum(axis=1), k.sum(axis=0)
    # rank 1 <=> the outer product of its marginals (a PSF's sum is not 0); an SVD per tile cost more
    separable = total > 0 and np.abs(np.outer(ky, kx / total) - k).max() <= 1e-12 * np.abs(k).max()
    img = np.asarray(img)
    dt = img.dtype if img.dtype in (np.float32, np.float64) else np.float64
    flat = np.ascontiguousarray(img.reshape((-1,) + img.shape[-2:]), dtype=dt)
    out = np.empty_like(flat)
    if separable:
        ky, kx = ky.astype(dt), (kx / total).astype(dt)
    for n in range(flat.shape[0]):
        if separable:
            cv2.sepFilter2D(flat[n], -1, kx, ky, dst=out[n], borderType=cv2.BORDER_REPLICATE)
        else:
            cv2.filter2D(flat[n], -1, k.astype(dt), dst=out[n], borderType=cv2.BORDER_REPLICATE)
    return out.reshape(img.shape)


def subpixel_centres(shape, origin, s: int) -> tuple[np.ndarray, np.ndarray]:
    """Image coordinates (x, y) of the sample centres of a supersampled region

    shape (..., H*s, W*s), origin = (x0, y0) camera pixel of the top-left
    block. Returns x of shape (W*s,) and y of shape (H*s,).
    """
    x0, y0 = origin
    x = x0 - 0.5 + (np.arange(shape[-1]) + 0.5) / s
    y = y0 - 0.5 + (np.arange(shape[-2]) + 0.5) / s
    return x, y


class IdentityPSF:
    """No blur"""

    radius_px = 0.0

    def __call__(self, sub, origin, s):
        return sub

    def describe(self):
        return {"kind": "none"}


class KernelPSF:
    """A fixed kernel given at sub-pixel resolution (normalised to sum 1)"""

    def __init__(self, kernel):
        self.kernel = normalize_kernel(kernel)

    def radius_for(self, s: int) -> float:
        return max(self.kernel.shape) // 2 / s

    def __call__(self, sub, origin, s):
        return convolve(sub, self.kernel)

    def describe(self):
        return {"kind": "kernel", "shape": list(self.kernel.shape)}


class GaussianPSF:
    """Isotropic Gaussian blur of sigma_px camera pixels"""

    def __init__(self, sigma_px: float, truncate: float = 4.0):
        if not sigma_px > 0:
            raise ValueError(f"Gaussian PSF sigma must be > 0, not {sigma_px}")
        self.sigma_px = float(sigma_px)
        self.truncate = truncate
        self.radius_px = truncate * self.sigma_px

    def __call__(self, sub, origin, s):
        return convolve(sub, gaussian_kernel(self.sigma_px, s, self.truncate))

    def describe(self):
        return {"kind": "gaussian", "sigma_px": self.sigma_px}


class TiledPSF:
    """A PSF that varies over the field: one kernel per tile of tile_px pixels

    kernel_at(x, y, s) returns the (odd-sized, sub-pixel resolution) kernel at
    image point (x, y); radius_px bounds the spread of every kernel.

    SYNOPSIS

        >>> import numpy as np
        >>> from rotstar_mrcal.optics.blur import TiledPSF, gaussian_kernel
        >>> psf = TiledPSF(lambda x, y, s: gaussian_kernel(0.5 + x / 200, s), tile_px=16, radius_px=4)
        >>> psf(np.ones((1, 128, 128), np.float32), (0, 0), 4).mean().round(6)
        np.float32(1.0)
    """

    def __init__(self, kernel_at: Callable, tile_px: int = 64, radius_px: float = DEFAULT_RADIUS_PX):
        self.kernel_at = kernel_at
        self.tile_px = int(tile_px)
        self.radius_px = float(radius_px)

    def __call__(self, sub, origin, s):
        out = np.empty_like(sub)
        H, W = sub.shape[-2:]
        T = self.tile_px * s
        x, y = subpixel_centres(sub.shape, origin, s)
        for r0 in range(0, H, T):
            for c0 in range(0, W, T):
                k = normalize_kernel(self.kernel_at(x[min(c0 + T // 2, W - 1)], y[min(r0 + T // 2, H - 1)], s))
                m = max(k.shape) // 2
                a0, b0 = max(r0 - m, 0), max(c0 - m, 0)
                win = convolve(sub[..., a0 : min(r0 + T + m, H), b0 : min(c0 + T + m, W)], k)
                out[..., r0 : r0 + T, c0 : c0 + T] = win[..., r0 - a0 : r0 - a0 + T, c0 - b0 : c0 - b0 + T]
        return out

    def describe(self):
        return {"kind": "tiled", "tile_px": self.tile_px}


def as_psf(psf, s: int):
    """Turn the renderer's psf argument into a callable with radius_px (camera pixels)"""
    if psf is None or (np.isscalar(psf) and float(psf) == 0):
        return IdentityPSF()
    if np.isscalar(psf):
        return GaussianPSF(float(psf))
    if isinstance(psf, (np.ndarray, list, tuple)):
        return KernelPSF(psf)
    if callable(psf):
        return psf
    raise TypeError(f"psf must be None, a sigma in pixels, a 2-D kernel or a callable, not {type(psf).__name__}")


def psf_radius(psf, s: int) -> float:
    """How far (camera pixels) a PSF from as_psf spreads light at supersampling s"""
    if hasattr(psf, "radius_for"):
        return float(psf.radius_for(s))
    return float(getattr(psf, "radius_px", DEFAULT_RADIUS_PX))


def describe_psf(psf) -> dict:
    """A JSON-able description of a psf argument (for the truth file)"""
    p = as_psf(psf, 1)
    return p.describe() if hasattr(p, "describe") else {"kind": "callable", "repr": repr(psf)}

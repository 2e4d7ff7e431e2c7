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

Field-varying PSFs (aberrations): SmoothPSF(kernel_at, node_px) spreads the
light of every point by the bilinear blend of the kernels kernel_at(x, y, s)
at the 4 nearest nodes of a grid anchored to the image, so the PSF changes
continuously over the field, as a lens's does; it also renders the camera
pixels directly (a `pixels(sub, origin, s)` method, which the renderer uses
when a PSF has one). TiledPSF(kernel_at, tile_px) cuts the region into tiles
of tile_px camera pixels and convolves each tile with the kernel of the
tile's centre (x, y), reading the neighbouring tiles for its margin: the PSF
is piecewise constant over tiles that start at the region's corner. A
wavefront (Seidel/Zernike) model from the paper, H = |F(exp(2 pi i W))|^2
sampled at the sub-pixel pitch, plugs in as kernel_at.
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


class SmoothPSF:
    """A PSF that varies continuously over the field, as a lens's does: the nodes' kernels blended bilinearly

    kernel_at(x, y, s) returns the (odd-sized, sub-pixel resolution) kernel
    at image point (x, y), as for TiledPSF. The light of a sub-pixel at
    (x, y) is spread by sum_i w_i(x, y) K_i over the 4 nearest nodes of a
    grid anchored to the image (node (a, b) at the pixel corner
    (a node_px - 0.5, b node_px - 0.5)), w_i the tents
    (1 - |x - x_i| / node_px) (1 - |y - y_i| / node_px). So every point's
    PSF is a proper one (unit sum, its centroid the blend of the nodes'
    centroids), it changes continuously from point to point, and it does
    not depend on the region rendered (TiledPSF's tiles start at the
    region's corner, so their seams move with the pose). The region's
    border is replicated outward by radius_px, as convolve does.

    `pixels(sub, origin, s)` gives the camera pixels (the s x s block means
    the renderer takes) directly, cell by cell (the squares between 4
    nodes): within a cell the weights are bilinear in the source point, and
    sum_y u(y) K(x - y) S(y) = u(x) (K * S)(x) - (t_x K * S)(x) / node_px
    (t = x - y, u linear), so the cell's light is 4 convolutions of the
    UNWEIGHTED cell (kernels of the nodes' kernels and their moments)
    weighted by 1, u, v, uv at the output pixel; each is taken at the pixel
    rate (every sub-pixel phase with its share of the kernel under the
    pixel box) and summed over the phases in the Fourier domain: one
    forward transform of the supersampled cell, 4 small inverse ones.
    Exact (as `__call__`, the plain reference: 4 supersampled convolutions
    per sub-pixel, then the block means) to float32 rounding. Kernels are
    cached per node and cell.

    SYNOPSIS

        >>> import numpy as np
        >>> from rotstar_mrcal.optics.blur import SmoothPSF, gaussian_kernel
        >>> psf = SmoothPSF(lambda x, y, s: gaussian_kernel(0.5 + x / 200, s), node_px=16, radius_px=4)
        >>> flat = psf.pixels(np.ones((1, 128, 128), np.float32), (0, 0), 4)
        >>> bool(np.abs(flat - 1).max() < 2e-4)  # (the blend's kinks at the nodes: 1.5e-4 where the width changes)
        True
        >>> sub = np.random.default_rng(0).random((2, 128, 96)).astype(np.float32)
        >>> ref = psf(sub, (3, -2), 4).reshape(2, 32, 4, 24, 4).mean(axis=(2, 4))
        >>> bool(np.abs(psf.pixels(sub, (3, -2), 4) - ref).max() < 1e-5)
        True
    """

    def __init__(self, kernel_at: Callable, node_px: int = 64, radius_px: float = DEFAULT_RADIUS_PX):
        self.kernel_at = kernel_at
        self.node_px = int(node_px)
        self.radius_px = float(radius_px)
        self._kernels: dict = {}

    def node_kernel(self, a: int, b: int, s: int) -> np.ndarray:
        """The normalised kernel of node (a, b) (image point (a node_px - 0.5, b node_px - 0.5)), cached"""
        key = (a, b, s)
        if key not in self._kernels:
            N = self.node_px
            self._kernels[key] = normalize_kernel(self.kernel_at(a * N - 0.5, b * N - 0.5, s))
        return self._kernels[key]

    def _corners(self, a: int, b: int, s: int) -> list[np.ndarray]:
        """The kernels of cell (a, b)'s nodes (a, b), (a+1, b), (a, b+1), (a+1, b+1), centred in one odd square"""
        ks = [self.node_kernel(a + i, b + j, s) for j in (0, 1) for i in (0, 1)]
        n = max(max(k.shape) for k in ks)
        out = np.zeros((4, n, n))
        for i, k in enumerate(ks):
            r, c = (n - k.shape[0]) // 2, (n - k.shape[1]) // 2
            out[i, r : r + k.shape[0], c : c + k.shape[1]] = k
        return list(out)

    def local_kernel(self, x: float, y: float, s: int) -> np.ndarray:
        """The PSF of the light from image point (x, y): its 4 nodes' kernels blended"""
        N = self.node_px
        a, b = math.floor((x + 0.5) / N), math.floor((y + 0.5) / N)
        u, v = (x + 0.5) / N - a, (y + 0.5) / N - b
        k00, k10, k01, k11 = self._corners(a, b, s)
        return (1 - u) * (1 - v) * k00 + u * (1 - v) * k10 + (1 - u) * v * k01 + u * v * k11

    def _cell_kernels(self, a: int, b: int, s: int):
        """((4, s, s, D + 1, D + 1) float32, dlo): cell (a, b)'s polyphase taps for the output weights 1, u, v, uv

        Camera pixel Y of weight term j gets sum over the phases p (sub-pixel rows s U + p) of
        S_p[U] G[j, p][Y - U - dlo] (and likewise along x).
        """
        key = ("cell", a, b, s)
        if key in self._kernels:
            return self._kernels[key]
        N = self.node_px
        k00, k10, k01, k11 = self._corners(a, b, s)
        n = k00.shape[0]
        t = (np.arange(n) - n // 2) / s / N  # tap offsets x - y in node spacings
        tx, ty = t[None, :], t[:, None]
        C00, C10, C01, C11 = k00, k10 - k00, k01 - k00, k00 - k10 - k01 + k11
        M00 = C00 - tx * C10 - ty * C01 + tx * ty * C11
        M10, M01, M11 = C10 - ty * C11, C01 - tx * C11, C11
        d = ((np.arange(s) + 0.5) / s - 0.5) / N  # sub-pixel offsets from the pixel centre, node spacings
        one = np.ones(s)

        def boxed(M, fx, fy):  # (1/s^2) sum over the block's sub-pixels of f(dx, dy) (M * S): taps (n+s-1)^2
            out = np.zeros((n + s - 1, n + s - 1))
            for i in range(s):
                for j in range(s):
                    out[s - 1 - i : s - 1 - i + n, s - 1 - j : s - 1 - j + n] += fy[i] * fx[j] * M / s**2
            return out

        E = [boxed(M00, one, one) + boxed(M10, d, one) + boxed(M01, one, d) + boxed(M11, d, d),
             boxed(M10, one, one) + boxed(M11, one, d), boxed(M01, one, one) + boxed(M11, d, one),
             boxed(M11, one, one)]
        L, c = n + s - 1, n // 2 + s - 1
        dlo, dhi = -(c // s), (L - 1) // s
        idx = s * np.arange(dlo, dhi + 1)[None, :] + c - np.arange(s)[:, None]  # (phase, d) -> tap
        ok = ((idx >= 0) & (idx < L)).astype(float)
        idx = np.clip(idx, 0, L - 1)
        G = np.stack([np.stack([np.stack([e[np.ix_(idx[p], idx[q])] * ok[p][:, None] * ok[q][None, :]
                                          for q in range(s)]) for p in range(s)]) for e in E]).astype(np.float32)
        self._kernels[key] = (G, dlo)
        return G, dlo

    def pixels(self, sub, origin, s):
        """(..., H, W) camera pixels of the blurred supersampled region sub (..., H s, W s) at origin (x0, y0)"""
        # (here, not at the top: scipy.fft costs 0.6 s of start-up; its float32 transforms are 2x numpy's)
        import scipy.fft

        lead, (Hs, Ws) = sub.shape[:-2], sub.shape[-2:]
        flat = np.asarray(sub, np.float32).reshape((-1, Hs, Ws))
        H, W, F, N = Hs // s, Ws // s, flat.shape[0], self.node_px
        x0, y0 = origin
        m = int(math.ceil(self.radius_px)) + 1
        cells = [(a, b) for b in range(math.floor((y0 - m) / N), math.floor((y0 + H - 1 + m) / N) + 1)
                 for a in range(math.floor((x0 - m) / N), math.floor((x0 + W - 1 + m) / N) + 1)]
        parts, reach, far = [], m, (H, W)
        for a, b in cells:
            X0, X1 = max(a * N, x0 - m), min(a * N + N, x0 + W + m)  # image pixels of the cell in the region
            Y0, Y1 = max(b * N, y0 - m), min(b * N + N, y0 + H + m)
            G, dlo = self._cell_kernels(a, b, s)
            D = G.shape[-1] - 1
            rows = np.clip(np.arange((Y0 - y0) * s, (Y1 - y0) * s), 0, Hs - 1)
            cols = np.clip(np.arange((X0 - x0) * s, (X1 - x0) * s), 0, Ws - 1)
            h, w = Y1 - Y0, X1 - X0
            blk = flat[:, rows][:, :, cols].reshape(F, h, s, w, s).transpose(2, 4, 0, 1, 3)  # (s, s, F, h, w)
            shape = (scipy.fft.next_fast_len(h + D, True), scipy.fft.next_fast_len(w + D, True))
            Sf = scipy.fft.rfft2(blk, shape)
            Gf = scipy.fft.rfft2(G, shape)  # (4, s, s, ...)
            R = scipy.fft.irfft2(np.einsum("pqfyx,jpqyx->jfyx", Sf, Gf), shape)[:, :, : h + D, : w + D]
            uX = (np.arange(X0 + dlo, X0 + dlo + w + D) + 0.5) / N - a  # the output pixels' u, v in the cell
            vY = ((np.arange(Y0 + dlo, Y0 + dlo + h + D) + 0.5) / N - b)[:, None]
            parts.append((Y0 + dlo - y0, X0 + dlo - x0, R[0] + uX * R[1] + vY * R[2] + (vY * uX) * R[3]))
            reach = max(reach, -(Y0 + dlo - y0), -(X0 + dlo - x0))
            far = (max(far[0], Y0 + dlo - y0 + h + D), max(far[1], X0 + dlo - x0 + w + D))
        out = np.zeros((F, far[0] + reach, far[1] + reach), np.float32)
        for Y, X, acc in parts:
            out[:, Y + reach : Y + reach + acc.shape[1], X + reach : X + reach + acc.shape[2]] += acc
        return out[:, reach : reach + H, reach : reach + W].reshape(lead + (H, W))

    def __call__(self, sub, origin, s):
        """The blurred supersampled region (the reference: every node's tent-weighted light convolved)"""
        Hs, Ws = sub.shape[-2:]
        N, x0, y0 = self.node_px, origin[0], origin[1]
        m = int(math.ceil(self.radius_px)) + 1
        xs = x0 - 0.5 + (np.arange(-m * s, Ws + m * s) + 0.5) / s
        ys = y0 - 0.5 + (np.arange(-m * s, Hs + m * s) + 0.5) / s
        rows, cols = (np.clip(np.arange(-m * s, n + m * s), 0, n - 1) for n in (Hs, Ws))
        ext = sub[..., rows, :][..., cols]  # the border replicated
        nodes = [(a, b) for b in range(math.floor((ys[0] + 0.5) / N), math.floor((ys[-1] + 0.5) / N) + 2)
                 for a in range(math.floor((xs[0] + 0.5) / N), math.floor((xs[-1] + 0.5) / N) + 2)]
        e = m * s + max(max(self.node_kernel(a, b, s).shape) for a, b in nodes)
        out = np.zeros(sub.shape[:-2] + (Hs + 2 * e, Ws + 2 * e), np.float32)
        for a, b in nodes:
            w = (np.maximum(0.0, 1 - np.abs((ys + 0.5) / N - b))[:, None] *
                 np.maximum(0.0, 1 - np.abs((xs + 0.5) / N - a))[None, :])
            if not w.any():
                continue
            k = self.node_kernel(a, b, s)
            r, c = k.shape[0] // 2, k.shape[1] // 2
            src = np.pad(ext * w, [(0, 0)] * (sub.ndim - 2) + [(r, r), (c, c)])
            o = e - m * s
            out[..., o - r : o - r + src.shape[-2], o - c : o - c + src.shape[-1]] += convolve(src, k)  # all its light
        return out[..., e : e + Hs, e : e + Ws]

    def describe(self):
        return {"kind": "smooth", "node_px": self.node_px}

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

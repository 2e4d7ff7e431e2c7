"""One view of a pattern: exact sub-pixel coverage, PSF convolution, block summation

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.synth.patterns import Star
    >>> from rotstar_mrcal.synth.imaging import render_view
    >>> from rotstar_mrcal.optics.psf import gaussian_psf
    >>> apex = np.array((10.0, 10.0))                      # the corner, tile pixels
    >>> img, grad = render_view([Star.regular(4, 0.3)], gaussian_psf(1.0, 4), 4, 21, apex)
    >>> img.shape, grad.shape                              # (frames, T, T), (frames, T, T, 2)
    ((1, 21, 21), (1, 21, 21, 2))
    >>> bool(np.allclose(img, img[:, ::-1, ::-1], atol=1e-6)), round(float(img[0, 10, 10]), 6)   # point-symmetric
    (True, 0.5)

The paper's renderer (4.1): a high-resolution pattern, convolved with the
PSF at that resolution, summed block-wise into camera pixels.

1. High resolution: s x s sub-pixels per camera pixel; every sub-pixel holds
   the exact fraction of its area that is white (star_coverage, exact for
   any star and any sub-pixel, including the one holding the apex, so the
   render is a continuous function of the corner position).
2. PSF: the sub-pixel image is convolved with the kernel (an odd, centred,
   unit-sum array at sub-pixel resolution: optics.wavefront_psf,
   optics.gaussian_psf; simulate.optics.convolve, a true convolution).
3. Block summation: each s x s block is averaged into one camera pixel
   (simulate.irradiance.block_average); a region of the kernel's radius around
   the tile is rendered and dropped so the tile has no border effects.

Pixel (c, r) of a T x T tile covers [c - 1/2, c + 1/2] x [r - 1/2, r + 1/2]
(mrcal's convention: integer coordinates are pixel centres).

The Cramer-Rao bound needs d mu / d q, the derivative of every pixel value
with respect to the corner position q. Moving the pattern by q changes a
sub-pixel's integral by minus the integral of grad P over it; grad P of a
star is a line measure on its edges (jump x normal), so the sub-pixel
integral is sum over edges of (colour after - colour before) n_e times the
length of the edge inside the sub-pixel (star_edge_measure, exact). That
image is convolved and summed like the pattern: the gradient returned is the
pixel-integrated gradient of the blurred pattern, d mu / d q = -C * grad for
contrast C. No finite differences of a hard-edged render are involved.

Fringes (patterns.Fringe, the phase pattern) take their own path through
the same three steps (fringe_subpixel): every sub-pixel holds the exact
mean of 0.5 + 0.5 cos(k . d + shift) over its square (the sinusoid times
sinc(k_x h / 2) sinc(k_y h / 2)), and the exact mean of its gradient
(-0.5 sin(...) k times the same factors); both are convolved with the
same PSF kernel and block-summed. A PSF shifts a sinusoid's phase by the
argument of its optical transfer function at k: zero for a point-symmetric
PSF, not for coma.
"""

from __future__ import annotations

import math

import numpy as np

import scipy.fft

from rotstar_mrcal.simulate.irradiance import block_average
from rotstar_mrcal.synth.patterns import Fringe, Star


def star_coverage(star: Star, dx: np.ndarray, dy: np.ndarray, h: float, hit=None, theta=None) -> np.ndarray:
    """White area fraction of squares of side h centred at (dx, dy) from the apex, exact

    SYNOPSIS

        >>> import numpy as np
        >>> from rotstar_mrcal.synth.patterns import Star
        >>> d = np.array([-0.5, 0.5])
        >>> star_coverage(Star.regular(4), d[None, :], d[:, None], 1.0).round(12)   # x > 0, y > 0 black
        array([[0., 1.],
               [1., 0.]])
        >>> float(star_coverage(Star.regular(4, 0.3), np.array(0.0), np.array(0.0), 1.0))
        0.5
        >>> sq = star_coverage(Star.regular(4, np.pi / 4), np.array(0.5), np.array(0.0), 1.0)
        >>> round(float(sq), 6)              # white wedge |y| < x: the square [0,1] x [-1/2,1/2] minus 2 triangles
        0.75

    Squares that no edge reaches take the colour of their centre. For the
    others, Green's theorem: the area of square & wedge is 1/2 the integral
    of x dy - y dx (apex at the origin) around its boundary; the edges are
    rays through the origin, where x dy - y dx = 0, so only the parts of the
    square's sides inside the wedge count, and along a side P0 + t D the
    integrand is the constant cross(P0, D). The white area is therefore the
    sum over sides of cross(P0, D) / 2 times the fraction of the side that
    lies in white wedges (split where the rays cross it, colour looked up at
    each piece's midpoint).

    hit (the squares an edge may cross, see reached_grid) and theta
    (arctan2(dy, dx)) may be given to save their computation.
    """
    dx, dy = np.broadcast_arrays(np.asarray(dx, float), np.asarray(dy, float))
    theta = np.arctan2(dy, dx) if theta is None else theta
    out = np.array(star.colour_at(theta), float).reshape(dx.shape)
    hit = _reached(star, dx, dy, h) if hit is None else hit
    if np.any(hit):
        out[hit] = _exact_coverage(star, dx[hit], dy[hit], h)
    return out


def _reached(star: Star, dx, dy, h) -> np.ndarray:
    """True for squares that an edge ray may cross (conservative), or that hold the apex"""
    c, s = np.cos(star.edges), np.sin(star.edges)
    E = (slice(None),) + (None,) * dx.ndim
    delta = -s[E] * dx + c[E] * dy
    along = c[E] * dx + s[E] * dy
    reach = 0.5 * h * (np.abs(c) + np.abs(s))[E] * (1 + 1e-9)
    near = (np.abs(delta) <= reach) & (along >= -reach)
    return near.any(axis=0) | (np.maximum(np.abs(dx), np.abs(dy)) <= h)


def reached_grid(star: Star, xs: np.ndarray, ys: np.ndarray, h: float) -> np.ndarray:
    """_reached for the grid of squares centred at (xs[c], ys[r]) (apex at 0), (len(ys), len(xs))

    SYNOPSIS

        >>> import numpy as np
        >>> from rotstar_mrcal.synth.patterns import Star
        >>> t = np.arange(-3, 4) * 0.5
        >>> st = Star.regular(4, 0.4)
        >>> dx, dy = np.meshgrid(t, t)
        >>> bool(np.all(reached_grid(st, t, t, 0.5) >= _reached(st, dx, dy, 0.5)))
        True

    Row by row: the part of each edge ray inside a row's band of height h
    spans an x interval; the squares of the row that overlap it are
    marked, with a running sum over a difference array.
    Cost O(edges x rows + grid) instead of O(edges x grid).
    """
    xs = np.asarray(xs, float)
    ys = np.asarray(ys, float)
    n = len(xs)
    c, sn = np.cos(star.edges)[:, None], np.sin(star.edges)[:, None]
    y0, y1 = ys[None, :] - h / 2, ys[None, :] + h / 2  # (1, rows)
    with np.errstate(divide="ignore", invalid="ignore"):
        ta, tb = y0 / sn, y1 / sn
    flat = np.abs(sn) < 1e-12
    tlo = np.where(flat, np.where(np.abs(ys) <= h / 2, 0.0, np.inf), np.maximum(np.minimum(ta, tb), 0.0))
    thi = np.where(flat, np.where(np.abs(ys) <= h / 2, np.inf, -np.inf), np.maximum(ta, tb))
    ok = thi >= tlo
    xa = np.where(ok, np.minimum(tlo * c, np.where(np.isfinite(thi), thi * c, np.sign(c) * np.inf)), 0.0)
    xb = np.where(ok, np.maximum(np.where(np.isfinite(tlo), tlo * c, 0.0),
                                 np.where(np.isfinite(thi), thi * c, np.sign(c) * np.inf)), 0.0)
    xa = np.where(np.isnan(xa), 0.0, xa)
    xb = np.where(np.isnan(xb), 0.0, xb)
    dxs = xs[1] - xs[0] if n > 1 else h
    eps = 1e-9
    ia = np.clip(np.ceil((xa - h / 2 - xs[0]) / dxs - eps), 0, n).astype(int)  # first square reaching xa
    ib = np.clip(np.floor((xb + h / 2 - xs[0]) / dxs + eps) + 1, 0, n).astype(int)  # past the last
    diff = np.zeros((len(ys), n + 1), int)
    rows = np.broadcast_to(np.arange(len(ys)), ia.shape)
    np.add.at(diff, (rows[ok], ia[ok]), 1)
    np.add.at(diff, (rows[ok], ib[ok]), -1)
    hit = np.cumsum(diff, axis=1)[:, :n] > 0
    return hit | (np.maximum(np.abs(xs)[None, :], np.abs(ys)[:, None]) <= h)


def _cross(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _exact_coverage(star: Star, dx: np.ndarray, dy: np.ndarray, h: float) -> np.ndarray:
    """star_coverage by Green's theorem, for 1-D arrays of squares"""
    q = 0.5 * h
    corner = np.array(((-q, -q), (q, -q), (q, q), (-q, q)))
    P0 = np.stack((dx, dy), axis=-1)[:, None, :] + corner  # (N, 4, 2)
    D = np.roll(corner, -1, axis=0) - corner  # (4, 2)
    d = np.stack((np.cos(star.edges), np.sin(star.edges)), axis=-1)  # (E, 2)
    P0e, De = P0[:, :, None, :], D[None, :, None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -_cross(P0e, d) / _cross(De, d)  # (N, 4, E): where side meets the edge's line
    lam = np.einsum("nsek,ek->nse", P0e + np.nan_to_num(t)[..., None] * De, d)
    t = np.where((t > 0) & (t < 1) & (lam > 0), t, 1.0)
    T = np.concatenate((np.zeros(t.shape[:-1] + (1,)), np.sort(t, axis=-1), np.ones(t.shape[:-1] + (1,))), axis=-1)
    mid = 0.5 * (T[..., 1:] + T[..., :-1])
    pts = P0[:, :, None, :] + mid[..., None] * D[None, :, None, :]
    white = np.sum(np.diff(T, axis=-1) * star.colour_at(np.arctan2(pts[..., 1], pts[..., 0])), axis=-1)
    w = 0.5 * _cross(P0, D[None])  # (N, 4)
    return np.sum(w * white, axis=-1) / np.sum(w, axis=-1)


def star_edge_measure(star: Star, dx: np.ndarray, dy: np.ndarray, h: float, hit=None) -> np.ndarray:
    """Integral of grad P over squares of side h centred at (dx, dy) from the apex: (..., 2), exact

    SYNOPSIS

        >>> import numpy as np
        >>> from rotstar_mrcal.synth.patterns import Star
        >>> star_edge_measure(Star.regular(4), np.array([2.0, 3.0]), np.array([0.25, 3.0]), 1.0)
        array([[ 0., -1.],
               [ 0.,  0.]])

    (The first square holds 1 px of the edge along +x, white above it (y < 0)
    and black below: grad P points to -y; no edge crosses the second.) It is
    the exact derivative of star_coverage * h^2 with respect to moving the
    apex, with the sign flipped (tests/synth/test_synth.py checks it against finite
    differences). Each edge e
    contributes (colour after - colour before) * n_e * (length of the ray
    inside the square), n_e = (-sin, cos) of the edge angle (pointing into
    the wedge after it).
    """
    dx, dy = np.broadcast_arrays(np.asarray(dx, float), np.asarray(dy, float))
    out = np.zeros(dx.shape + (2,))
    hit = _reached(star, dx, dy, h) if hit is None else hit
    if np.any(hit):
        out[hit] = _edge_measure(star, dx[hit], dy[hit], h)
    return out


def _edge_measure(star: Star, dx: np.ndarray, dy: np.ndarray, h: float) -> np.ndarray:
    """star_edge_measure for 1-D arrays of squares (Liang-Barsky clipping of every ray)"""
    c, s = np.cos(star.edges), np.sin(star.edges)
    jump = star.colours - np.roll(star.colours, 1)
    lo = np.zeros((len(dx), len(c)))
    hi = np.full((len(dx), len(c)), np.inf)
    for comp, d in ((dx[:, None], c), (dy[:, None], s)):
        par = np.abs(d) < 1e-15
        with np.errstate(divide="ignore", invalid="ignore"):
            t0 = (comp - h / 2) / d
            t1 = (comp + h / 2) / d
        inside = np.abs(comp) <= h / 2
        lo = np.maximum(lo, np.where(par, np.where(inside, 0.0, np.inf), np.minimum(t0, t1)))
        hi = np.minimum(hi, np.where(par, np.where(inside, np.inf, -np.inf), np.maximum(t0, t1)))
    w = np.maximum(hi - lo, 0.0) * jump
    return np.stack((w @ -s, w @ c), axis=-1)


def fringe_subpixel(fringe: Fringe, dx: np.ndarray, dy: np.ndarray, h: float):
    """Exact means of a fringe and of its gradient over squares of side h centred at (dx, dy)

    SYNOPSIS

        >>> import numpy as np
        >>> from rotstar_mrcal.synth.patterns import Fringe
        >>> f = Fringe(np.array((2 * np.pi / 4, 0.0)), 0.0)      # period 4
        >>> v, g = fringe_subpixel(f, np.array([0.0, 1.0]), np.array([0.0, 0.0]), 2.0)
        >>> np.round(v, 4).tolist(), round(0.5 + 1 / np.pi, 4)   # squares [-1, 1] and [0, 2]
        ([0.8183, 0.5], 0.8183)
        >>> (np.round(g[:, 0] * 2, 12) + 0.0).tolist()   # P(1) - P(-1) = 0, P(2) - P(0) = -1
        [0.0, -1.0]

    Returns (value (...), gradient (..., 2)); the mean of cos(k . d + s)
    over the square is cos(k . c + s) sinc(k_x h / 2) sinc(k_y h / 2).
    """
    dx, dy = np.broadcast_arrays(np.asarray(dx, float), np.asarray(dy, float))
    kx, ky = (float(v) for v in fringe.k)
    box = np.sinc(kx * h / (2 * math.pi)) * np.sinc(ky * h / (2 * math.pi))  # numpy's sinc is sin(pi x) / (pi x)
    a = kx * dx + ky * dy + fringe.shift
    value = 0.5 + 0.5 * box * np.cos(a)
    g = -0.5 * box * np.sin(a)
    return value, np.stack((g * kx, g * ky), axis=-1)


class FFTBlur:
    """Convolution of (..., H, W) images with one kernel, its transform computed once

    SYNOPSIS

        >>> import numpy as np
        >>> from rotstar_mrcal.optics.blur import convolve
        >>> rng = np.random.default_rng(0)
        >>> k, img = rng.random((7, 5)), rng.random((2, 40, 30))
        >>> blur = FFTBlur(k / k.sum(), (40, 30))
        >>> bool(np.allclose(blur(img)[:, 3:-3, 2:-2], convolve(img, k / k.sum())[:, 3:-3, 2:-2], atol=1e-5))
        True

    The same true convolution as simulate.optics.convolve (which checks the
    kernel for separability with an SVD on every call, 0.3 s for a 131 x 131
    kernel), computed as a circular convolution in float32: only the pixels
    at least the kernel's half-size from the border are right (the others
    see the opposite border). The renderer crops a larger margin.
    """

    def __init__(self, kernel: np.ndarray, shape):
        self.k = np.asarray(kernel, float)
        kh, kw = self.k.shape
        H, W = shape
        if kh > H or kw > W:
            raise ValueError(f"kernel {self.k.shape} larger than the image {tuple(shape)}")
        self.shape = (H, W)
        self.full = (scipy.fft.next_fast_len(H, True), scipy.fft.next_fast_len(W, True))
        kp = np.zeros(self.full, np.float32)
        kp[:kh, :kw] = self.k
        kp = np.roll(kp, (-(kh // 2), -(kw // 2)), axis=(0, 1))  # kernel centre at [0, 0]
        self.K = scipy.fft.rfft2(kp)

    def __call__(self, img: np.ndarray) -> np.ndarray:
        H, W = self.shape
        f = scipy.fft.rfft2(np.asarray(img, np.float32), self.full)
        return scipy.fft.irfft2(f * self.K, self.full)[..., :H, :W]


class ViewRenderer:
    """Renders T x T tiles through one PSF kernel at supersampling s (the FFT of the kernel is kept)

    SYNOPSIS

        >>> import numpy as np
        >>> from rotstar_mrcal.optics.psf import gaussian_psf
        >>> from rotstar_mrcal.synth.patterns import pattern_frames
        >>> r = ViewRenderer(gaussian_psf(1.0, 4), 4, 21)
        >>> img, grad = r(pattern_frames("rotstar"), np.array((10.3, 9.6)))
        >>> img.shape, grad.shape
        ((8, 21, 21), (8, 21, 21, 2))

    Calling it returns (images, grads): images (K, T, T) in [0, 1], one per
    star (or per fringe: a list of patterns.Fringe takes the fringe path), apex at `apex` (tile pixel coordinates); grads (K, T, T, 2) the
    integral over each pixel of grad (PSF * P), so d pixel / d apex = -grads
    for a unit contrast (None with gradient=False).
    """

    def __init__(self, kernel: np.ndarray, s: int, tile: int):
        k = np.asarray(kernel, float)
        self.kernel = k / k.sum()
        self.s = int(s)
        self.tile = int(tile)
        self.margin = int(math.ceil((max(k.shape) // 2) / self.s)) + 1  # camera pixels
        n = (self.tile + 2 * self.margin) * self.s
        self.centres = -self.margin - 0.5 + (np.arange(n) + 0.5) / self.s
        self.blur = FFTBlur(self.kernel, (n, n))
        self._apex = None

    def __call__(self, stars, apex, gradient: bool = True):
        if len(stars) and all(isinstance(f, Fringe) for f in stars):
            return self._fringes(stars, apex, gradient)
        s, m, T = self.s, self.margin, self.tile
        xs, ys = self.centres - apex[0], self.centres - apex[1]
        if self._apex is None or not np.array_equal(self._apex, apex):
            self._apex = np.array(apex, float)
            self._grid = np.meshgrid(xs, ys)
            self._theta = np.arctan2(self._grid[1], self._grid[0])
        dx, dy = self._grid
        h = 1.0 / s
        hits = [reached_grid(st, xs, ys, h) for st in stars]
        cov = np.stack([star_coverage(st, dx, dy, h, hit, self._theta) for st, hit in zip(stars, hits)])
        img = block_average(self.blur(cov), s)[:, m : m + T, m : m + T]
        if not gradient:
            return img, None
        meas = np.stack([star_edge_measure(st, dx, dy, h, hit) for st, hit in zip(stars, hits)])
        g = block_average(self.blur(np.moveaxis(meas, -1, 1)), s)  # (K, 2, n/s, n/s)
        return img, np.moveaxis(g[..., m : m + T, m : m + T] * (s * s), 1, -1)

    def _fringes(self, fringes, apex, gradient: bool):
        """The fringe path: exact sub-pixel means (fringe_subpixel), PSF, block summation"""
        s, m, T = self.s, self.margin, self.tile
        dx, dy = np.meshgrid(self.centres - apex[0], self.centres - apex[1])
        sub = [fringe_subpixel(f, dx, dy, 1.0 / s) for f in fringes]
        img = block_average(self.blur(np.stack([v for v, _ in sub])), s)[:, m : m + T, m : m + T]
        if not gradient:
            return img, None
        # the mean gradient over a sub-pixel, averaged over the s x s block: the integral over the pixel
        g = block_average(self.blur(np.stack([np.moveaxis(gr, -1, 0) for _, gr in sub])), s)
        return img, np.moveaxis(g[..., m : m + T, m : m + T], 1, -1)


def render_view(stars, kernel: np.ndarray, s: int, tile: int, apex, gradient: bool = True):
    """ViewRenderer(kernel, s, tile)(stars, apex, gradient), for one view"""
    return ViewRenderer(kernel, s, tile)(stars, np.asarray(apex, float), gradient)

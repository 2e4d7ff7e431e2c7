"""The PSF of a wavefront: H = A |F(P exp(2 pi i W))|^2, sampled at the renderer's sub-pixels

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.optics.psf import Optics, wavefront_psf
    >>> from rotstar_mrcal.optics.wavefront import Seidel
    >>> optics = Optics(wavelength_um=0.55, fnumber=2.0, pixel_um=3.0)
    >>> round(optics.lambda_fnum_px, 4)                  # lambda N / pixel pitch
    0.3667
    >>> k = wavefront_psf(Seidel(coma=4.0), optics, supersample=4)
    >>> k.shape[0] % 2, round(float(k.sum()), 12)        # odd, centred, unit sum
    (1, 1.0)
    >>> centroid_px(k, 4)[0] > 1                         # the comet's tail points to +x
    np.True_

The image-plane field is the Fourier transform of the pupil function. With
the pupil sampled on an N x N grid and a pupil radius of R samples, one FFT
bin is 2 R lambda_fnum_px / N camera pixels (lambda_fnum_px = wavelength *
F-number / pixel pitch). N and R are chosen so that a bin is 1/m of a
sub-pixel (m odd, large enough for m * s * lambda_fnum_px >= 2: Nyquist for
the intensity), the pupil is sampled finely enough for the steepest
wavefront slope (R >= 4 max|dW/drho| and R >= 24) and the grid holds twice
the geometric spot (whose radius is 2 lambda_fnum_px max|dW/drho| pixels).
The intensity is then integrated over m x m bins (one sub-pixel each),
cropped to the smallest centred odd square that keeps all but `tail` of the
energy, and normalised to unit sum.

Orientation: the image coordinates are the FFT frequencies, so a wavefront
slope dW/dx > 0 moves light toward +x: a ray through pupil point (x, y)
lands at 2 lambda_fnum_px grad W (pixels) from the ideal image point. Seidel
coma W_coma rho^3 cos(theta - a) > 0 thus draws a comet whose head sits at the
ideal image point and whose tail points along a (3 x 2 lambda_fnum_px W_coma
pixels long). The kernel follows the orientation of simulate.optics
(tap [r, c] moves light r - h//2 sub-pixels down and c - w//2 right): it
plugs into the foundation's renderer as `psf=kernel` (KernelPSF), as
`psf=SeidelPSF(...)` (any supersampling), or field-dependent as
`psf=radial_psf(...)` (SmoothPSF, coma and astigmatism along the field
radius, the PSF changing continuously over the field).
"""

from __future__ import annotations

import collections
import dataclasses
import math

import numpy as np

from rotstar_mrcal.optics.blur import SmoothPSF, convolve
from rotstar_mrcal.optics.wavefront import Seidel, pupil_function

DEFAULT_TAIL = 2e-3
"""Energy fraction allowed outside the cropped kernel"""


@dataclasses.dataclass(frozen=True)
class Optics:
    """The imaging optics that scale a wavefront into pixels

    Defaults: green light, F/2.0, 3 um pixels (an Intel RealSense D435 IR
    imager): lambda N / p = 0.37 px, Airy radius 1.22 lambda N = 0.45 px, and
    a W_coma = 4 wave comet 8.8 px long.
    """

    wavelength_um: float = 0.55
    fnumber: float = 2.0
    pixel_um: float = 3.0

    @property
    def lambda_fnum_px(self) -> float:
        return self.wavelength_um * self.fnumber / self.pixel_um

    def to_dict(self) -> dict:
        return dataclasses.asdict(self) | {"lambda_fnum_px": self.lambda_fnum_px}


def max_slope(seidel: Seidel) -> float:
    """An upper bound of |grad W| (waves per unit pupil radius) over the pupil"""
    s = seidel
    return abs(s.tilt) + 2 * abs(s.focus) + 4 * abs(s.spherical) + 3 * abs(s.coma) + 2 * abs(s.astigmatism)


def geometric_radius_px(seidel: Seidel, optics: Optics) -> float:
    """Largest ray displacement in the image (pixels), plus the Airy radius"""
    k = optics.lambda_fnum_px
    return 2 * k * max_slope(seidel) + 1.22 * k


def _psf_grid(seidel: Seidel, optics: Optics, supersample: int):
    """(m, n_sub, N, R): oversampling, sub-pixels across the grid, FFT size, pupil radius"""
    k = optics.lambda_fnum_px
    s = int(supersample)
    m = max(1, math.ceil(2.0 / (s * k)))
    m += (m + 1) % 2  # odd: a fine bin is centred on the centre sub-pixel
    fine = m * s  # fine bins per camera pixel; one bin = 1 / fine px
    r_min = max(24.0, 4.0 * max_slope(seidel))
    # field of N / fine px must hold the spot (2 radii) with a margin
    half_px = max(2.0 * geometric_radius_px(seidel, optics), 8 * k, 3.0)
    n_sub = 2 * math.ceil(max(half_px * s, r_min / (m * k * 2))) + 1
    N = n_sub * m
    R = N / (2.0 * fine * k)
    if R < r_min:  # the pupil needs finer sampling: grow the grid
        n_sub = 2 * math.ceil(r_min * 2.0 * fine * k / m / 2) + 1
        N = n_sub * m
        R = N / (2.0 * fine * k)
    return m, n_sub, N, R


def wavefront_psf(seidel: Seidel, optics: Optics | None = None, supersample: int = 4,
                  tail: float = DEFAULT_TAIL, max_radius_px: float | None = None,
                  zero_centroid: bool = False) -> np.ndarray:
    """PSF kernel of a Seidel wavefront at sub-pixel resolution: odd, centred, unit sum

    See the module docstring for the sampling. tail: energy fraction allowed
    outside the crop (0: keep the whole computed grid); max_radius_px caps
    the crop (camera pixels). zero_centroid: the kernel's light centroid put
    on its centre by a tilt added to seidel's (found from the cropped
    kernel's own centroid, ZERO_CENTROID_STEPS times): a tilt of -coma puts
    the untruncated PSF's centroid there, but the crop takes coma's one-sided
    tail and moves it toward the head by 0.01-0.02 px under 1.5 waves,
    differently at each supersampling.
    """
    optics = Optics() if optics is None else optics
    # (the grid is kept for the added tilt: a grid that changed with it would make the centroid jump)
    grid = _psf_grid(seidel, optics, supersample)
    k = _wavefront_kernel(seidel, grid, tail, max_radius_px, supersample)
    if zero_centroid:
        t = seidel.tilt * np.array((math.cos(seidel.tilt_angle), math.sin(seidel.tilt_angle)))
        for _ in range(ZERO_CENTROID_STEPS):
            c = centroid_px(k, supersample)
            if np.hypot(*c) < ZERO_CENTROID_PX:
                break
            t = t - c / (2.0 * optics.lambda_fnum_px)  # a tilt t (waves) moves the light 2 lambda N t px along it
            k = _wavefront_kernel(dataclasses.replace(seidel, tilt=float(np.hypot(*t)),
                                                      tilt_angle=float(math.atan2(t[1], t[0]))),
                                  grid, tail, max_radius_px, supersample)
    return k


ZERO_CENTROID_STEPS = 3
ZERO_CENTROID_PX = 1e-4


def _wavefront_kernel(seidel, grid, tail, max_radius_px, supersample) -> np.ndarray:
    m, n_sub, N, R = grid
    U = pupil_function(seidel, N, R)
    # fftshift(fft2(ifftshift(U))) with the rows' transforms taken only where the pupil is (a quarter of them)
    rows = np.arange(max(N // 2 - int(R) - 1, 0), min(N // 2 + int(R) + 2, N))
    cols = np.zeros((N, N), complex)
    cols[(rows - N // 2) % N] = np.fft.fft(np.fft.ifftshift(U[rows], axes=1), axis=1)
    A = np.fft.fft(cols, axis=0)
    H = np.fft.fftshift(A.real**2 + A.imag**2).reshape(n_sub, m, n_sub, m).sum(axis=(1, 3))
    H /= H.sum()
    c = n_sub // 2
    # smallest centred square with at most `tail` of the energy outside
    yy, xx = np.mgrid[-c : c + 1, -c : c + 1]
    ring = np.maximum(abs(xx), abs(yy)).ravel()
    inside = np.bincount(ring, weights=H.ravel(), minlength=c + 1).cumsum()
    r = int(np.searchsorted(inside, 1.0 - tail)) if tail > 0 else c
    r = min(max(r, 1), c)
    if max_radius_px is not None:
        r = min(r, max(1, int(round(max_radius_px * supersample))))
    k = H[c - r : c + r + 1, c - r : c + r + 1]
    return k / k.sum()


def gaussian_psf(sigma_px: float, supersample: int = 4, truncate: float = 4.0) -> np.ndarray:
    """A Gaussian kernel (sigma in camera pixels) integrated over sub-pixels, unit sum

    SYNOPSIS

        >>> k = gaussian_psf(1.0, 4)
        >>> k.shape, round(float(k.sum()), 12), round(float(second_moment_px(k, 4)[0, 0]), 3)
        ((33, 33), 1.0, 1.005)

    The sub-pixel integral (difference of erf) rather than the point samples
    of simulate.optics.gaussian_kernel; the variance grows by the box's
    1 / (12 s^2).
    """
    # (here, not at the top: scipy.special costs 0.7-1.9 s of start-up, python -X importtime, and
    # rotstar-simulate imports this module for LensPSF without ever drawing a Gaussian)
    from scipy.special import ndtr

    s = int(supersample)
    r = max(1, math.ceil(truncate * sigma_px * s))
    e = (np.arange(-r, r + 2) - 0.5) / (s * sigma_px)
    g = np.diff(ndtr(e))
    g /= g.sum()
    return np.outer(g, g)


def centroid_px(kernel: np.ndarray, supersample: int) -> np.ndarray:
    """(x, y) centroid of a kernel relative to its centre, camera pixels"""
    h, w = kernel.shape
    y = (np.arange(h) - h // 2) / supersample
    x = (np.arange(w) - w // 2) / supersample
    k = kernel / kernel.sum()
    return np.array((np.sum(k.sum(axis=0) * x), np.sum(k.sum(axis=1) * y)))


def second_moment_px(kernel: np.ndarray, supersample: int) -> np.ndarray:
    """2x2 central second moment of a kernel, camera pixels^2"""
    h, w = kernel.shape
    y = (np.arange(h) - h // 2)[:, None] / supersample
    x = (np.arange(w) - w // 2)[None, :] / supersample
    k = kernel / kernel.sum()
    cx, cy = centroid_px(k, supersample)
    dx, dy = x - cx, y - cy
    return np.array(((np.sum(k * dx * dx), np.sum(k * dx * dy)), (np.sum(k * dx * dy), np.sum(k * dy * dy))))


def asymmetry(kernel: np.ndarray) -> float:
    """Relative energy of the point-antisymmetric part: 0 for a point-symmetric kernel

    SYNOPSIS

        >>> import numpy as np
        >>> asymmetry(np.array([[0, 0, 0], [0, 1, 0], [0, 0, 0]])), asymmetry(np.eye(3)[::-1] + np.eye(3))
        (0.0, 0.0)
        >>> round(asymmetry(np.array([[0, 0, 0], [0, 1, 1], [0, 0, 0]])), 3)
        0.5

    |k - k rotated by 180 degrees|_1 / (2 |k|_1).
    """
    k = np.asarray(kernel, float)
    return float(np.abs(k - k[::-1, ::-1]).sum() / (2 * np.abs(k).sum()))


class SeidelPSF:
    """A wavefront PSF for simulate.render_irradiance(psf=...), at any supersampling

    SYNOPSIS

        >>> import numpy as np
        >>> from rotstar_mrcal.optics.psf import SeidelPSF
        >>> from rotstar_mrcal.optics.wavefront import Seidel
        >>> psf = SeidelPSF(Seidel(spherical=1.0))
        >>> img = np.zeros((1, 81, 81), np.float32); img[0, 40, 40] = 1
        >>> out = psf(img, (0, 0), 4)
        >>> round(float(out.sum()), 5), bool(np.allclose(out[0], out[0, ::-1, ::-1], atol=1e-7))
        (1.0, True)
    """

    def __init__(self, seidel: Seidel, optics: Optics | None = None, tail: float = DEFAULT_TAIL):
        self.seidel = seidel
        self.optics = Optics() if optics is None else optics
        self.tail = tail
        self._kernels: dict[int, np.ndarray] = {}

    def kernel(self, s: int) -> np.ndarray:
        if s not in self._kernels:
            self._kernels[s] = wavefront_psf(self.seidel, self.optics, s, self.tail)
        return self._kernels[s]

    def radius_for(self, s: int) -> float:
        return self.kernel(s).shape[0] // 2 / s

    @property
    def radius_px(self) -> float:
        return self.radius_for(4)

    def __call__(self, sub, origin, s):
        return convolve(sub, self.kernel(s))

    def describe(self):
        return {"kind": "seidel", "seidel": self.seidel.to_dict(), "optics": self.optics.to_dict()}


def radial_psf(seidel: Seidel, centre, optics: Optics | None = None, node_px: int = 64,
               field_radius_px: float | None = None, tail: float = DEFAULT_TAIL,
               zero_centroid: bool = False) -> SmoothPSF:
    """A field-dependent wavefront PSF: coma and astigmatism point along the field radius

    SYNOPSIS

        >>> import numpy as np
        >>> from rotstar_mrcal.optics.wavefront import Seidel
        >>> from rotstar_mrcal.optics.psf import radial_psf
        >>> psf = radial_psf(Seidel(coma=2.0), centre=(64, 64), node_px=32)
        >>> out = psf.pixels(np.ones((1, 512, 512), np.float32), (0, 0), 4)
        >>> out.shape, bool(out[0, 64, 64] < 0.95 < out[0, 8, 8])  # without tilt coma moves the light outward
        ((1, 128, 128), True)

    The kernel at (x, y) (SmoothPSF's nodes, every node_px pixels, blended
    bilinearly between them) is that of `seidel` turned by the azimuth of
    (x, y) - centre (image direction; so the comet's tail points away from
    `centre` when seidel.coma > 0). With field_radius_px the Seidel field
    dependence is applied with h = |(x, y) - centre| / field_radius_px:
    tilt and coma scale with h, focus and astigmatism with h^2 (field
    curvature), spherical is constant; without it the amplitudes are constant
    over the field. Kernels are cached per node. zero_centroid: every
    node's kernel has its light's centroid at its centre (wavefront_psf).
    """
    optics = Optics() if optics is None else optics
    cx, cy = (float(v) for v in centre)
    cache: collections.OrderedDict = collections.OrderedDict()

    def seidel_at(x, y):
        a = math.atan2(y - cy, x - cx)
        s = seidel.rotated(a)
        if field_radius_px:
            h = math.hypot(x - cx, y - cy) / field_radius_px
            s = dataclasses.replace(s, tilt=s.tilt * h, coma=s.coma * h, focus=s.focus * h * h,
                                    astigmatism=s.astigmatism * h * h)
        return s

    def kernel_at(x, y, s):
        key = (round(float(x), 3), round(float(y), 3), s)
        if key not in cache:
            cache[key] = wavefront_psf(seidel_at(x, y), optics, s, tail, zero_centroid=zero_centroid)
            while len(cache) > 256:
                cache.popitem(last=False)
        return cache[key]

    worst = seidel if not field_radius_px else dataclasses.replace(
        seidel, tilt=seidel.tilt * 1.5, coma=seidel.coma * 1.5, focus=seidel.focus * 2.25,
        astigmatism=seidel.astigmatism * 2.25)
    return SmoothPSF(kernel_at, node_px=node_px, radius_px=geometric_radius_px(worst, optics) + 1.0)


class LensPSF:
    """radial_psf over a whole image, kept by value: it pickles (for worker processes), built on first use

    SYNOPSIS

        >>> import numpy as np
        >>> from rotstar_mrcal.optics.psf import LensPSF
        >>> from rotstar_mrcal.optics.wavefront import Seidel
        >>> psf = LensPSF(Seidel(coma=1.5, focus=0.3), (128, 96))     # waves at the image corners
        >>> psf.seidel.tilt                                           # coma's centroid put back
        -1.5
        >>> d435 = LensPSF(Seidel(coma=1.5, focus=0.3), (1280, 800))
        >>> out = d435.pixels(np.ones((1, 256, 256), np.float32), (300, 200), 4)
        >>> bool(np.abs(out - 1).max() < 2e-4), d435.radius_px > 1     # a flat field stays flat (to 2nd order)
        (True, True)

    The Seidel amplitudes are those at the image corners (h = 1, the field
    radius is the half-diagonal from the image centre (W-1)/2, (H-1)/2):
    tilt and coma grow linearly with the field radius, focus (field
    curvature) and astigmatism with its square, spherical is constant; coma
    and astigmatism point along the field radius (radial_psf). Coma moves
    the light's centroid off the chief ray; unless `tilt` is given, an
    equal and opposite tilt (tilt = -coma) puts it back, and every kernel's
    centroid is put on the chief ray exactly (wavefront_psf's zero_centroid:
    the crop of coma's tail would leave it 0.01-0.02 px off), so the true
    camera model is where the light's centroid lands (what make demo does).
    """

    def __init__(self, seidel: Seidel, imagersize, optics: Optics | None = None, node_px: int = 64,
                 tail: float = DEFAULT_TAIL, tilt: float | None = None):
        self.seidel = dataclasses.replace(seidel, tilt=-seidel.coma if tilt is None else float(tilt))
        self.imagersize = tuple(int(v) for v in imagersize)
        self.optics = Optics() if optics is None else optics
        self.node_px, self.tail = int(node_px), float(tail)
        self.centred = tilt is None  # the light's centroid on the chief ray
        self._psf = None

    def _built(self) -> SmoothPSF:
        if self._psf is None:
            W, H = self.imagersize
            c = ((W - 1) / 2, (H - 1) / 2)
            self._psf = radial_psf(self.seidel, c, self.optics, self.node_px, math.hypot(*c), self.tail,
                                   zero_centroid=self.centred)
        return self._psf

    def __getstate__(self):
        return {k: v for k, v in self.__dict__.items() if k != "_psf"} | {"_psf": None}

    @property
    def radius_px(self) -> float:
        return self._built().radius_px

    def __call__(self, sub, origin, s):
        return self._built()(sub, origin, s)

    def pixels(self, sub, origin, s):
        return self._built().pixels(sub, origin, s)

    def local_kernel(self, x: float, y: float, s: int) -> np.ndarray:
        """The PSF of the light from image point (x, y) (SmoothPSF.local_kernel)"""
        return self._built().local_kernel(x, y, s)

    def describe(self):
        return {"kind": "seidel-field", "seidel_at_corners": self.seidel.to_dict(), "optics": self.optics.to_dict(),
                "imagersize": list(self.imagersize), "node_px": self.node_px}

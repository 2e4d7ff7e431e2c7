"""Bias by simulation: the symmetric fit's offset from the light's centroid under a known local PSF (issue 24)

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.detect.psfbias import simulated_bias, star_normals
    >>> from rotstar_mrcal.optics.psf import gaussian_psf
    >>> n = star_normals(np.eye(2)[None], np.arange(8) * np.pi / 16)
    >>> b = simulated_bias(gaussian_psf(1.0, 4)[None], 4, n, np.array([[10.3, 20.6]]), np.array([8.0]), 1.0)
    >>> bool(np.abs(b).max() < 0.005)          # a symmetric PSF: no bias
    True

Under a PSF that is not point-symmetric (coma) the symmetric fit (refine.py,
Eq. 1, on frames low-passed by refine.prefilter) finds the blurred star's
point of symmetry, not where the light's centroid lands. That offset is a
deterministic function of the local PSF, of the local pattern (the two edge
directions of every frame in the image, i.e. the element's Jacobian and the
frames' angles), of the fit window, of the low-pass and (by some 0.002-0.003
px) of the corner's sub-pixel phase. So render the ideal local star through
the PSF with its centre at a known point (`render_star`; `render_star_fft` is
the plain reference: the sharp pattern on a sub-pixel grid, convolved with
the kernel, averaged over each pixel), run the SAME fit on it and read the
bias (`simulated_bias`); the corner is then the fit's corner less that bias.

The local PSF is not known: `bias_correct` (the refiner psf-sim's step after
the symmetric fit) takes it as the wavefront PSF of the Seidel coma that the
edges' third moments show (`pooled_coma`, `local_coma`), simulates 12 nodes
of the pose whole and then every corner on its node's star at its own phase
and window, by one Gauss-Newton step from where its node's fit ended
(`PHASE`). Measured (doc/blur-map.md): 0.0029 px RMS from the centroid
truth on 10 near D435 poses under 1.5 waves of coma at the image corners,
noiseless, where the symmetric fit is 0.0247 px off.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from rotstar_mrcal.detect.edgespread import (BIN_PX, MAX_REACH, MIN_REACH, REACH_PER_WINDOW, edge_spread, local_psf,
                                             smooth_field)
from rotstar_mrcal.detect import coma_tables
from rotstar_mrcal.detect.refine import lowpass_for, prefilter, symmetric_refine, symmetric_step
from rotstar_mrcal.optics.psf import Optics, centroid_px, wavefront_psf
from rotstar_mrcal.optics.wavefront import Seidel


def _smooth_length(n: int) -> int:
    """The least 2^a 3^b 5^c >= n (a fast FFT length)"""
    best = 1 << max(n - 1, 0).bit_length()
    p5 = 1
    while p5 < best:
        p35 = p5
        while p35 < best:
            m = p35
            while m < n:
                m *= 2
            best = min(best, m)
            p35 *= 3
        p5 *= 5
    return best


def fftconvolve(a: np.ndarray, b: np.ndarray, mode: str = "full") -> np.ndarray:
    """2-D convolution over the last two axes (the others broadcast), mode "full" or "valid" as scipy.signal's

    numpy's FFT: scipy.signal takes 1.4 s to import (-X importtime), and every command that knows the methods
    imports this module.

    >>> a, b = np.arange(12.0).reshape(3, 4), np.array([[1.0, 2.0], [0.0, -1.0]])
    >>> np.round(fftconvolve(a, b, "valid"), 9).tolist()
    [[13.0, 15.0, 17.0], [21.0, 23.0, 25.0]]
    >>> fftconvolve(a, b).shape
    (4, 5)
    """
    ha, wa = a.shape[-2:]
    hb, wb = b.shape[-2:]
    full = (ha + hb - 1, wa + wb - 1)
    size = tuple(_smooth_length(n) for n in full)
    out = np.fft.irfft2(np.fft.rfft2(a, size) * np.fft.rfft2(b, size), size)[..., :full[0], :full[1]]
    if mode == "full":
        return out
    if mode != "valid":
        raise ValueError(f"mode must be 'full' or 'valid', not {mode!r}")
    return out[..., hb - 1 : ha, wb - 1 : wa]


PAD_PX = 2  # px beyond the window and the low-pass's reach in every rendered patch


def star_normals(jac: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """(N, K, 2, 2) unit image normals of frame k's two lines at each corner

    jac (N, 2, 2): camera px per display px at the corner; angles (K,): the
    frames' rotations (Layout.angle), the lines along angle and angle + pi/2.

    >>> np.round(star_normals(np.eye(2)[None], np.array([0.0]))[0, 0], 3)
    array([[-0.,  1.],
           [-1.,  0.]])
    """
    a = np.asarray(angles, float)
    t = np.stack((np.stack((np.cos(a), np.sin(a)), -1), np.stack((-np.sin(a), np.cos(a)), -1)), 1)  # (K, 2, 2)
    d = np.einsum("nij,klj->nkli", np.asarray(jac, float), t)
    n = np.stack((-d[..., 1], d[..., 0]), -1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def render_star_fft(kernels: np.ndarray, s: int, normals: np.ndarray, frac: np.ndarray, half: int) -> np.ndarray:
    """(N, K, 2 half + 1, 2 half + 1) pixels of the local star through each corner's PSF, by FFT (the reference)

    kernels (N, kh, kw): the PSFs at s sub-pixels per px (odd sizes, centred,
    sum 1); normals (N, K, 2, 2) from star_normals; frac (N, 2): the corner's
    position from the patch's centre pixel (its light lands there when the
    kernel is centred). Values in [-1, 1] (the pattern's two colours).
    """
    N, K = normals.shape[:2]
    kh, kw = kernels.shape[1:]
    P = 2 * half + 1

    def grid(n, m, f):  # sub-pixel centres, corner-relative, with m extra taps on each side
        return -half - 0.5 + (np.arange(-m, P * s + m) + 0.5) / s - f[:, None]

    xs, ys = grid(P, kw // 2, frac[:, 0]), grid(P, kh // 2, frac[:, 1])  # (N, Ws), (N, Hs)
    ramp = (np.abs(normals).sum(-1) / s)[..., None, None]  # (N, K, 2, 1, 1): a sub-pixel's extent along n
    dist = (normals[..., 0, None, None] * xs[:, None, None, None, :] +
            normals[..., 1, None, None] * ys[:, None, None, :, None])  # (N, K, 2, Hs, Ws)
    sharp = np.clip(2 * dist / ramp, -1, 1).prod(axis=2)
    blurred = fftconvolve(sharp, kernels[:, None], "valid")  # (N, K, P s, P s)
    return blurred.reshape(N, K, P, s, P, s).mean(axis=(3, 5))


BIN_UV = 0.25  # px: the grid the PSF's light is binned on along the two edge normals (render_star)
TAP_FLOOR = 1e-4  # kernel taps below this fraction of the largest are left out (bias: 0.0013 px RMS, half the time)


def render_star(kernels: np.ndarray, s: int, normals: np.ndarray, frac: np.ndarray, half: int) -> np.ndarray:
    """(N, K, 2 half + 1, 2 half + 1) pixels of the local star through each corner's PSF (as render_star_fft)

    kernels (N, kh, kw): the PSFs at s sub-pixels per px (odd sizes, centred,
    sum 1); normals (N, K, 2, 2) from star_normals; frac (N, 2): the corner's
    position from the patch's centre pixel (its light lands there when the
    kernel is centred). Values in [-1, 1] (the pattern's two colours).

    A checker corner is sign(n1 . x) sign(n2 . x), so a pixel at p sees
    E[sign(a - U) sign(b - V)] = 1 - 2 P(U > a) - 2 P(V > b) + 4 P(U > a, V > b)
    with a = n1 . p, b = n2 . p and (U, V) = (n1 . T, n2 . T), T drawn from
    the PSF convolved with the pixel's box: the light binned on a BIN_UV
    grid in (U, V) per frame (linear shares), its joint survival function
    by cumulative sums (star_light), read bilinearly at every pixel
    (star_pixels). On 16 corners with 0.3-2 waves of coma the simulated
    bias differs from the FFT rendering's by 0.0003 px RMS (of 0.063 px) at
    half the time with every tap, 0.0013 px with the taps under TAP_FLOOR
    left out (at a fifth).
    """
    light = star_light(kernels, s, normals)
    return star_pixels(light, normals, frac, half, np.arange(len(normals)))


def star_light(kernels: np.ndarray, s: int, normals: np.ndarray) -> tuple[np.ndarray, float]:
    """(T (N, K, nb + 1, nb + 1), R px) the joint survival function of (n1 . T, n2 . T) per corner and frame

    T[n, k, i, j]: the light of kernel n (with the pixel's box) whose projections on frame k's two normals
    are in bins >= i and >= j of the BIN_UV grid that starts at -R (render_star). Summed in float64, kept in
    float32 (star_pixels reads it so: a tenth of its precision is 1e-7 of the light, and the patches are
    fitted in float32).
    """
    N, K = normals.shape[:2]
    kh, kw = kernels.shape[1:]
    E = fftconvolve(kernels, np.ones((1, s, s)) / s ** 2)
    ty = (np.arange(E.shape[1]) - kh // 2 - (s - 1) / 2) / s
    tx = (np.arange(E.shape[2]) - kw // 2 - (s - 1) / 2) / s
    E = E.reshape(N, -1)
    keep = np.abs(E).max(axis=0) > TAP_FLOOR * np.abs(E).max()
    t = np.stack(np.broadcast_arrays(tx[None, :], ty[:, None]), -1).reshape(-1, 2)[keep]  # (M, 2)
    m = E[:, keep] * (E.sum(axis=1) / E[:, keep].sum(axis=1))[:, None]  # the light left out spread over the rest
    R = float(np.linalg.norm(t, axis=1).max()) + 2 * BIN_UV
    nb = int(np.ceil(2 * R / BIN_UV)) + 2
    x = (np.einsum("nkli,mi->nklm", normals, t) + R) / BIN_UV  # (N, K, 2, M) in bins
    i0 = np.floor(x).astype(np.intp)
    f = x - i0
    base = (np.arange(N * K) * nb * nb).reshape(N, K, 1)
    acc = np.zeros(N * K * nb * nb)
    for du in (0, 1):
        wu = f[:, :, 0] if du else 1 - f[:, :, 0]
        for dv in (0, 1):
            wv = f[:, :, 1] if dv else 1 - f[:, :, 1]
            idx = base + (i0[:, :, 0] + du) * nb + i0[:, :, 1] + dv
            acc += np.bincount(idx.ravel(), (m[:, None, :] * wu * wv).ravel(), minlength=N * K * nb * nb)
    T = np.zeros((N, K, nb + 1, nb + 1), np.float32)  # T[i, j]: the light of bins >= i along n1 and >= j along n2
    T[:, :, :nb, :nb] = acc.reshape(N, K, nb, nb)[:, :, ::-1, ::-1].cumsum(2).cumsum(3)[:, :, ::-1, ::-1]
    return T, R


def star_pixels(light: tuple[np.ndarray, float], normals: np.ndarray, frac: np.ndarray, half: int,
                source: np.ndarray) -> np.ndarray:
    """(n, K, 2 half + 1, 2 half + 1) the stars of star_light's light[source] (n,) at sub-pixel positions frac (n, 2)

    normals (N, K, 2, 2): those light was made with (source picks them too).
    """
    T, R = light
    nb = T.shape[-1] - 1
    nrm = (normals[source] / BIN_UV).astype(np.float32)  # in bins, in float32 as the table (star_light)
    o = np.arange(-half, half + 1, dtype=np.float32)
    px = (o[None, :] - frac[:, 0, None].astype(np.float32))[:, None, None, None, :]  # (n, 1, 1, 1, P)
    py = (o[None, :] - frac[:, 1, None].astype(np.float32))[:, None, None, :, None]
    xa = nrm[..., 0, None, None] * px + nrm[..., 1, None, None] * py  # (n, K, 2, P, P) bins from the start
    xa += np.float32((R + BIN_UV / 2) / BIN_UV)
    np.clip(xa, 0, np.float32(nb - 1e-3), out=xa)
    j = np.floor(xa)
    g = xa - j
    j = j.astype(np.intp)
    m = nb + 1
    flat = T.reshape(-1)
    base = ((np.asarray(source)[:, None] * T.shape[1] + np.arange(nrm.shape[1])[None]) * m * m)[:, :, None, None]
    ja, jb, ga, gb = j[:, :, 0], j[:, :, 1], g[:, :, 0], g[:, :, 1]
    ia = base + ja * m  # (row starts)

    def at(i):  # T[source, k] at flat offsets i (np.take on the flat table: a fraction of fancy indexing's time)
        return np.take(flat, i)

    b00, b10 = at(ia + jb), at(ia + m + jb)
    b01, b11 = at(ia + jb + 1), at(ia + m + jb + 1)
    both = b00 + ga * (b10 - b00) + gb * ((b01 + ga * (b11 - b01)) - (b00 + ga * (b10 - b00)))
    pu = at(ia)
    pu += ga * (at(ia + m) - pu)
    pv = at(base + jb)
    pv += gb * (at(base + jb + 1) - pv)
    return 1 - 2 * pu - 2 * pv + 4 * both


CHUNK = 32  # corners per mosaic fitted at once
SIM_TOL = 1e-3  # px: the simulated fits stop when a step is below this (as the real fit)
STAR_FFT = False  # simulated_bias renders every corner's star by FFT (render_star_fft; psfcheck --star-fft)


def simulated_bias(kernels, s, normals, corners, windows, lowpass_sigma: float, chunk: int | None = None,
                   source: np.ndarray | None = None, light=None, start=None, steps: int = 1) -> np.ndarray:
    """(N, 2) the symmetric fit's corner less the PSF's centre, on the local star rendered through each kernel

    corners (N, 2): where the real corners are (their sub-pixel phase is
    kept); windows (N,): the fit's half-windows; lowpass_sigma: the Gaussian
    the frames are low-passed by before the fit (pipeline.prefilter). The
    patches are tiled into one image per frame and fitted as a pose is: the
    same offsets, damping and stopping rule. NaN where the fit fails.
    source (N,): corner i's star is that of kernels[source[i]] and
    normals[source[i]] (one light table per kernel; None: its own); light:
    star_light(kernels, s, normals) if already made. start (N, 2): not
    the whole fit but `steps` Gauss-Newton steps (refine.symmetric_step)
    from the PSF's centre plus start, where the fit is expected to end
    (one step from within a few thousandths of a px of it is within 1e-4
    px of the whole fit, at a third of its cost; NaN where a sample would
    leave the patch).
    """
    q = np.asarray(corners, float)
    w = np.asarray(windows, float)
    N = len(q)
    out = np.full((N, 2), np.nan)
    if not N:
        return out
    chunk = CHUNK if chunk is None else chunk
    src = np.arange(N) if source is None else np.asarray(source)
    if STAR_FFT:  # one kernel per corner, no light table
        return _simulated_bias_with(lambda sel, fr, h: render_star_fft(kernels[src[sel]], s, normals[src[sel]], fr, h),
                                    q, w, lowpass_sigma, chunk)
    light = star_light(kernels, s, normals) if light is None else light
    return _simulated_bias_with(lambda sel, fr, h: star_pixels(light, normals, fr, h, src[sel]), q, w, lowpass_sigma,
                                chunk, start, steps)


def _simulated_bias_with(star, q, w, lowpass_sigma, chunk, start=None, steps=1):
    """simulated_bias with star(sel, frac (n, 2), half) -> the patches (n, K, P, P) of corners [sel] (indices)

    The corners go in chunks by increasing window, each chunk's patches as
    large as its largest window needs (a third of the pixels where the
    windows range 3-8 px).
    """
    N = len(q)
    out = np.full((N, 2), np.nan)
    reach = int(math.ceil(4 * lowpass_sigma)) + PAD_PX
    frac = q - np.round(q)
    order = np.argsort(w, kind="stable")
    for a in range(0, N, chunk):
        sel = order[a:a + chunk]
        half = int(np.ceil(w[sel].max())) + reach
        P = 2 * half + 1
        patches = star(sel, frac[sel], half)
        n, K = patches.shape[:2]
        cols = int(math.ceil(math.sqrt(n)))
        rows = int(math.ceil(n / cols))
        mosaic = np.zeros((K, rows * P, cols * P), np.float32)
        r, c = np.divmod(np.arange(n), cols)
        for i in range(n):
            mosaic[:, r[i] * P:(r[i] + 1) * P, c[i] * P:(c[i] + 1) * P] = patches[i]
        at = np.stack((c * P + half + frac[sel, 0], r * P + half + frac[sel, 1]), -1)
        if start is not None:  # Gauss-Newton steps from near the optimum (symmetric_step)
            low, b = prefilter(mosaic, lowpass_sigma), start[sel]
            for _ in range(steps):
                b = b + symmetric_step(low, at + b, w[sel])
            out[sel] = b
            continue
        fit = symmetric_refine(prefilter(mosaic, lowpass_sigma), at, w[sel], tol=SIM_TOL)
        out[sel] = fit.corners - at
    return out


# ---------------------------------------------------------------------------
# the local PSF from the edges' moments: a Seidel wavefront (coma, focus) per region
# ---------------------------------------------------------------------------
KERNEL_STEP = 0.1  # waves: the local coma and focus are rounded to this for the kernels that are rendered
SUPERSAMPLE = 4


def seidel_kernel(coma: float, focus: float, angle: float, optics=None, s: int = SUPERSAMPLE) -> np.ndarray:
    """The wavefront PSF of coma (waves, its tail along `angle`) and focus, its centroid at its centre (as LensPSF's)

    As the simulator's lens (optics.psf.LensPSF); cached on the values rounded to KERNEL_STEP and 1 degree.
    """
    r = KERNEL_STEP
    return _seidel_kernel(round(coma / r) * r, round(focus / r) * r, round(math.degrees(angle)) % 360,
                          optics or Optics(), s)


@functools.lru_cache(maxsize=512)
def _seidel_kernel(coma, focus, angle_deg, optics, s):
    a = math.radians(angle_deg)
    return wavefront_psf(Seidel(tilt=-coma, coma=coma, focus=focus, tilt_angle=a, coma_angle=a), optics, s,
                         zero_centroid=True)


def tilted_kernel(coma: float, angle: float, optics=None, s: int = SUPERSAMPLE) -> tuple[np.ndarray, np.ndarray]:
    """(kernel, its centroid (2,) px) of coma (waves, tail along `angle`) with the tilt -coma that centres it uncropped

    seidel_kernel without its centring (a third of the time): the crop
    leaves the light's centroid 0.01-0.02 px from the kernel's centre,
    which the caller allows for. Cached on the values rounded as seidel_kernel's.
    """
    r = KERNEL_STEP
    return _tilted_kernel(round(coma / r) * r, round(math.degrees(angle)) % 360, optics or Optics(), s)


@functools.lru_cache(maxsize=1024)
def _tilted_kernel(coma, angle_deg, optics, s):
    a = math.radians(angle_deg)
    k = wavefront_psf(Seidel(tilt=-coma, coma=coma, tilt_angle=a, coma_angle=a), optics, s)
    return k, centroid_px(k, s)


TABLE_COMA = np.arange(0.0, 4.01, 0.25)  # waves of local coma in the table of measured third moments


def coma_table(reach: float, optics) -> np.ndarray:
    """(len(TABLE_COMA),) the third moment edgespread measures (A, px^3) on the local star through each coma

    For the default Optics at the reaches edgespread uses (MIN_REACH to
    MAX_REACH in BIN_PX steps) the table is read from detect/coma_tables.py
    (written by scripts/coma_tables.py; computing one takes 0.3 s of a
    process's first pose at that reach, 2.4 s of an 8-pose dataset);
    otherwise computed_coma_table.
    """
    if optics == Optics():
        shipped = coma_tables.TABLES.get(round(float(reach), 6))
        if shipped is not None and len(shipped) == len(TABLE_COMA):
            return np.array(shipped)
    return computed_coma_table(reach, optics)


TABLE_ANGLES = np.radians([0.0, 15.0, 30.0, 45.0])  # the coma's directions to the pixel grid ...
TABLE_PHASES = tuple((x, y) for y in (-0.375, -0.125, 0.125, 0.375) for x in (-0.375, -0.125, 0.125, 0.375))
# ... and the corner's sub-pixel phases (a 4 x 4 grid) the table averages over


@functools.lru_cache(maxsize=64)
def computed_coma_table(reach: float, optics) -> np.ndarray:
    """coma_table computed: the star (square pixels, window reach / REACH_PER_WINDOW) rendered
    through seidel_kernel(coma, 0, angle) and read by local_psf with this
    reach, as the real corners are: the table carries what the ESF reading
    does to the moments (the tail beyond the reach, the levels it is
    normalised by, the pixel box). The third moment read along the coma's
    direction is averaged over TABLE_ANGLES x TABLE_PHASES: at a single
    direction and phase (the corner at a pixel's centre, the tail along a
    pixel row) the reading is 2-14 % above the mean over them, and the
    comas of real corners, at every phase and direction, came out 11 %
    low under 1.5 waves.
    """
    normals = star_normals(np.eye(2)[None], np.arange(8) * np.pi / 16)
    frac = np.array(TABLE_PHASES)
    n = len(frac)
    w = reach / REACH_PER_WINDOW
    half = int(np.ceil(w)) + 3
    P = 2 * half + 1
    at = np.stack((np.arange(n) * P + half + frac[:, 0], half + frac[:, 1]), -1)  # the stars side by side
    out = np.zeros(len(TABLE_COMA))
    for i, c in enumerate(TABLE_COMA[1:], 1):
        for a in TABLE_ANGLES:
            k = seidel_kernel(c, 0.0, a, optics)
            stars = render_star(np.broadcast_to(k, (n,) + k.shape), SUPERSAMPLE, normals.repeat(n, 0), frac, half)
            e = local_psf(np.concatenate(list(stars), axis=-1), at, w, reach=reach)[1]  # (8, P, n P)
            out[i] += np.nanmean(e.coma * np.cos(e.coma_angle - a)) / len(TABLE_ANGLES)
    return np.maximum.accumulate(out)


def local_coma(third: np.ndarray, reach: float, optics=None) -> np.ndarray:
    """(N,) waves of coma (focus 0) whose measured third moment at this reach is third (N,) (coma_table)

    >>> t = coma_table(2.0, Optics())
    >>> np.round(local_coma(t[[2, 6]], 2.0), 2).tolist()
    [0.5, 1.5]
    """
    t = coma_table(round(float(reach) / BIN_PX) * BIN_PX, optics or Optics())
    return np.interp(np.asarray(third, float), t + np.arange(len(t)) * 1e-9, TABLE_COMA)


def _turned(v: np.ndarray, a: np.ndarray) -> np.ndarray:
    """vectors v (N, ..., 2) turned by angles a (N,) (radians, from x toward y)"""
    c, s = (f(a).reshape((-1,) + (1,) * (v.ndim - 2)) for f in (np.cos, np.sin))
    return np.stack((c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1]), -1)


def _padded(ks) -> np.ndarray:
    """(n, m, m) the odd square kernels ks centred in one size"""
    m = max(k.shape[0] for k in ks)
    out = np.zeros((len(ks), m, m))
    for i, k in enumerate(ks):
        p = (m - k.shape[0]) // 2
        out[i, p:p + k.shape[0], p:p + k.shape[1]] = k
    return out


def plane_with_sd(xy: np.ndarray, v: np.ndarray, at: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(values (M, 2), sd (M,)) of the least-squares plane through v (N, 2) at points xy (N, 2), read at (M, 2)

    sd: the standard deviation of each component at `at`, from the scatter
    about the plane (refitted once without the points beyond 3 robust sigmas).

    >>> xy = np.array([[0.0, 0.0], [10, 0], [0, 10], [10, 10], [5, 5]])
    >>> v, sd = plane_with_sd(xy, np.stack((xy[:, 0] * 0.1, np.ones(5)), -1), np.array([[20.0, 0.0]]))
    >>> np.round(v, 3).tolist(), bool(sd[0] < 1e-9)
    ([[2.0, 1.0]], True)
    """
    c = xy.mean(axis=0)
    sc = np.maximum(np.ptp(xy, axis=0) / 2, 1e-9)

    def design(p):
        return np.column_stack((np.ones(len(p)), (p - c) / sc))

    A, B = design(xy), design(at)
    keep = np.ones(len(v), bool)
    for _ in range(2):
        coef = np.linalg.lstsq(A[keep], v[keep], rcond=None)[0]
        r = np.linalg.norm(v - A @ coef, axis=1)
        keep = r <= 3 * 1.4826 * np.median(r[keep]) + 1e-12
    n = int(keep.sum())
    s2 = (r[keep] ** 2).sum() / max(2 * (n - 3), 1)
    lev = np.einsum("mi,ij,mj->m", B, np.linalg.pinv(A[keep].T @ A[keep]), B)
    return B @ coef, np.sqrt(s2 * lev)


def spread_nodes(xy: np.ndarray, n: int) -> np.ndarray:
    """Indices of n of the points xy (N, 2) spread over them: farthest-point sampling from the most central

    >>> spread_nodes(np.array([[0.0, 0.0], [1.0, 0.0], [5.0, 0.0], [10.0, 0.0]]), 3).tolist()
    [2, 0, 3]
    """
    xy = np.asarray(xy, float)
    pick = [int(np.argmin(np.linalg.norm(xy - xy.mean(axis=0), axis=1)))]
    d = np.linalg.norm(xy - xy[pick[0]], axis=1)
    while len(pick) < min(n, len(xy)):
        pick.append(int(np.argmax(d)))
        d = np.minimum(d, np.linalg.norm(xy - xy[pick[-1]], axis=1))
    return np.array(pick, int)


NODES = 12  # corners per pose where the bias is simulated; a smooth field carries it to the others
DEGREE = 2  # of that field
PHASE = True  # bias_correct: every corner's own sub-pixel phase and window simulated on its node's star
PHASE_ANGLE_STEP = math.radians(5.0)  # ... through a kernel at its coma's angle rounded to this
# (doc/blur-map.md: on 10 near poses under coma 1.5, noiseless, the pooled correction leaves 0.41 x the symmetric
# fit's pose-dependent part; False: the nodes' biases alone, carried by the smooth field)
MAX_SAMPLES = 64  # corners per pose whose coma coma_samples reads
COMA_SIGNIFICANCE = 3.0  # a pooled coma below this many standard deviations of its plane is taken as 0


def coma_samples(frames, corners, window, shifts=None, min_window: float = 4.0,
                 optics=None) -> tuple[np.ndarray, np.ndarray]:
    """(xy (M, 2), coma vectors (M, 2), waves along the tail) of the corners whose edges show it

    Each corner of min_window or more has its edge-spread third moment read
    (edgespread.local_psf, one reach for the call: 0.45 x the median
    half-window, at least MIN_REACH, and the corners whose window holds it)
    and turned into waves of coma (local_coma, focus 0) along its measured
    direction. Corners with edges missing are left out. Of more than
    MAX_SAMPLES such corners, MAX_SAMPLES spread over the pose are read (the
    plane they feed has 6 numbers; a dataset pools every pose's).
    """
    q, w = np.asarray(corners, float).reshape(-1, 2), np.broadcast_to(np.asarray(window, float), (len(corners),))
    meas = np.isfinite(q).all(axis=1) & (w >= min_window)
    if not meas.any():
        return np.zeros((0, 2)), np.zeros((0, 2))
    L = float(np.floor(np.clip(REACH_PER_WINDOW * np.median(w[meas]), MIN_REACH, MAX_REACH) / BIN_PX) * BIN_PX)
    meas &= REACH_PER_WINDOW * w >= L - 1e-9
    if meas.sum() > MAX_SAMPLES:
        keep = np.flatnonzero(meas)[spread_nodes(q[meas], MAX_SAMPLES)]
        meas[:] = False
        meas[keep] = True
    _, est = local_psf(frames, q[meas], w[meas], None if shifts is None else np.asarray(shifts, float)[:, meas],
                       reach=L)
    good = np.isfinite(est.coma) & (est.edges >= 2 * _nframes(frames) - 2)
    cw = local_coma(est.coma[good], L, optics)
    return q[meas][good], cw[:, None] * np.stack((np.cos(est.coma_angle[good]), np.sin(est.coma_angle[good])), -1)


def pooled_coma(xy: np.ndarray, vec: np.ndarray, at: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(waves (M,), tail angle (M,)) of the coma at points at (M, 2) from coma_samples' (xy, vec)

    The vectors pooled by a plane over the image (Seidel coma grows linearly
    with the field radius) and read at `at`; a coma below COMA_SIGNIFICANCE
    standard deviations of the plane there is 0.
    """
    cv, sd = plane_with_sd(xy, vec, at)
    c = np.hypot(cv[:, 0], cv[:, 1])
    return np.where(c > COMA_SIGNIFICANCE * sd, c, 0.0), np.arctan2(cv[:, 1], cv[:, 0])


def _nframes(frames) -> int:
    return 1 if np.ndim(frames) == 2 else len(frames)


def measured_normals(frames, corners, window, shifts=None) -> np.ndarray:
    """(N, K, 2, 2) each frame's two edge normals at the corners, as edgespread measures them"""
    ang = edge_spread(frames, corners, window, shifts, reach=MIN_REACH).normal.reshape(len(corners), -1, 2)
    return np.stack((np.cos(ang), np.sin(ang)), -1)


def bias_correct(frames, corners, window, shifts=None, jac=None, angles=None, lowpass_sigma: float | None = None,
                 nodes: int = NODES, degree: int = DEGREE, optics=None, min_window: float = 4.0,
                 samples: tuple[np.ndarray, np.ndarray] | None = None, phase: bool | None = None) -> np.ndarray:
    """(N, 2) the symmetric fit's corners (N, 2) less their simulated bias: the light's centroid

    frames (K, H, W) the raw rotating-star frames the corners were fitted on
    (low-passed by lowpass_sigma first; None: refine.lowpass_for the
    windows, as detect_pose), window (N,) the fit's half-windows, shifts
    (K, N, 2) display offsets or None. The local PSF: pooled_coma at `nodes`
    corners spread over the pose (spread_nodes), of this pose's coma_samples
    or of `samples` (xy, vectors) given (e.g. a dataset's). The local pattern: jac
    (N, 2, 2) camera px per display px with angles (K,) the frames'
    rotations, or (None) the edge normals measured at the nodes. The bias
    of the same fit on the local star through that PSF (simulated_bias):
    phase (None: PHASE, True by default): every corner's own, on its
    nearest node's star (kernel and normals) at its own window and at the
    sub-pixel phase of its estimated centroid, plus the change from the
    node to it of the smooth field (`degree`) of the nodes' biases at phase
    0 (_phase_correct: the fit's offset changes with the corner's phase by
    some 0.002-0.003 px in a way no smooth field follows); not phase: the
    nodes' biases (the kernel computed with its tail along +x and the
    pattern turned instead) carried to every corner by the smooth field.
    Fewer than 2 x the field's terms of corners measured or simulated, or
    no coma at any node: the corners are returned unchanged; a node without
    coma has no bias.
    """
    q = np.asarray(corners, float).reshape(-1, 2)
    w = np.broadcast_to(np.asarray(window, float), (len(q),))
    idx = np.flatnonzero(np.isfinite(q).all(axis=1) & np.isfinite(w))
    enough = (degree + 1) * (degree + 2)
    if len(idx) < enough:
        return q.copy()
    nd = idx[spread_nodes(q[idx], nodes)]
    xy, vec = coma_samples(frames, q, w, shifts, min_window, optics) if samples is None else samples
    if len(xy) < enough:
        return q.copy()
    c, a = pooled_coma(xy, vec, q[nd])
    if not c.any():  # no coma shown: the symmetric fit is where the light's centroid is
        return q.copy()
    if jac is not None:
        normals = star_normals(np.asarray(jac, float)[nd], angles)
    else:
        normals = measured_normals(frames, q[nd], w[nd], None if shifts is None else np.asarray(shifts)[:, nd])
    sigma = lowpass_for(w[idx]) if lowpass_sigma is None else lowpass_sigma
    if not (PHASE if phase is None else phase):
        kern = _padded([seidel_kernel(ci, 0.0, 0.0, optics) for ci in c])
        b = _turned(simulated_bias(kern, SUPERSAMPLE, _turned(normals, -a), q[nd], w[nd], sigma), a)
        b[c == 0] = 0.0  # (the sharp diffraction kernel's own small offsets from the pixel grid are not the lens's)
        ok = np.isfinite(b).all(axis=1)
        out = q.copy()
        if ok.sum() >= enough:
            out[idx] -= smooth_field(q[nd][ok], b[ok], degree, at=q[idx])
        return out
    return _phase_correct(q, idx, nd, w, c, a, normals, sigma, degree, optics)


def _phase_correct(q, idx, nd, w, c, a, normals, sigma, degree, optics) -> np.ndarray:
    """bias_correct (phase): every corner on its node's star at its own window and at the sub-pixel phase of where
    its light's centroid is, plus the change from its node to it of the smooth field of the nodes' biases at
    phase 0 (the bias is smooth over the image at a fixed phase, not from corner to corner at theirs)"""
    # the node's kernel at its coma's angle rounded to PHASE_ANGLE_STEP (kernels cached), the pattern turned by
    # the rest (at most half a step: turning it by the whole angle turns the pixel grid against it too)
    aq = np.round(a / PHASE_ANGLE_STEP) * PHASE_ANGLE_STEP
    kc = [tilted_kernel(ci, ai, optics) for ci, ai in zip(c, aq)]
    kern, cen = _padded([k for k, _ in kc]), np.array([m for _, m in kc])  # (the light lands at cen, not 0)
    normals = _turned(normals, aq - a)
    light = star_light(kern, SUPERSAMPLE, normals)
    b0t = simulated_bias(kern, SUPERSAMPLE, normals, np.round(q[nd]), w[nd], sigma, light=light,
                         start=np.zeros((len(nd), 2)), steps=2)  # (two steps from the centre: 1e-4 px)
    b0 = _turned(b0t - cen, a - aq)
    b0[c == 0] = 0.0  # (the sharp diffraction kernel's own small offsets from the pixel grid are not the lens's)
    ok = np.isfinite(b0).all(axis=1)
    out = q.copy()
    if ok.sum() < (degree + 1) * (degree + 2):
        return out
    field = smooth_field(q[nd][ok], b0[ok], degree, at=np.concatenate((q[idx], q[nd])))
    near = np.argmin(np.linalg.norm(q[idx, None] - q[nd][None], axis=2), axis=1)  # each corner's node
    near[np.searchsorted(idx, nd)] = np.arange(len(nd))  # (a node is its own)
    guess = field[:len(idx)]
    # each corner's star with its light at the phase of the corner's centroid, fitted by one Gauss-Newton step from
    # where its node's fit ended (symmetric_step: within 1e-4 px of the whole fit, for a third of its cost)
    own = simulated_bias(kern, SUPERSAMPLE, normals, q[idx] - guess - cen[near], w[idx], sigma, source=near,
                         light=light, start=np.nan_to_num(b0t[near]))
    own = _turned(own - cen[near], (a - aq)[near])
    own[c[near] == 0] = 0.0
    step = own + guess - field[len(idx):][near]
    out[idx] -= np.where(np.isfinite(step).all(axis=1)[:, None], step, guess)
    return out

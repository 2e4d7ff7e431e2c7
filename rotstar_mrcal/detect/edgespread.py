"""The local PSF from the rotating star's edges: edge-spread moments per corner (issue 24)

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.detect.edgespread import local_psf
    >>> yy, xx = np.mgrid[0:48, 0:48] - np.array([24.3, 23.6])[:, None, None]
    >>> frames = np.stack([np.tanh((np.cos(t) * xx + np.sin(t) * yy) / 0.8)
    ...                    * np.tanh((-np.sin(t) * xx + np.cos(t) * yy) / 0.8)
    ...                    for t in np.arange(8) * np.pi / 16]).astype(np.float32)
    >>> es, est = local_psf(frames, np.array([[23.5, 24.4]]), 10.0)
    >>> np.round(est.centroid + [23.5, 24.4], 1)         # the edges' centroid lines meet at the corner
    array([[23.6, 24.3]])
    >>> float(np.round(est.width[0], 1)), bool(est.elongation[0] < 0.05), int(est.edges[0])
    (0.7, True, 16)

(point-sampled frames: the true width is that of a logistic of scale 0.4,
0.73 px, less the pixel box's 1/12 px^2 edge_spread takes off: 0.67 px.)

In frame k of the rotating star every corner is crossed by two straight
edges. Across an edge with unit normal n the image is the cumulative
distribution (the edge-spread function, ESF) of n . Y, Y ~ the PSF, placed
where the sharp edge is: its derivative (the line-spread function) is the
PSF's projection onto n. The eight frames give 16 edge directions, so the
moments of the 16 projections are those of the PSF:

    mean   m1(phi) = n . (c - q0)      c: where the sharp edges meet, the light's
                                       centroid (the PSF's centroid held at the corner)
    var    m2(phi) = s0 + s2c cos 2phi + s2s sin 2phi      (+ 1/12: the pixel box)
    third  m3(phi) = A cos phi + B sin phi + C cos 3phi + D sin 3phi

q0 is the corner the moments are taken about (the symmetric fit's). Least
squares over the 16 edges gives the centroid offset c - q0, the width
sqrt(s0) (RMS of the PSF along a direction, averaged over directions), the
elongation |s2| / s0 with its direction (of the long axis), and the coma
vector (A, B) (the cos-phi part of the third moment, px^3: where the light's
tail points) with its direction; C, D (trefoil) are fitted and not reported.
Each comes with a standard deviation from the scatter of the fit.

How an edge's moments are measured (`edge_spread`): the two edge directions
of each frame from the frame's gradients about the corner (the 4th harmonic of
the gradient angle, then the 2nd within each edge's pixels); the levels of the
two colours from the pixels at least `reach` from both edges; the ESF from
the pixels within `reach` of the edge and at least `reach` from the other
(inside the square window), from both halves of the edge (their level errors
cancel), binned every BIN_PX along n; the moments as integrals of the ESF F
against a smooth reference CDF R whose moments are known,
E[X^j] = E_R[X^j] + integral of j u^(j-1) (R(u) - F(u)) du over [-L, L],
L = reach. A PSF wider than the reach is truncated there: the moments are
those of the PSF clipped to +-reach, and the centroid that of that light.

Uses: psf_correct (rotstar-detect --refine psf: the symmetric fit's corners
moved toward the light's centroid) and blur_columns (rotstar-detect
--blur-map, detect/blurmap.py). The measurements against the simulator's
true PSFs and the centroid truth are in doc/blur-map.md.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

BIN_PX = 0.25  # ESF bin along the edge normal, px
MAX_REACH = 5.0  # px: the farthest the ESF is read from the edge
REACH_PER_WINDOW = 0.45  # ... and at most this fraction of the corner's half-window
MIN_REACH = 2.0
PIXEL_VAR = 1.0 / 12  # variance of a unit pixel's projection on any direction


@dataclasses.dataclass
class EdgeSpread:
    """Moments of every edge's spread about each corner: arrays (N, E), E = 2 nframes, NaN = not measured"""

    normal: np.ndarray  # angle of the edge normal n (radians; the ESF rises along +n)
    mean: np.ndarray  # first moment of the LSF, px along n from the corner the moments are taken about
    var: np.ndarray  # its central second moment, px^2 (pixel box removed)
    third: np.ndarray  # its central third moment, px^3
    reach: np.ndarray  # (N,) L, px


@dataclasses.dataclass
class PSFEstimate:
    """Per corner (N,): the local PSF's few parameters with their standard deviations"""

    centroid: np.ndarray  # (N, 2) c - q0: where the light's centroid is, from the corner given
    centroid_cov: np.ndarray  # (N, 2, 2)
    width: np.ndarray  # sqrt(s0), px
    width_sd: np.ndarray
    elongation: np.ndarray  # |s2| / s0 (0 round)
    elongation_angle: np.ndarray  # direction of the long axis, radians in [0, pi)
    coma: np.ndarray  # |(A, B)|, px^3
    coma_sd: np.ndarray
    coma_angle: np.ndarray  # where the light's tail points, radians in (-pi, pi]
    edges: np.ndarray  # edges used


def _patches(frames, corners, half, shifts):
    """(values, d/dx, d/dy (N, K, M), offsets d (N, K, M, 2) from the corner, inside (N, K, M)) of a (2 half + 1)^2 square

    The derivatives are central differences (one-sided at the image's border).
    """
    K, H, W = frames.shape
    c = corners[:, None, :] + (0 if shifts is None else np.transpose(shifts, (1, 0, 2)))  # (N, K, 2)
    ic = np.round(c).astype(int)
    o = np.arange(-half, half + 1)
    oy, ox = np.meshgrid(o, o, indexing="ij")
    px = ic[..., 0, None] + ox.ravel()
    py = ic[..., 1, None] + oy.ravel()
    inside = (px >= 0) & (px < W) & (py >= 0) & (py < H)
    x, y = np.clip(px, 0, W - 1), np.clip(py, 0, H - 1)
    flat = frames.reshape(-1)  # (edge_spread made it contiguous)
    row = np.arange(K)[None, :, None] * (H * W) + y * W  # (np.take on the flat frames: fancy indexing's result,
    v = np.take(flat, row + x)  # at a fraction of its time)
    xl, xr, yu, yd = np.maximum(x - 1, 0), np.minimum(x + 1, W - 1), np.maximum(y - 1, 0), np.minimum(y + 1, H - 1)
    gx = (np.take(flat, row + xr) - np.take(flat, row + xl)) / np.maximum(xr - xl, 1)
    col = np.arange(K)[None, :, None] * (H * W) + x
    gy = (np.take(flat, col + yd * W) - np.take(flat, col + yu * W)) / np.maximum(yd - yu, 1)
    d = np.stack((px - c[..., 0, None], py - c[..., 1, None]), axis=-1)
    return v, gx, gy, d, inside


def _along(d, normals):
    """(N, K, 2, M) the offsets d (N, K, M, 2) along each of the two edge normals (N, K, 2) (angles)"""
    return (d[:, :, None, :, 0] * np.cos(normals)[..., None] + d[:, :, None, :, 1] * np.sin(normals)[..., None])


def edge_normals(gx: np.ndarray, gy: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(..., 2) the normal angles of a corner's two edges from its gradients (..., M)

    >>> y, x = np.mgrid[-6:7, -6:7].astype(float)
    >>> t = 0.3; img = np.tanh(np.cos(t) * x + np.sin(t) * y) * np.tanh(-np.sin(t) * x + np.cos(t) * y)
    >>> gy, gx = np.gradient(img)
    >>> np.round(np.sort(edge_normals(gx.ravel(), gy.ravel(), np.ones(169, bool)) % np.pi), 2)
    array([0.32, 1.89])

    (the pixels near the corner pull it a little: edge_spread refines each
    edge's angle on its own strip, edge_angle)
    """
    z2 = (gx + 1j * gy) ** 2 * mask  # |g|^2 exp(2i angle)
    phi0 = np.angle((z2 * z2 / np.maximum(np.abs(z2), 1e-30)).sum(-1)) / 4
    out = []
    for p in (phi0, phi0 + np.pi / 2):
        z = z2 * np.exp(-2j * p)[..., None]
        out.append(p + np.angle(np.where(z.real > 0, z, 0).sum(-1)) / 2)
    return np.stack(out, axis=-1)


def edge_angle(z2, mask, phi):
    """The normal angle (...) of one edge: the doubled-angle mean of the gradients z2 = (gx + i gy)^2 in mask"""
    z = (z2 * mask).sum(-1) * np.exp(-2j * phi)
    return np.where(np.abs(z) > 0, phi + np.angle(z) / 2, phi)


def _binned_esf(u, F, sel, L, nb):
    """(mean u, mean F) per bin (rows, nb) of samples u, F (rows, M) where sel, row r's bins from -L[r]; NaN: empty"""
    rows = u.shape[0]
    b = np.clip(np.floor((u + L[:, None]) / BIN_PX).astype(int), 0, nb - 1)
    idx = (np.arange(rows)[:, None] * nb + b)[sel]
    cnt = np.bincount(idx, minlength=rows * nb).reshape(rows, nb)
    su = np.bincount(idx, u[sel], rows * nb).reshape(rows, nb)
    sf = np.bincount(idx, F[sel], rows * nb).reshape(rows, nb)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(cnt > 0, su / cnt, np.nan), np.where(cnt > 0, sf / cnt, np.nan)


REFERENCE_SCALE = 0.8  # px: the logistic CDF the ESF is compared with (module doc)


def _reference(u):
    """The smooth reference CDF R(u): a logistic of scale REFERENCE_SCALE"""
    return 1.0 / (1.0 + np.exp(-np.asarray(u, float) / REFERENCE_SCALE))


@functools.lru_cache(maxsize=256)
def _reference_moments(L: float) -> np.ndarray:
    """E[X^j], j = 1, 2, 3, of the distribution with CDF R on [-L, L] (mass beyond put at the ends)"""
    u = np.linspace(-L, L, 20001)
    one_minus = 1.0 - _reference(u)
    return np.array([(-L) ** j + np.trapezoid(j * u ** (j - 1) * one_minus, u) for j in (1, 2, 3)])


MIN_BINS = 6  # an edge's ESF needs samples in this many bins


def _moments(u, F, L):
    """(mean, central var, central third) (3, rows) of the distributions with CDFs F sampled at u (rows, n)

    Row r lies on [-L[r], L[r]], its samples in increasing u (NaN: none).
    E[X^j] = E_R[X^j] + integral of j u^(j-1) (R - F) du by the trapezoid rule
    over the samples, the integrand taken as 0 at +-L: it is smooth and
    vanishes at both ends, so the rule is accurate even where the samples
    are a pixel apart (an edge along the pixel grid).
    """
    rows = u.shape[0]
    x = np.concatenate((-L[:, None], u, L[:, None]), axis=1)
    d = np.concatenate((np.zeros((rows, 1)), _reference(u) - F, np.zeros((rows, 1))), axis=1)
    ok = np.isfinite(x) & np.isfinite(d)
    # each valid point's previous valid point (the ends are always valid)
    pos = np.where(ok, np.arange(x.shape[1])[None], 0)
    prev = np.maximum.accumulate(pos, axis=1)
    prev = np.concatenate((np.zeros((rows, 1), int), prev[:, :-1]), axis=1)
    x0 = np.take_along_axis(x, prev, 1)
    d0 = np.take_along_axis(d, prev, 1)
    ok[:, 0] = False
    dx = np.where(ok, x - x0, 0.0)
    xs, ds, x0s, d0s = (np.where(ok, a, 0.0) for a in (x, d, x0, d0))
    ref = np.array([_reference_moments(float(v)) for v in L]).T  # (3, rows)
    e = [ref[j - 1] + (dx * (j * x0s ** (j - 1) * d0s + j * xs ** (j - 1) * ds) / 2).sum(1) for j in (1, 2, 3)]
    e1, e2, e3 = e
    out = np.stack((e1, e2 - e1 ** 2, e3 - 3 * e1 * e2 + 2 * e1 ** 3))
    out[:, ok.sum(1) - 1 < MIN_BINS] = np.nan
    return out


def edge_spread(frames, corners, window, shifts=None, reach=None) -> EdgeSpread:
    """Every edge's spread moments about corners (N, 2) on frames (K, H, W); see the module doc

    window: (N,) or one half-window (px, the square the pixels come from);
    shifts: (K, N, 2) per-frame offsets of the corner (display offsets);
    reach: L (px), default min(MAX_REACH, REACH_PER_WINDOW x window), a
    whole number of bins.
    """
    frames = np.ascontiguousarray(frames, np.float32)  # (once: _patches reads it flat, group by group)
    frames = frames[None] if frames.ndim == 2 else frames
    q = np.asarray(corners, float).reshape(-1, 2)
    N, K = len(q), len(frames)
    w = np.broadcast_to(np.asarray(window, float), (N,))
    L = np.broadcast_to(np.asarray(reach if reach is not None else
                                   np.clip(REACH_PER_WINDOW * w, MIN_REACH, MAX_REACH), float), (N,))
    L = np.where(np.isfinite(L), np.floor(L / BIN_PX + 1e-9) * BIN_PX, MIN_REACH)
    nan = np.full((N, 2 * K), np.nan)
    out = EdgeSpread(nan.copy(), nan.copy(), nan.copy(), nan.copy(), L)
    good = np.isfinite(q).all(axis=1) & np.isfinite(w)
    if not good.any():
        return out
    q, w, L = q[good], w[good], L[good]
    sh = None if shifts is None else np.asarray(shifts)[:, good]
    idx = np.flatnonzero(good)
    size = np.ceil(w).astype(int)
    for g in np.unique(size):  # each size of window on patches of its own size (not all on the largest's)
        m = size == g
        _edge_spread_group(out, idx[m], frames, q[m], w[m], L[m], None if sh is None else sh[:, m], int(g))
    return out


def _edge_spread_group(out, idx, frames, q, w, L, shifts, half):
    """edge_spread of corners q (n, 2) whose windows fit half, into out's rows idx"""
    K = len(frames)
    v, gx, gy, d, inside = _patches(frames, q, half, shifts)
    z2 = (gx + 1j * gy) ** 2
    sq = inside & (np.abs(d) <= w[:, None, None, None]).all(-1)
    normals = edge_normals(gx, gy, sq)  # (N, K, 2)
    Lc = L[:, None, None, None]
    for _ in range(2):  # again from each edge's own strip, away from the corner
        uv = _along(d, normals)  # (N, K, 2, M) distance along each edge's normal
        strip = sq[:, :, None] & (np.abs(uv) < Lc) & (np.abs(uv[:, :, ::-1]) >= Lc)
        normals = edge_angle(z2[:, :, None], strip, normals)
    uv = _along(d, normals)
    far = sq & (np.abs(uv) >= Lc).all(2)
    prod = np.sign(uv[:, :, 0] * uv[:, :, 1])
    cnt_p, cnt_m = (far & (prod > 0)).sum(-1), (far & (prod < 0)).sum(-1)
    hi = np.where(far & (prod > 0), v, 0).sum(-1) / np.maximum(cnt_p, 1)
    lo = np.where(far & (prod < 0), v, 0).sum(-1) / np.maximum(cnt_m, 1)
    contrast = np.where((cnt_p >= 3) & (cnt_m >= 3), hi - lo, np.nan)  # (N, K) signed
    mid = (hi + lo) / 2
    other = uv[:, :, ::-1]
    with np.errstate(invalid="ignore", divide="ignore"):
        F = 0.5 + np.sign(other) * ((v - mid[..., None]) / contrast[..., None])[:, :, None]  # (N, K, 2, M)
    sel = sq[:, :, None] & (np.abs(uv) < Lc) & (np.abs(other) >= Lc) & np.isfinite(F)
    nb = int(round(2 * L.max() / BIN_PX))
    Lr = np.repeat(L, K * 2)
    rows = [_binned_esf(uv.reshape(-1, uv.shape[-1]), F.reshape(-1, F.shape[-1]),
                        (sel & (np.sign(other) == side)).reshape(-1, sel.shape[-1]), Lr, nb) for side in (1, -1)]
    (ua, Fa), (ub, Fb) = rows
    both = np.isfinite(Fa) & np.isfinite(Fb)  # a bin with both halves: their mean (level errors cancel)
    um = np.where(both, (ua + ub) / 2, np.where(np.isfinite(Fa), ua, ub))
    Fm = np.where(both, (Fa + Fb) / 2, np.where(np.isfinite(Fa), Fa, Fb))
    m1, m2, m3 = (m.reshape(-1, K, 2) for m in _moments(um, Fm, Lr))
    for e in range(2):
        out.normal[idx, e::2] = normals[:, :, e]
        out.mean[idx, e::2] = m1[:, :, e]
        out.var[idx, e::2] = m2[:, :, e] - PIXEL_VAR
        out.third[idx, e::2] = m3[:, :, e]


def _harmonic_fit(y, cols):
    """Least squares per row of y (N, E) on columns (N, E, p), NaNs left out: (coef (N, p), cov (N, p, p), used (N,))"""
    ok = np.isfinite(y) & np.isfinite(cols).all(-1)
    A = np.where(ok[..., None], cols, 0.0)
    yy = np.where(ok, y, 0.0)
    p = cols.shape[-1]
    AtA = np.einsum("nep,neq->npq", A, A)
    used = ok.sum(-1)
    enough = used > p + 1
    AtA[~enough] = np.eye(p)
    inv = np.linalg.inv(AtA)
    coef = np.einsum("npq,nq->np", inv, np.einsum("nep,ne->np", A, yy))
    r = yy - np.einsum("nep,np->ne", A, coef)
    s2 = (r * r).sum(-1) / np.maximum(used - p, 1)
    coef[~enough] = np.nan
    return coef, inv * s2[:, None, None], used


def psf_estimate(es: EdgeSpread) -> PSFEstimate:
    """The few PSF parameters of each corner from its edges' moments (module doc), with standard deviations"""
    phi = es.normal
    c1, s1 = np.cos(phi), np.sin(phi)
    cen, cen_cov, used = _harmonic_fit(es.mean, np.stack((c1, s1), -1))
    v, v_cov, _ = _harmonic_fit(es.var, np.stack((np.ones_like(phi), np.cos(2 * phi), np.sin(2 * phi)), -1))
    t, t_cov, _ = _harmonic_fit(es.third, np.stack((c1, s1, np.cos(3 * phi), np.sin(3 * phi)), -1))
    s0 = np.maximum(v[:, 0], 1e-6)
    width = np.sqrt(s0)
    coma = np.hypot(t[:, 0], t[:, 1])
    # first-order propagation: d width = d s0 / (2 width); |(A, B)| along (A, B)
    unit = np.stack((t[:, 0], t[:, 1]), -1) / np.maximum(coma, 1e-12)[:, None]
    coma_var = np.einsum("np,npq,nq->n", unit, t_cov[:, :2, :2], unit)
    return PSFEstimate(cen, cen_cov, width, np.sqrt(v_cov[:, 0, 0]) / (2 * width),
                       np.hypot(v[:, 1], v[:, 2]) / s0, (np.arctan2(v[:, 2], v[:, 1]) / 2) % np.pi,
                       coma, np.sqrt(coma_var), np.arctan2(t[:, 1], t[:, 0]), used)


def projected_moments(kernel: np.ndarray, supersample: int, normals: np.ndarray, reach: float) -> EdgeSpread:
    """The same moments of a known PSF kernel (sub-pixel taps, as optics.psf), about its centroid: the truth

    The projection onto each normal, clipped to +-reach about the kernel's
    centroid (the light beyond put at +-reach) as edge_spread reads the ESF
    (no pixel box: it is removed there). normals: (E,) angles. One corner (arrays (1, E)).

    >>> from rotstar_mrcal.optics.psf import gaussian_psf
    >>> es = projected_moments(gaussian_psf(1.0, 4), 4, np.arange(16) * np.pi / 8, 5.0)
    >>> np.round(psf_estimate(es).width, 2)
    array([1.])
    """
    k = np.asarray(kernel, float)
    k = k / k.sum()
    h, w = k.shape
    s = float(supersample)
    yy, xx = np.mgrid[0:h, 0:w]
    x, y = (xx - w // 2) / s, (yy - h // 2) / s
    cx, cy = (k * x).sum(), (k * y).sum()
    out = []
    for phi in np.asarray(normals, float):
        u = np.clip(np.cos(phi) * (x - cx) + np.sin(phi) * (y - cy), -reach, reach)
        m1 = (k * u).sum()
        out.append((m1, (k * (u - m1) ** 2).sum(), (k * (u - m1) ** 3).sum()))
    a = np.array(out).T[:, None, :]
    return EdgeSpread(np.asarray(normals, float)[None], a[0], a[1], a[2], np.array([reach]))


def local_psf(frames, corners, window, shifts=None, reach=None, rounds: int = 2) -> tuple[EdgeSpread, PSFEstimate]:
    """(EdgeSpread, PSFEstimate) about the light's centroid: edge_spread re-centred `rounds` times

    The ESF is read over +-reach about the corner given; read about a point
    off the edge's centre the truncation is lopsided and shows as a third
    moment, so each round re-centres on the centroid found by the last one.
    The estimate's centroid is returned relative to `corners`.

    >>> yy, xx = np.mgrid[0:40, 0:40] - np.array([20.3, 19.6])[:, None, None]
    >>> frames = np.stack([np.tanh((np.cos(t) * xx + np.sin(t) * yy))
    ...                    * np.tanh((-np.sin(t) * xx + np.cos(t) * yy)) for t in np.arange(8) * np.pi / 16])
    >>> es, est = local_psf(frames, np.array([[19.2, 20.7]]), 10.0)
    >>> np.round(est.centroid, 1), bool(est.coma[0] < 0.02)
    (array([[ 0.4, -0.4]]), True)
    """
    q0 = np.asarray(corners, float).reshape(-1, 2)
    q = q0.copy()
    frames = np.ascontiguousarray(frames, np.float32)  # (once for the rounds)
    for _ in range(max(int(rounds), 1)):
        es = edge_spread(frames, q, window, shifts, reach)
        est = psf_estimate(es)
        step = np.where(np.isfinite(est.centroid), est.centroid, 0.0)
        q = q + np.clip(step, -1.0, 1.0)
    est.centroid = np.where(np.isfinite(est.centroid), q - q0 - np.clip(step, -1, 1) + est.centroid, np.nan)
    return es, est


PSF_MIN_WINDOW = 4.0  # px: a corner with a smaller half-window keeps the symmetric fit's position
MAX_CENTROID_STEP = 1.0  # px: a centroid farther than this from the symmetric corner is not believed


def smooth_field(xy: np.ndarray, values: np.ndarray, degree: int = 2, clip: float = 3.0, weights=None,
                 at=None) -> np.ndarray:
    """(N, 2) values (N, 2) at points xy (N, 2) replaced by a polynomial of x, y fitted to them (robustly)

    at: (M, 2) other points to evaluate the polynomial at, (M, 2) returned.

    Least squares on the monomials up to `degree` (coordinates scaled to the
    points' extent; weights (N,): relative, e.g. 1 / variance), refitted once
    without the points whose residual is over `clip` robust sigmas. Fewer
    points than twice the monomials: the (weighted) mean.

    >>> xy = np.random.default_rng(0).uniform(0, 100, (50, 2))
    >>> v = np.stack((0.01 * xy[:, 0], -0.02 * xy[:, 1] + 0.5), -1)
    >>> bool(np.allclose(smooth_field(xy, v), v))
    True
    """
    xy, v = np.asarray(xy, float), np.asarray(values, float)
    if not len(v):
        return v.copy()
    c, s = xy.mean(axis=0), np.maximum(np.ptp(xy, axis=0) / 2, 1e-9)

    def monomials(p):
        x, y = ((np.asarray(p, float) - c) / s).T
        return np.stack([x ** i * y ** j for i in range(degree + 1) for j in range(degree + 1 - i)], -1)

    A = monomials(xy)
    B = A if at is None else monomials(at)
    wt = np.ones(len(v)) if weights is None else np.asarray(weights, float)
    if len(v) < 2 * A.shape[1]:
        return np.broadcast_to((wt[:, None] * v).sum(axis=0) / wt.sum(), (len(B), 2)).copy()
    keep = np.ones(len(v), bool)
    sw = np.sqrt(wt)[:, None]
    for _ in range(2):
        coef = np.linalg.lstsq((sw * A)[keep], (sw * v)[keep], rcond=None)[0]
        r = np.linalg.norm(v - A @ coef, axis=1) * sw[:, 0]
        sigma = 1.4826 * np.median(r[keep]) + 1e-12
        keep = r <= clip * sigma
    return B @ coef


def psf_correct(frames, corners, window, shifts=None, min_window: float = PSF_MIN_WINDOW, rounds: int = 1,
                pool: bool = True, degree: int = 1, weighted: bool = True) -> np.ndarray:
    """(N, 2) corners moved from the symmetric fit's point toward the light's centroid where the window allows

    The centroid is where the 16 edges, each placed at its line-spread
    function's mean, meet (local_psf). Corners whose half-window is below
    min_window (the edges too short to hold the PSF's spread) keep the corner
    given; NaN corners stay NaN. A corner's own step counts when all but two
    of its edges were measured and it is at most MAX_CENTROID_STEP long.
    pool False: those corners move by their own step. pool True (default):
    the counted steps of the call (one pose) are fitted by a smooth field
    over the image (smooth_field of `degree`, weighted by the steps' inverse
    variance when `weighted`), which moves every corner of min_window or more:
    the symmetric fit's offset from the centroid varies slowly with the PSF,
    while each corner's own step carries the noise of its edges' first
    moments. Measured on 4 near D435 views (windows 3-8 px,
    benchmark.psfcheck; RMS against the centroid truth, all corners): coma
    2.5 waves: symmetric 0.0609 px, own steps 0.0539, pooled (degree 1,
    weighted) 0.0502; coma 1.5: 0.0345, -, 0.0277; Gaussian PSF of 1 px:
    0.0049, 0.0072, 0.0051. Pooled but moving only the counted corners:
    0.0532, 0.0303, 0.0050; degree 2: 0.0532 and 0.0052 (counted only).

    >>> yy, xx = np.mgrid[0:40, 0:40] - np.array([20.3, 19.6])[:, None, None]
    >>> frames = np.stack([np.tanh((np.cos(t) * xx + np.sin(t) * yy))
    ...                    * np.tanh((-np.sin(t) * xx + np.cos(t) * yy)) for t in np.arange(8) * np.pi / 16])
    >>> np.round(psf_correct(frames, np.array([[19.5, 20.4], [19.5, 20.4]]), np.array([8.0, 3.0])), 1)
    array([[19.6, 20.3],
           [19.5, 20.4]])
    """
    q = np.asarray(corners, float).reshape(-1, 2)
    w = np.broadcast_to(np.asarray(window, float), (len(q),))
    use = np.isfinite(q).all(axis=1) & (w >= min_window)
    out = q.copy()
    if not use.any():
        return out
    sh = None if shifts is None else np.asarray(shifts, float)[:, use]
    _, est = local_psf(frames, q[use], w[use], sh, rounds=rounds)
    step = est.centroid
    nframes = 1 if np.ndim(frames) == 2 else len(frames)
    good = (est.edges >= 2 * nframes - 2) & (np.linalg.norm(step, axis=1) <= MAX_CENTROID_STEP)
    at = np.flatnonzero(use)[good]
    if not pool:
        out[at] += step[good]
        return out
    if not good.any():
        return out
    wt = 1 / np.maximum(np.trace(est.centroid_cov[good], axis1=1, axis2=2), 1e-8) if weighted else None
    out[use] += smooth_field(q[at], step[good], degree, weights=wt, at=q[use])
    return out


BLUR_FIELDS = ("width", "width_sd", "elongation", "elongation_deg", "coma", "coma_sd", "coma_deg", "reach")
"""The blur map's columns per corner: px, px, 1, degrees of the long axis, px^3, px^3, degrees of the tail,
and the reach (px) the PSF was clipped to"""


def blur_columns(frames, corners, window, min_window: float = PSF_MIN_WINDOW) -> np.ndarray:
    """(N, len(BLUR_FIELDS)) the local PSF of every corner (local_psf), NaN rows where the window is too small

    >>> yy, xx = np.mgrid[0:40, 0:40] - np.array([20.3, 19.6])[:, None, None]
    >>> frames = np.stack([np.tanh((np.cos(t) * xx + np.sin(t) * yy))
    ...                    * np.tanh((-np.sin(t) * xx + np.cos(t) * yy)) for t in np.arange(8) * np.pi / 16])
    >>> b = blur_columns(frames, np.array([[19.6, 20.3], [19.6, 20.3]]), np.array([8.0, 3.0]))
    >>> b.shape, bool(0.5 < b[0, 0] < 1.0), bool(np.isnan(b[1]).all()), float(b[0, 7])
    ((2, 8), True, True, 3.5)
    """
    q = np.asarray(corners, float).reshape(-1, 2)
    w = np.broadcast_to(np.asarray(window, float), (len(q),))
    out = np.full((len(q), len(BLUR_FIELDS)), np.nan)
    use = np.isfinite(q).all(axis=1) & (w >= min_window)
    if use.any():
        es, e = local_psf(frames, q[use], w[use])
        out[use] = np.column_stack((e.width, e.width_sd, e.elongation, np.degrees(e.elongation_angle),
                                    e.coma, e.coma_sd, np.degrees(e.coma_angle), es.reach))
    return out

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
L = reach. A PSF
wider than the reach is truncated there: the moments are those of the PSF
within +-reach of the corner, and the centroid that of that light.
"""

from __future__ import annotations

import dataclasses

import numpy as np

BIN_PX = 0.25  # ESF bin along the edge normal, px
MAX_REACH = 5.0  # px: the farthest the ESF is read from the edge
REACH_PER_WINDOW = 0.5  # ... and at most this fraction of the corner's half-window
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
    """(values (N, K, M), offsets d (N, K, M, 2) from the corner, inside (N, K, M)) of a (2 half + 1)^2 square"""
    K, H, W = frames.shape
    c = corners[:, None, :] + (0 if shifts is None else np.transpose(shifts, (1, 0, 2)))  # (N, K, 2)
    ic = np.round(c).astype(int)
    o = np.arange(-half, half + 1)
    oy, ox = np.meshgrid(o, o, indexing="ij")
    px = ic[..., 0, None] + ox.ravel()
    py = ic[..., 1, None] + oy.ravel()
    inside = (px >= 0) & (px < W) & (py >= 0) & (py < H)
    k = np.arange(K)[None, :, None]
    v = frames[k, np.clip(py, 0, H - 1), np.clip(px, 0, W - 1)]
    d = np.stack((px - c[..., 0, None], py - c[..., 1, None]), axis=-1)
    return v, d, inside, (k, np.clip(py, 0, H - 1), np.clip(px, 0, W - 1))


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
    w = (gx * gx + gy * gy) * mask
    a = np.arctan2(gy, gx)
    phi0 = np.angle((w * np.exp(4j * a)).sum(-1)) / 4
    out = []
    for p in (phi0, phi0 + np.pi / 2):
        z = np.exp(2j * (a - p[..., None]))
        mine = z.real > 0
        out.append(p + np.angle((w * mine * z).sum(-1)) / 2)
    return np.stack(out, axis=-1)


def edge_angle(gx, gy, mask, phi):
    """The normal angle (...) of one edge: the doubled-angle mean of the gradients (..., M) in mask, about phi"""
    w = (gx * gx + gy * gy) * mask
    z = (w * np.exp(2j * (np.arctan2(gy, gx) - phi[..., None]))).sum(-1)
    return np.where(np.abs(z) > 0, phi + np.angle(z) / 2, phi)


def _binned_esf(u, F, sel, L):
    """(mean u, mean F) per bin (rows, nbins) of samples u, F (rows, M) where sel; NaN where a bin is empty"""
    nb = int(round(2 * L / BIN_PX))
    rows = u.shape[0]
    b = np.clip(np.floor((u + L) / BIN_PX).astype(int), 0, nb - 1)
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


def _reference_moments(L: float) -> np.ndarray:
    """E[X^j], j = 1, 2, 3, of the distribution with CDF R on [-L, L] (mass beyond put at the ends)"""
    u = np.linspace(-L, L, 20001)
    one_minus = 1.0 - _reference(u)
    return np.array([(-L) ** j + np.trapezoid(j * u ** (j - 1) * one_minus, u) for j in (1, 2, 3)])


MIN_BINS = 6  # an edge's ESF needs samples in this many bins


def _moments(u, F, L):
    """(mean, central var, central third) of the distributions with CDFs F sampled at u (rows, n) on [-L, L]

    E[X^j] = E_R[X^j] + integral of j u^(j-1) (R - F) du by the trapezoid rule
    over the samples (NaN: none), the integrand taken as 0 at +-L: it is
    smooth and vanishes at both ends, so the rule is accurate even where the
    samples are a pixel apart (an edge along the pixel grid).
    """
    out = np.full((3, u.shape[0]), np.nan)
    ref = _reference_moments(L)
    for r in range(u.shape[0]):
        ok = np.isfinite(u[r]) & np.isfinite(F[r])
        if ok.sum() < MIN_BINS:
            continue
        o = np.argsort(u[r, ok])
        x = np.concatenate(([-L], u[r, ok][o], [L]))
        d = np.concatenate(([0.0], _reference(x[1:-1]) - F[r, ok][o], [0.0]))
        e1, e2, e3 = ref + [np.trapezoid(j * x ** (j - 1) * d, x) for j in (1, 2, 3)]
        out[:, r] = e1, e2 - e1 ** 2, e3 - 3 * e1 * e2 + 2 * e1 ** 3
    return out


def edge_spread(frames, corners, window, shifts=None, reach=None) -> EdgeSpread:
    """Every edge's spread moments about corners (N, 2) on frames (K, H, W); see the module doc

    window: (N,) or one half-window (px, the square the pixels come from);
    shifts: (K, N, 2) per-frame offsets of the corner (display offsets);
    reach: L (px), default min(MAX_REACH, REACH_PER_WINDOW x window).
    """
    frames = np.asarray(frames, np.float32)
    frames = frames[None] if frames.ndim == 2 else frames
    q = np.asarray(corners, float).reshape(-1, 2)
    N, K = len(q), len(frames)
    w = np.broadcast_to(np.asarray(window, float), (N,))
    L = np.broadcast_to(np.asarray(reach if reach is not None else
                                   np.clip(REACH_PER_WINDOW * w, MIN_REACH, MAX_REACH), float), (N,))
    nan = np.full((N, 2 * K), np.nan)
    out = EdgeSpread(nan.copy(), nan.copy(), nan.copy(), nan.copy(), np.array(L, float))
    good = np.isfinite(q).all(axis=1) & np.isfinite(w)
    if not good.any():
        return out
    half = int(np.ceil(np.nanmax(w[good])))
    v, d, inside, at = _patches(frames, np.where(good[:, None], q, 0.0), half, shifts)
    gy = np.gradient(frames, axis=1)[at]
    gx = np.gradient(frames, axis=2)[at]
    sq = inside & (np.abs(d) <= w[:, None, None, None]).all(-1)
    normals = edge_normals(gx, gy, sq)  # (N, K, 2)
    Lc = L[:, None, None]
    for _ in range(2):  # again from each edge's own strip, away from the corner
        n = np.stack((np.cos(normals), np.sin(normals)), -1)  # (N, K, 2 edges, 2)
        uv = np.einsum("nkmc,nkec->nkem", d, n)  # (N, K, 2, M) distance along each edge's normal
        strip = sq[:, :, None] & (np.abs(uv) < Lc[..., None]) & (np.abs(uv[:, :, ::-1]) >= Lc[..., None])
        normals = np.stack([edge_angle(gx, gy, strip[:, :, e], normals[..., e]) for e in range(2)], -1)
    n = np.stack((np.cos(normals), np.sin(normals)), -1)
    uv = np.einsum("nkmc,nkec->nkem", d, n)
    far = sq & (np.abs(uv) >= Lc[..., None]).all(2)
    prod = np.sign(uv[:, :, 0] * uv[:, :, 1])
    cnt_p, cnt_m = (far & (prod > 0)).sum(-1), (far & (prod < 0)).sum(-1)
    hi = np.where(far & (prod > 0), v, 0).sum(-1) / np.maximum(cnt_p, 1)
    lo = np.where(far & (prod < 0), v, 0).sum(-1) / np.maximum(cnt_m, 1)
    contrast = np.where((cnt_p >= 3) & (cnt_m >= 3), hi - lo, np.nan)  # (N, K) signed
    mid = (hi + lo) / 2
    for e in range(2):
        u, other = uv[:, :, e], uv[:, :, 1 - e]
        with np.errstate(invalid="ignore", divide="ignore"):
            F = 0.5 + np.sign(other) * (v - mid[..., None]) / contrast[..., None]
        sel = sq & (np.abs(u) < Lc) & (np.abs(other) >= Lc) & np.isfinite(F)
        for i in np.flatnonzero(good):  # each corner its own reach; rows = frames
            (ua, Fa), (ub, Fb) = [_binned_esf(u[i], F[i], sel[i] & (np.sign(other[i]) == side), L[i])
                                  for side in (1, -1)]
            both = np.isfinite(Fa) & np.isfinite(Fb)  # a bin with both halves: their mean (level errors cancel)
            um = np.where(both, (ua + ub) / 2, np.where(np.isfinite(Fa), ua, ub))
            Fm = np.where(both, (Fa + Fb) / 2, np.where(np.isfinite(Fa), Fa, Fb))
            m1, m2, m3 = _moments(um, Fm, L[i])
            out.normal[i, e::2] = normals[i, :, e]
            out.mean[i, e::2] = m1
            out.var[i, e::2] = m2 - PIXEL_VAR
            out.third[i, e::2] = m3
    return out


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
    >>> es, est = local_psf(frames, np.array([[19.2, 20.7]]), 8.0)
    >>> np.round(est.centroid, 1), bool(est.coma[0] < 0.02)
    (array([[ 0.4, -0.4]]), True)
    """
    q0 = np.asarray(corners, float).reshape(-1, 2)
    q = q0.copy()
    for _ in range(max(int(rounds), 1)):
        es = edge_spread(frames, q, window, shifts, reach)
        est = psf_estimate(es)
        step = np.where(np.isfinite(est.centroid), est.centroid, 0.0)
        q = q + np.clip(step, -1.0, 1.0)
    est.centroid = np.where(np.isfinite(est.centroid), q - q0 - np.clip(step, -1, 1) + est.centroid, np.nan)
    return es, est

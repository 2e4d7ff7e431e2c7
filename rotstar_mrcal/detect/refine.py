"""Symmetric refinement: the point about which every frame is point-symmetric (paper 3.3, Eq. 1)

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.detect.refine import symmetric_refine
    >>> yy, xx = np.mgrid[0:60, 0:60] - np.array([30.3, 29.6])[:, None, None]
    >>> frames = np.stack([np.tanh((np.cos(t) * xx + np.sin(t) * yy) * (-np.sin(t) * xx + np.cos(t) * yy) / 4)
    ...                    for t in np.arange(8) * np.pi / 16]).astype(np.float32)
    >>> res = symmetric_refine(frames, np.array([[31.0, 29.0]]), window=10)
    >>> float(np.abs(res.corners - [29.6, 30.3]).max()) < 0.02, res.ok.tolist()
    (True, [True])

For a corner q the cost is

    sum over frames k and offsets d of [I_k(q + d) - I_k(q - d)]^2

with the offsets d drawn uniformly in the square [-w, w]^2 (4 (2w+1)^2 of
them, the same set for every corner, from a fixed seed). I_k is the bilinear
interpolant of frame k and the Jacobian of each residual is the difference of
the interpolant's gradients at q + d and q - d. Levenberg-Marquardt runs on
all corners of a pose at once (per-corner damping, started at 1e-3 of the
trace of J'J; divided by 3 after a step that lowers the cost, multiplied by 4
after one that does not), until the accepted step is shorter than `tol`
pixels. A corner is rejected if it moves more than w from its start, if a
sample leaves the image, or if it does not converge.

A checker corner stays point-symmetric under perspective (its edges are lines
through the corner, and lines map to lines), so translation alone is enough
as long as the window stays inside the element; `window` may be given per
corner for that reason.
"""

from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass
class Refined:
    corners: np.ndarray  # (N, 2)
    ok: np.ndarray  # (N,) bool
    reason: np.ndarray  # (N,) str: '' or why the corner was rejected
    sigma: np.ndarray  # (N,) rms residual (image units)
    cov: np.ndarray  # (N, 2, 2) Gauss-Newton covariance of the corner, px^2
    iterations: int


def unit_offsets(window: int, seed: int = 0, density: int = 4) -> np.ndarray:
    """(S, 2) offsets uniform in [-1, 1]^2, S = density * (2 window + 1)^2"""
    n = density * (2 * int(np.ceil(window)) + 1) ** 2
    return np.random.default_rng(seed).uniform(-1.0, 1.0, (n, 2))


class _Sampler:
    """Bilinear interpolation of all frames at once, and its gradient"""

    def __init__(self, frames: np.ndarray):
        nf, self.H, self.W = frames.shape
        self.F = np.ascontiguousarray(np.moveaxis(np.asarray(frames, np.float32), 0, -1).reshape(-1, nf))

    def inside(self, p: np.ndarray) -> np.ndarray:
        """(N,) True where every point of a corner's (N, S, 2) set is interpolable"""
        x, y = p[..., 0], p[..., 1]
        return ((x >= 0) & (x <= self.W - 1.001) & (y >= 0) & (y <= self.H - 1.001)).all(axis=-1)

    def __call__(self, p: np.ndarray):
        """Values (N, S, nf) and gradients d/dx, d/dy (N, S, nf) at points p (N, S, 2)"""
        x = np.clip(p[..., 0], 0, self.W - 1.001)
        y = np.clip(p[..., 1], 0, self.H - 1.001)
        x0 = np.floor(x)
        y0 = np.floor(y)
        fx = (x - x0).astype(np.float32)[..., None]
        fy = (y - y0).astype(np.float32)[..., None]
        i = (y0.astype(np.int64) * self.W + x0.astype(np.int64))
        a = self.F[i]
        b = self.F[i + 1]
        c = self.F[i + self.W]
        d = self.F[i + self.W + 1]
        top = a + fx * (b - a)
        bot = c + fx * (d - c)
        val = top + fy * (bot - top)
        gx = (b - a) + fy * ((d - c) - (b - a))
        gy = bot - top
        return val, gx, gy

    def shifted(self, p: np.ndarray, shifts: np.ndarray):
        """As __call__, but frame k is sampled at p + shifts[:, k] (shifts (N, nf, 2))"""
        out = [np.empty(p.shape[:-1] + (shifts.shape[1],), np.float32) for _ in range(3)]
        for k in range(shifts.shape[1]):
            pk = p + shifts[:, None, k, :]
            F = self.F
            self.F = F[:, k : k + 1]
            try:
                for o, v in zip(out, self(pk)):
                    o[..., k] = v[..., 0]
            finally:
                self.F = F
        return tuple(out)


def _residuals(sampler, q, d, sh=None):
    if sh is None:
        vp, gxp, gyp = sampler(q[:, None, :] + d)
        vm, gxm, gym = sampler(q[:, None, :] - d)
    else:
        vp, gxp, gyp = sampler.shifted(q[:, None, :] + d, sh)
        vm, gxm, gym = sampler.shifted(q[:, None, :] - d, sh)
    r = (vp - vm).reshape(len(q), -1)
    jx = (gxp - gxm).reshape(len(q), -1)
    jy = (gyp - gym).reshape(len(q), -1)
    return r, jx, jy


def _normal(r, jx, jy):
    JtJ = np.empty((len(r), 2, 2))
    JtJ[:, 0, 0] = np.einsum("ns,ns->n", jx, jx)
    JtJ[:, 1, 1] = np.einsum("ns,ns->n", jy, jy)
    JtJ[:, 0, 1] = JtJ[:, 1, 0] = np.einsum("ns,ns->n", jx, jy)
    Jtr = np.stack((np.einsum("ns,ns->n", jx, r), np.einsum("ns,ns->n", jy, r)), axis=-1)
    cost = np.einsum("ns,ns->n", r, r).astype(float)
    return JtJ, Jtr, cost


def symmetric_refine(
    frames: np.ndarray,
    corners0: np.ndarray,
    window: float | np.ndarray = 10,
    density: int = 4,
    max_iter: int = 50,
    tol: float = 1e-3,
    seed: int = 0,
    shifts: np.ndarray | None = None,
) -> Refined:
    """Refine corners (N, 2) on frames (nframes, H, W) by Eq. 1; see the module doc

    Corners are processed in groups of equal ceil(window), each corner with
    density * (2 ceil(w) + 1)^2 samples. shifts: optional (nframes, N, 2)
    image offsets of each frame's copy of each corner (a display that shows
    frames displaced): frame k is then sampled symmetrically about
    q + shifts[k], and q is returned.
    """
    frames = np.asarray(frames, np.float32)
    if frames.ndim == 2:
        frames = frames[None]
    q0 = np.asarray(corners0, float).reshape(-1, 2)
    N = len(q0)
    w = np.broadcast_to(np.asarray(window, float), (N,)).copy()
    sampler = _Sampler(frames)
    sh = None if shifts is None else np.moveaxis(np.asarray(shifts, float).reshape(frames.shape[0], N, 2), 0, 1)
    out = Refined(np.full((N, 2), np.nan), np.zeros(N, bool), np.full(N, "", dtype=object),
                  np.full(N, np.nan), np.full((N, 2, 2), np.nan), 0)
    wc = np.ceil(np.maximum(w, 1)).astype(int)
    for g in np.unique(wc):
        sel = np.flatnonzero(wc == g)
        r = _refine_group(sampler, frames.shape[0], q0[sel], w[sel], unit_offsets(g, seed, density), max_iter, tol,
                          None if sh is None else sh[sel])
        out.corners[sel], out.ok[sel], out.reason[sel] = r.corners, r.ok, r.reason
        out.sigma[sel], out.cov[sel] = r.sigma, r.cov
        out.iterations = max(out.iterations, r.iterations)
    return out


def _inside(sampler, q, D, sh):
    """(N,) True where every sample q + s_k +- d of every frame k lies inside the image"""
    if sh is None:
        return sampler.inside(q[:, None, :] + D) & sampler.inside(q[:, None, :] - D)
    N = len(q)
    c = q[:, None, None, :] + sh[:, None, :, :]  # (N, 1, nf, 2)
    return (sampler.inside((c + D[:, :, None, :]).reshape(N, -1, 2))
            & sampler.inside((c - D[:, :, None, :]).reshape(N, -1, 2)))


def _refine_group(sampler, nframes, q0, w, u, max_iter, tol, sh=None) -> Refined:
    N = len(q0)
    D = (w[:, None, None] * u[None]).astype(np.float64)  # (N, S, 2)

    q = q0.copy()
    reason = np.full(N, "", dtype=object)
    ok = np.ones(N, bool)
    bad = ~_inside(sampler, q, D, sh) | ~np.isfinite(q).all(axis=1)
    reason[bad] = "window leaves the image"
    ok &= ~bad
    active = ok.copy()
    JtJ = np.zeros((N, 2, 2))
    Jtr = np.zeros((N, 2))
    cost = np.full(N, np.inf)
    idx = np.flatnonzero(active)
    if len(idx):
        JtJ[idx], Jtr[idx], cost[idx] = _normal(*_residuals(sampler, q[idx], D[idx], None if sh is None else sh[idx]))
    lam = 1e-3 * np.trace(JtJ, axis1=1, axis2=2) + 1e-12
    converged = np.zeros(N, bool)
    it = 0
    for it in range(1, max_iter + 1):
        idx = np.flatnonzero(active)
        if not len(idx):
            break
        A = JtJ[idx] + lam[idx, None, None] * np.eye(2)
        step = -np.linalg.solve(A, Jtr[idx][..., None])[..., 0]
        qn = q[idx] + step
        shi = None if sh is None else sh[idx]
        inside = _inside(sampler, qn, D[idx], shi)
        r, jx, jy = _residuals(sampler, qn, D[idx], shi)
        JtJn, Jtrn, costn = _normal(r, jx, jy)
        acc = (costn <= cost[idx]) & inside
        a = idx[acc]
        q[a], JtJ[a], Jtr[a], cost[a] = qn[acc], JtJn[acc], Jtrn[acc], costn[acc]
        lam[a] /= 3
        lam[idx[~acc]] *= 4
        small = np.linalg.norm(step, axis=1) < tol
        done = (acc & small) | (~acc & (lam[idx] > 1e8 * np.trace(JtJ[idx], axis1=1, axis2=2) + 1e-6))
        converged[idx[done]] = True
        left = ~inside & ~acc
        reason[idx[left]] = "window leaves the image"
        ok[idx[left]] = False
        active[idx[done | left]] = False
    moved = np.linalg.norm(q - q0, axis=1) > w
    reason[ok & moved] = "moved more than the window from its rough position"
    ok &= ~moved
    nc = ok & ~converged
    reason[nc] = "did not converge"
    ok &= ~nc

    M = D.shape[1] * nframes
    sigma2 = cost / max(M - 2, 1)
    cov = np.full((N, 2, 2), np.nan)
    good = ok & np.isfinite(cost)
    if good.any():
        cov[good] = np.linalg.inv(JtJ[good] + 1e-12 * np.eye(2)) * sigma2[good, None, None]
    q[~ok] = np.nan
    return Refined(q, ok, reason, np.sqrt(sigma2), cov, it)

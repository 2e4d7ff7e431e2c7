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

Two batch forms share that machinery: `shifts` samples frame k about q + s_k
(a display that shows each frame displaced), and `refine_each_frame` refines
every frame alone (the pipeline's motion check) as one batch of nframes x N
problems, with the same numbers as one call per frame.

The sampler gathers the four neighbours of every sample with np.take from a
(pixels, frames) copy of the frames (all frames at once) or from the frames
themselves (one frame per sample); whether a corner's samples stay inside the
image is decided from the extremes of its offsets.

A checker corner stays point-symmetric under perspective (its edges are lines
through the corner, and lines map to lines), so translation alone is enough
as long as the window stays inside the element; `window` may be given per
corner for that reason.
"""

from __future__ import annotations

import dataclasses
from typing import Callable

import cv2
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
    """Bilinear interpolation of the frames, and its gradient

    Two layouts of the same pixels: (H*W, nframes) rows, one gather per
    neighbour for all frames at once (built on first use), and the frames as
    given, for samples that each read one frame.
    """

    def __init__(self, frames: np.ndarray):
        self.nf, self.H, self.W = frames.shape
        self.frames = np.ascontiguousarray(frames, np.float32)
        self._rows = None

    @property
    def rows(self) -> np.ndarray:
        if self._rows is None:
            self._rows = np.ascontiguousarray(np.moveaxis(self.frames, 0, -1).reshape(-1, self.nf))
        return self._rows

    def inside(self, p: np.ndarray) -> np.ndarray:
        """(N,) True where every point of a corner's (N, S, 2) set is interpolable"""
        x, y = p[..., 0], p[..., 1]
        return ((x >= 0) & (x <= self.W - 1.001) & (y >= 0) & (y <= self.H - 1.001)).all(axis=-1)

    def inside_box(self, q: np.ndarray, dmin: np.ndarray, dmax: np.ndarray) -> np.ndarray:
        """inside(q + D) & inside(q - D) from the per-corner extremes of D (N, 2)

        The same answer without forming the points: rounding is monotonic, so
        the smallest of q + d is q + min(d) and the largest q + max(d).
        """
        lim = (self.W - 1.001, self.H - 1.001)
        return ((q + dmin >= 0) & (q + dmax <= lim) & (q - dmax >= 0) & (q - dmin <= lim)).all(axis=-1)

    def __call__(self, p: np.ndarray, frame: np.ndarray | None = None):
        """Values, d/dx and d/dy at points p (..., 2)

        frame None: every frame, arrays (..., nframes). Otherwise an integer
        array broadcastable to p[..., 0]: each point reads its own frame,
        arrays of p[..., 0]'s shape.
        """
        x = np.clip(p[..., 0], 0, self.W - 1.001)
        y = np.clip(p[..., 1], 0, self.H - 1.001)
        x0 = np.floor(x)
        y0 = np.floor(y)
        fx = (x - x0).astype(np.float32)
        fy = (y - y0).astype(np.float32)
        i = y0.astype(np.intp)
        i *= self.W
        i += x0.astype(np.intp)
        if frame is None:
            F = self.rows
            fx, fy = fx[..., None], fy[..., None]
        else:
            F = self.frames.reshape(-1)
            i = i + np.asarray(frame, np.intp) * (self.H * self.W)
        a = np.take(F, i, axis=0)
        b = np.take(F, i + 1, axis=0)
        i += self.W
        c = np.take(F, i, axis=0)
        d = np.take(F, i + 1, axis=0)
        b -= a  # b - a
        d -= c  # d - c
        top = fx * b
        top += a
        bot = fx * d
        bot += c
        bot -= top  # d/dy
        val = fy * bot
        val += top
        d -= b
        d *= fy
        d += b  # d/dx
        return val, d, bot


def _residuals(sampler, q, d, frame=None, shifts=None):
    """Residuals (N, S * nf) and their derivatives by the corner's x and y

    shifts (N, nf, 2): frame k of corner i is sampled about q_i + shifts[i, k].
    """
    if shifts is None:
        vp, gxp, gyp = sampler(q[:, None, :] + d, frame)
        vm, gxm, gym = sampler(q[:, None, :] - d, frame)
    else:
        s = shifts[:, None]  # (N, 1, nf, 2); points (q +- d) + s_k
        k = np.arange(shifts.shape[1])
        vp, gxp, gyp = sampler((q[:, None, :] + d)[:, :, None, :] + s, k)
        vm, gxm, gym = sampler((q[:, None, :] - d)[:, :, None, :] + s, k)
    vp -= vm
    gxp -= gxm
    gyp -= gym
    return vp.reshape(len(q), -1), gxp.reshape(len(q), -1), gyp.reshape(len(q), -1)


def _normal(r, jx, jy):
    JtJ = np.empty((len(r), 2, 2))
    JtJ[:, 0, 0] = np.einsum("ns,ns->n", jx, jx)
    JtJ[:, 1, 1] = np.einsum("ns,ns->n", jy, jy)
    JtJ[:, 0, 1] = JtJ[:, 1, 0] = np.einsum("ns,ns->n", jx, jy)
    Jtr = np.stack((np.einsum("ns,ns->n", jx, r), np.einsum("ns,ns->n", jy, r)), axis=-1)
    cost = np.einsum("ns,ns->n", r, r).astype(float)
    return JtJ, Jtr, cost


PREFILTER_SIGMA = 1.0  # px: the Gaussian low-pass before the symmetric refinement (pipeline's module doc) ...
PREFILTER_PER_WINDOW = 0.25  # ... at most this fraction of the pose's median half-window (small elements)


def lowpass_for(windows, sigma: float = PREFILTER_SIGMA) -> float:
    """The low-pass (px) detect_pose uses for a pose whose corners have these half-windows

    >>> lowpass_for([3.0, 4.0, 5.0]), lowpass_for([8.0, 10.0])
    (1.0, 1.0)
    >>> lowpass_for([2.0, 3.0, 3.0])
    0.75
    """
    return min(sigma, PREFILTER_PER_WINDOW * float(np.median(windows)))


def prefilter(frames: np.ndarray, sigma: float = PREFILTER_SIGMA) -> np.ndarray:
    """The frames low-passed by a Gaussian of sigma px (edge pixels replicated); sigma 0: unchanged

    SYNOPSIS

        >>> f = np.zeros((1, 9, 9), np.float32); f[0, 4, 4] = 1
        >>> g = prefilter(f, 1.0)
        >>> round(float(g.sum()), 3), bool(g[0, 4, 4] == g.max()), g.dtype
        (1.0, True, dtype('float32'))
    """
    frames = np.asarray(frames, np.float32)
    if sigma <= 0:
        return frames
    return np.stack([cv2.GaussianBlur(f, (0, 0), sigma, borderType=cv2.BORDER_REPLICATE) for f in frames])


def _frame_stack(frames) -> np.ndarray:
    """(nframes, H, W) float32 of one frame (H, W) or a stack"""
    frames = np.asarray(frames, np.float32)
    return frames[None] if frames.ndim == 2 else frames


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
    density * (2 ceil(w) + 1)^2 samples.

    shifts: optional (nframes, N, 2) image offsets; frame k's samples for
    corner i are then taken about q_i + shifts[k, i], i.e. the cost is
    sum_k sum_d [I_k(q + s_k + d) - I_k(q + s_k - d)]^2, and the corner
    returned is q (for frames that show the pattern displaced).
    """
    frames = _frame_stack(frames)
    q0 = np.asarray(corners0, float).reshape(-1, 2)
    N = len(q0)
    if shifts is not None:
        shifts = np.asarray(shifts, float)
        if shifts.shape != (len(frames), N, 2):
            raise ValueError(f"shifts must be (nframes, N, 2) = {(len(frames), N, 2)}, not {shifts.shape}")
        shifts = np.ascontiguousarray(shifts.transpose(1, 0, 2))  # (N, nframes, 2)
    return _refine(_Sampler(frames), frames.shape[0], q0, window, density, max_iter, tol, seed, shifts=shifts)


def refine_each_frame(
    frames: np.ndarray,
    corners0: np.ndarray,
    window: float | np.ndarray = 10,
    density: int = 4,
    max_iter: int = 50,
    tol: float = 1e-3,
    seed: int = 0,
) -> Refined:
    """symmetric_refine on every frame alone: a Refined whose arrays have a leading frame axis

    The same numbers as [symmetric_refine(f[None], corners0, window, ...) for f
    in frames], computed as one batch of nframes x N problems (each sample
    reads only its own problem's frame).
    """
    frames = _frame_stack(frames)
    nf = len(frames)
    q0 = np.asarray(corners0, float).reshape(-1, 2)
    N = len(q0)
    w = np.broadcast_to(np.asarray(window, float), (N,))
    r = _refine(_Sampler(frames), 1, np.tile(q0, (nf, 1)), np.tile(w, nf), density, max_iter, tol, seed,
                frame=np.repeat(np.arange(nf), N))
    return Refined(r.corners.reshape(nf, N, 2), r.ok.reshape(nf, N), r.reason.reshape(nf, N),
                   r.sigma.reshape(nf, N), r.cov.reshape(nf, N, 2, 2), r.iterations)


def _refine(sampler, nframes, q0, window, density, max_iter, tol, seed, frame=None, shifts=None) -> Refined:
    """Every corner, in groups of equal ceil(window); frame: (N,) one frame per corner, or None"""
    N = len(q0)
    w = np.broadcast_to(np.asarray(window, float), (N,)).copy()
    out = Refined(np.full((N, 2), np.nan), np.zeros(N, bool), np.full(N, "", dtype=object),
                  np.full(N, np.nan), np.full((N, 2, 2), np.nan), 0)
    wc = np.ceil(np.maximum(w, 1)).astype(int)
    for g in np.unique(wc):
        sel = np.flatnonzero(wc == g)
        r = _refine_group(sampler, nframes, q0[sel], w[sel], unit_offsets(g, seed, density), max_iter, tol,
                          None if frame is None else frame[sel, None],
                          None if shifts is None else shifts[sel])
        out.corners[sel], out.ok[sel], out.reason[sel] = r.corners, r.ok, r.reason
        out.sigma[sel], out.cov[sel] = r.sigma, r.cov
        out.iterations = max(out.iterations, r.iterations)
    return out


def _refine_group(sampler, nframes, q0, w, u, max_iter, tol, frame=None, shifts=None) -> Refined:
    """Levenberg-Marquardt on corners that share one set of unit offsets u

    frame: (N, 1) the frame each corner reads, or None (all frames);
    shifts: (N, nframes, 2) per-frame offsets of the sampling centre, or None.
    """
    N = len(q0)
    D = (w[:, None, None] * u[None]).astype(np.float64)  # (N, S, 2)
    if shifts is None:
        dmin, dmax = D.min(axis=1), D.max(axis=1)

        def inside(q, i):
            return sampler.inside_box(q, dmin[i], dmax[i])
    else:
        def inside(q, i):
            s = shifts[i][:, None]  # (n, 1, nframes, 2); the points _residuals samples
            p = (q[:, None, :] + D[i])[:, :, None, :] + s
            m = (q[:, None, :] - D[i])[:, :, None, :] + s
            return sampler.inside(p.reshape(len(q), -1, 2)) & sampler.inside(m.reshape(len(q), -1, 2))

    def residuals(q, i):
        return _residuals(sampler, q, D[i], None if frame is None else frame[i],
                          None if shifts is None else shifts[i])

    q = q0.copy()
    reason = np.full(N, "", dtype=object)
    ok = np.ones(N, bool)
    bad = ~inside(q, slice(None)) | ~np.isfinite(q).all(axis=1)
    reason[bad] = "window leaves the image"
    ok &= ~bad
    active = ok.copy()
    JtJ = np.zeros((N, 2, 2))
    Jtr = np.zeros((N, 2))
    cost = np.full(N, np.inf)
    idx = np.flatnonzero(active)
    if len(idx):
        JtJ[idx], Jtr[idx], cost[idx] = _normal(*residuals(q[idx], idx))
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
        ins = inside(qn, idx)
        JtJn, Jtrn, costn = _normal(*residuals(qn, idx))
        acc = (costn <= cost[idx]) & ins
        a = idx[acc]
        q[a], JtJ[a], Jtr[a], cost[a] = qn[acc], JtJn[acc], Jtrn[acc], costn[acc]
        lam[a] /= 3
        lam[idx[~acc]] *= 4
        small = np.linalg.norm(step, axis=1) < tol
        done = (acc & small) | (~acc & (lam[idx] > 1e8 * np.trace(JtJ[idx], axis1=1, axis2=2) + 1e-6))
        converged[idx[done]] = True
        left = ~ins & ~acc
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


# ---------------------------------------------------------------------------
# refiners by method, behind one interface: detect_pose takes one as a value
# ---------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Refiner:
    """A corner refiner: start corners (N, 2) on frames (K, H, W) -> (N, 2), NaN = failed

    needs 'rotstar': the rotating-star frames jointly (detect_pose runs the
    symmetric refinement with its display maps and motion check);
    'checkerboard': the checkerboard frame, one image at a time. The peers'
    refiners and the table of all of them are in peers.registry (REFINERS).
    """

    name: str
    needs: str  # 'rotstar' or 'checkerboard'
    description: str
    refine: Callable  # (frames (K, H, W), starts (N, 2), window) -> (N, 2), NaN = failed
    correct: Callable | None = None  # needs 'rotstar' only: (frames, symmetric corners (N, 2), windows (N,),
    # display offsets (K, N, 2) or None) -> (N, 2), applied by detect_pose after its symmetric refinement
    samples: Callable | None = None  # with correct: (the same arguments) -> what the correction measured on the
    # pose (psf-sim: the corners' coma, psfbias.coma_samples), handed back as correct(..., samples=); a dataset
    # pools them over its poses and corrects every pose again with the pool (pipeline.correct_with_dataset)

    @property
    def pools(self) -> bool:
        """True for a refiner whose correction pools a dataset's poses (it has samples): psf-sim"""
        return self.samples is not None


def refine_symmetric(frames, starts, window=10.0) -> np.ndarray:
    """The paper's Eq. 1 (symmetric_refine) on all frames jointly

    >>> y, x = np.mgrid[0:30, 0:30].astype(float)
    >>> frames = (128 + 100 * np.tanh(x - 14.3) * np.tanh(y - 15.6))[None]
    >>> np.round(refine_symmetric(frames, [[15.0, 15.0]], 6), 2)
    array([[14.3, 15.6]])
    """
    return symmetric_refine(np.asarray(frames, np.float32), np.asarray(starts, float).reshape(-1, 2),
                            window=window).corners


SYMMETRIC = Refiner("symmetric", "rotstar", "the paper's point-symmetry fit (Eq. 1) on all frames jointly",
                    refine_symmetric)
"""The paper's refiner, detect_pose's default"""


def symmetric_step(frames: np.ndarray, q: np.ndarray, window: float | np.ndarray = 10, density: int = 4,
                   seed: int = 0) -> np.ndarray:
    """(N, 2) the Gauss-Newton step of Eq. 1's cost at corners q (N, 2): -(J'J)^-1 J'r, one evaluation

    Where the optimum is within a small fraction of a pixel of q (a simulated
    star fitted from where its light is), q plus the step is where
    symmetric_refine converges, to second order in the distance. NaN where
    a sample would leave the frames.
    """
    frames = _frame_stack(frames)
    sampler = _Sampler(frames)
    q = np.asarray(q, float).reshape(-1, 2)
    w = np.broadcast_to(np.asarray(window, float), (len(q),))
    out = np.full((len(q), 2), np.nan)
    wc = np.ceil(np.maximum(w, 1)).astype(int)
    for g in np.unique(wc):
        sel = np.flatnonzero(wc == g)
        D = w[sel, None, None] * unit_offsets(g, seed, density)[None]
        ok = sampler.inside_box(q[sel], D.min(axis=1), D.max(axis=1))
        JtJ, Jtr, _ = _normal(*_residuals(sampler, q[sel], D))
        out[sel[ok]] = -np.linalg.solve(JtJ[ok] + 1e-12 * np.eye(2), Jtr[ok][..., None])[..., 0]
    return out

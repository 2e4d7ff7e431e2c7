"""Phase-shift corners: where the fringes along x and along y take the corner's phases

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.peers.phase import phase_corners
    >>> y, x = np.mgrid[0:40, 0:50].astype(float)
    >>> q = np.array([20.3, 17.6])                      # the corner, image (x, y)
    >>> ax = 2 * np.pi * ((x - q[0]) + 0.2 * (y - q[1])) / 12   # phase 0 at q, both fringes tilted
    >>> ay = 2 * np.pi * ((y - q[1]) - 0.1 * (x - q[0])) / 15
    >>> phase = np.stack([[0.5 + 0.4 * np.cos(a + n * np.pi / 2) for n in range(4)] for a in (ax, ay)])
    >>> r = phase_corners(phase, np.array([[[20.0, 18.0]]]), np.zeros((1, 1, 2)), full_scale=1.0)
    >>> np.round(r.corners, 6).tolist(), r.reason.tolist()
    ([[[20.3, 17.6]]], [['']])

The paper's phase-shift baseline (section 4.2, after Xu et al.'s local phase
planes): the screen shows fringes I_n = A + B cos(phi + n pi / 2), n = 0..3,
along x and along y. Per camera pixel and axis the wrapped phase is

    phi = atan2(I_3 - I_1, I_0 - I_2),  modulation B = |(I_0 - I_2, I_3 - I_1)| / 2.

Each corner starts at the rotating star's labelled corner (the paper does
the same: the start is within a fraction of a pixel, so the phase needs no
absolute unwrapping): in the (2h + 1)^2 pixels around the start, the phase
difference to the corner's phase is unwrapped about its value at the start
pixel, a plane a0 + a1 du + a2 dv is fitted to it by least squares (per axis),
and the corner is where both planes are 0. The window is then centred on
that point and the fit repeated once. h = 3 px is the paper's best.

A corner is NaN, with its reason, when a sample of its window is saturated
in any of the 8 frames (the clipped sinusoid biases the phase). Once the white
clips, the crests of the four steps together cover every phase, so every
pixel is clipped in some step and a saturating exposure rejects every corner
(leaving the clipped pixels out would leave none either); saturation="keep"
uses the clipped values as they are, which is what a pipeline without the
check does), when the
fringes' modulation in the window is below MIN_MODULATION of full scale, when
its window leaves the image, when the two planes are nearly parallel, or
when the solution leaves the window.
"""

from __future__ import annotations

import dataclasses

import numpy as np

HALF_WINDOW = 3  # px: the paper's best fixed neighbourhood for the phase planes
MIN_MODULATION = 0.02  # fringe modulation B, fraction of full scale
SATURATED = 0.998  # a sample at or above this fraction of full scale is clipped (10-bit data scaled into 16 too)


@dataclasses.dataclass
class PhaseCorners:
    corners: np.ndarray  # (..., 2) image points, NaN where rejected
    reason: np.ndarray  # (...) str: '' or why the corner was rejected
    modulation: np.ndarray  # (..., 2) median fringe modulation in the window along x and y, fraction of full scale


def wrapped_phase(shifts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(phase, modulation) of 4-step shifts (..., 4, H, W): atan2(I3 - I1, I0 - I2) and B

    SYNOPSIS

        >>> a = np.array([0.3, -2.0])
        >>> phi, b = wrapped_phase(np.stack([0.5 + 0.25 * np.cos(a + n * np.pi / 2) for n in range(4)])[:, None])
        >>> np.round(phi, 12).tolist(), np.round(b, 12).tolist()     # (4 steps, H=1, W=2) -> (1, 2)
        ([[0.3, -2.0]], [[0.25, 0.25]])
    """
    s = np.asarray(shifts, float)
    c, d = s[..., 0, :, :] - s[..., 2, :, :], s[..., 3, :, :] - s[..., 1, :, :]
    return np.arctan2(d, c), 0.5 * np.hypot(c, d)


def wrap(a):
    """Angles into [-pi, pi)"""
    return np.mod(np.asarray(a) + np.pi, 2 * np.pi) - np.pi


def _plane_zero(d: np.ndarray, du: np.ndarray, dv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares planes d ~ a0 + a1 du + a2 dv (d: (N, 2 axes, K)); (offset (N, 2) where both are 0, |det|)"""
    A = np.stack((np.ones_like(du), du, dv), axis=-1)  # (K, 3)
    coef = np.linalg.lstsq(A, d.reshape(-1, d.shape[-1]).T, rcond=None)[0].T.reshape(d.shape[:-1] + (3,))
    M = coef[..., 1:]  # (N, 2 axes, 2): gradients of the two phases
    det = np.linalg.det(M)
    ok = np.abs(det) > 1e-12
    off = np.full(d.shape[:-2] + (2,), np.nan)
    off[ok] = np.linalg.solve(M[ok], -coef[ok][..., :1])[..., 0]
    return off, np.abs(det)


def phase_corners(phase: np.ndarray, start: np.ndarray, target: np.ndarray, full_scale: float,
                  half_window: int = HALF_WINDOW, min_modulation: float = MIN_MODULATION,
                  saturated: float = SATURATED, saturation: str = "reject") -> PhaseCorners:
    """Sub-pixel corners from the phase-shift frames; see the module doc

    phase: (2, 4, H, W) the shifts along x then y, steps 0..3; start:
    (..., 2) image points (NaN: none); target: (..., 2) the corners' phases
    along x and y (radians, Layout.corner_phase()).
    """
    if saturation not in ("reject", "keep"):
        raise ValueError(f"saturation {saturation!r}; must be reject or keep")
    phase = np.asarray(phase, float)
    if phase.ndim != 4 or phase.shape[:2] != (2, 4):
        raise ValueError(f"phase frames must be (2 axes, 4 steps, H, W), not {phase.shape}")
    H, W = phase.shape[2:]
    start = np.asarray(start, float)
    shape = start.shape[:-1]
    q0 = start.reshape(-1, 2)
    t = np.asarray(target, float).reshape(-1, 2)
    phi, mod = wrapped_phase(phase)  # (2, H, W)
    clipped = np.any(phase >= saturated * full_scale, axis=(0, 1))  # (H, W)
    h = int(half_window)
    dv, du = (g.ravel().astype(float) for g in np.mgrid[-h : h + 1, -h : h + 1])
    N = len(q0)
    reason = np.full(N, "", dtype=object)
    out = np.full((N, 2), np.nan)
    modulation = np.full((N, 2), np.nan)
    q = q0.copy()
    live = np.isfinite(q).all(axis=-1)
    reason[~live] = "no start"
    for _ in range(2):  # fit about the start, then about the first solution
        c = np.where(live[:, None], np.round(np.nan_to_num(q)), 0).astype(int)
        inside = (c[:, 0] - h >= 0) & (c[:, 0] + h < W) & (c[:, 1] - h >= 0) & (c[:, 1] + h < H)
        reason[live & ~inside] = "window leaves the image"
        live &= inside
        idx = np.flatnonzero(live)
        if not len(idx):
            break
        u = c[idx, 0, None] + du.astype(int)  # (n, K)
        v = c[idx, 1, None] + dv.astype(int)
        p = phi[:, v, u].transpose(1, 0, 2)  # (n, 2, K)
        m = np.median(mod[:, v, u], axis=-1).T / full_scale  # (n, 2)
        modulation[idx] = m
        sat = clipped[v, u].any(axis=-1) if saturation == "reject" else np.zeros(len(idx), bool)
        low = (m < min_modulation).any(axis=-1)
        reason[idx[sat]] = "saturated: a sample of the window at full scale"
        reason[idx[low & ~sat]] = "fringe modulation too low"
        d = wrap(p - t[idx, :, None])
        centre = d[..., (len(du) - 1) // 2, None]  # the window's centre pixel
        d = centre + wrap(d - centre)  # unwrapped about the start
        off, _ = _plane_zero(d, du, dv)
        sol = c[idx] + off
        bad = ~np.isfinite(off).all(axis=-1)
        far = np.linalg.norm(np.nan_to_num(off, nan=np.inf), axis=-1) > h
        reason[idx[bad & ~sat & ~low]] = "the phase planes are parallel"
        reason[idx[far & ~bad & ~sat & ~low]] = "the phases' zero lies outside the window"
        ok = ~(sat | low | bad | far)
        live[idx[~ok]] = False
        q[idx[ok]] = sol[ok]
    out[live] = q[live]
    return PhaseCorners(out.reshape(shape + (2,)), reason.reshape(shape), modulation.reshape(shape + (2,)))

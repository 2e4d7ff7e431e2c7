"""Rough corners: the point nearest to the checker lines of every frame (paper 3.2)

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.detect.rough import rough_corners
    >>> yy, xx = np.mgrid[0:41, 0:41] - np.array([20.3, 19.6])[:, None, None]
    >>> frames = np.stack([((np.cos(t) * xx + np.sin(t) * yy) * (-np.sin(t) * xx + np.cos(t) * yy) < 0)
    ...                    for t in np.arange(8) * np.pi / 16]).astype(np.float32) * 200
    >>> contour = np.array([[2, 2], [38, 2], [38, 38], [2, 38]])
    >>> q, ok = rough_corners(frames, [contour], np.array([[20., 20.]]))
    >>> bool(np.hypot(*(q[0] - [19.6, 20.3])) < 0.3), ok.tolist()
    (True, [True])

For each element: the edge points (strong gradient) inside the largest square
centred on the element's centroid that fits inside its boundary; per frame,
the points are split into the two lines of the checker corner by RANSAC line
fits, and a quadratic curve (lens distortion bends the lines) is fitted to each
line's inliers; the rough corner is the least-squares point nearest to all
curves of all frames. All elements and frames are processed as one batch.
"""

from __future__ import annotations

import cv2
import numpy as np

from rotstar_mrcal.detect.boundaries import inscribed_square

MAX_POINTS = 64
RANSAC_HYPOTHESES = 16
INLIER_PX = 1.5


def _edge_points(grad: np.ndarray, centres: np.ndarray, halfsides: np.ndarray, rng):
    """Batched edge points: (B, M, 2) coordinates and (B, M) validity

    grad: (nframes, H, W) gradient magnitude. Batch b = element * nframes + frame.
    Each element's square is cut out as a fixed-size patch (the largest square
    of the pose), pixels outside the element's own square masked off; the edge
    points are the pixels above 30% of the patch's strongest gradient.
    """
    nf, H, W = grad.shape
    E = len(centres)
    R = int(np.ceil(np.max(halfsides))) if E else 0
    o = np.arange(-R, R + 1)
    cx = np.round(centres[:, 0]).astype(int)
    cy = np.round(centres[:, 1]).astype(int)
    X = cx[:, None, None] + o[None, None, :]  # (E, 1, P)
    Y = cy[:, None, None] + o[None, :, None]  # (E, P, 1)
    inside = (np.abs(X - centres[:, 0, None, None]) <= halfsides[:, None, None]) & (
        np.abs(Y - centres[:, 1, None, None]) <= halfsides[:, None, None]
    )
    inside &= (X >= 0) & (X < W) & (Y >= 0) & (Y < H)
    Xc, Yc = np.clip(X, 0, W - 1), np.clip(Y, 0, H - 1)
    patch = grad[:, Yc, Xc]  # (nf, E, P, P)
    patch = np.where(inside[None], patch, 0.0).transpose(1, 0, 2, 3).reshape(E * nf, -1)
    inside = np.broadcast_to(inside[:, None], (E, nf) + inside.shape[1:]).reshape(E * nf, -1)
    thr = 0.3 * patch.max(axis=1)
    cand = (patch > thr[:, None]) & inside
    # keep at most MAX_POINTS candidates per batch, chosen at random
    key = np.where(cand, rng.random(cand.shape), -1.0)
    M = min(MAX_POINTS, key.shape[1])
    sel = np.argpartition(-key, M - 1, axis=1)[:, :M]
    valid = np.take_along_axis(cand, sel, axis=1)
    mag = np.take_along_axis(patch, sel, axis=1)
    P = 2 * R + 1
    xs = np.broadcast_to(X, (E, P, P)).reshape(E, 1, -1).repeat(nf, 1).reshape(E * nf, -1)
    ys = np.broadcast_to(Y, (E, P, P)).reshape(E, 1, -1).repeat(nf, 1).reshape(E * nf, -1)
    pts = np.stack((np.take_along_axis(xs, sel, 1), np.take_along_axis(ys, sel, 1)), axis=-1).astype(float)
    # valid points first, so that RANSAC can sample the first n entries
    order = np.argsort(~valid, axis=1, kind="stable")
    return (np.take_along_axis(pts, order[..., None], 1), np.take_along_axis(valid, order, 1),
            np.take_along_axis(mag, order, 1))


def _ransac_lines(pts, valid, rng):
    """Best line per batch: (point, unit direction), inlier mask"""
    B, M, _ = pts.shape
    n = valid.sum(axis=1)
    # random pairs of valid points (indices into the first n entries)
    u = rng.random((B, RANSAC_HYPOTHESES, 2))
    idx = np.minimum((u * np.maximum(n, 1)[:, None, None]).astype(int), np.maximum(n - 1, 0)[:, None, None])
    p0 = np.take_along_axis(pts, idx[..., 0, None].repeat(2, -1).reshape(B, -1, 2), axis=1)
    p1 = np.take_along_axis(pts, idx[..., 1, None].repeat(2, -1).reshape(B, -1, 2), axis=1)
    d = p1 - p0
    norm = np.linalg.norm(d, axis=-1, keepdims=True)
    d = np.where(norm > 1e-9, d / np.maximum(norm, 1e-9), [1.0, 0.0])
    nrm = np.stack((-d[..., 1], d[..., 0]), axis=-1)  # (B, K, 2)
    dist = np.abs(nrm @ pts.transpose(0, 2, 1) - (nrm * p0).sum(-1)[..., None])
    inl = (dist < INLIER_PX) & valid[:, None, :] & (norm > 2.0)
    best = np.argmax(inl.sum(axis=-1), axis=1)
    inliers = inl[np.arange(B), best]
    return inliers


def _fit_quadratic(pts, w, min_span: float = 12.0):
    """Weighted quadratic curve per batch in a frame aligned with its principal axis

    Returns (centre (B,2), direction (B,2), coefficients (B,3) of
    v = c0 + c1 u + c2 u^2, u along direction from centre), ok (B,)
    """
    sw = w.sum(axis=1)
    ok = sw >= 6
    swc = np.maximum(sw, 1)[:, None]
    m = (w[..., None] * pts).sum(axis=1) / swc
    x = pts - m[:, None, :]
    cov = (x.transpose(0, 2, 1) * w[:, None, :]) @ x / swc[..., None]
    evals, evecs = np.linalg.eigh(cov)
    direction = evecs[..., :, 1]  # largest eigenvalue
    normal = np.stack((-direction[:, 1], direction[:, 0]), axis=-1)
    u = (x * direction[:, None, :]).sum(-1)
    v = (x * normal[:, None, :]).sum(-1)
    # curvature only where the points span enough of the line to show it
    span = np.sqrt(np.maximum(evals[:, 1], 0)) * 3.46  # ~ length of a uniform segment
    A = np.stack((np.ones_like(u), u, u * u * (span[:, None] >= min_span)), axis=-1)
    Aw = A.transpose(0, 2, 1) * w[:, None, :]
    AtA = Aw @ A + 1e-9 * np.eye(3)
    Atv = (Aw @ v[..., None])[..., 0]
    coef = np.linalg.solve(AtA, Atv[..., None])[..., 0]
    ok &= evals[:, 1] > 4 * np.maximum(evals[:, 0], 1e-12)  # elongated: a line, not a blob
    return m, direction, coef, ok


def _curve_residuals(q, m, direction, coef):
    """Signed distances of q (E,2) to the curves (E,C,...) and their gradients"""
    normal = np.stack((-direction[..., 1], direction[..., 0]), axis=-1)
    x = q[:, None, :] - m
    u = np.einsum("ecd,ecd->ec", x, direction)
    v = np.einsum("ecd,ecd->ec", x, normal)
    f = coef[..., 0] + coef[..., 1] * u + coef[..., 2] * u * u
    fp = coef[..., 1] + 2 * coef[..., 2] * u
    s = np.sqrt(1 + fp * fp)
    r = (v - f) / s
    grad = (normal - fp[..., None] * direction) / s[..., None]
    return r, grad


def rough_corners(frames: np.ndarray, contours: list, centroids: np.ndarray, seed: int = 0):
    """Rough corner of every element: (E, 2) positions and (E,) success flags"""
    rng = np.random.default_rng(seed)
    f = np.asarray(frames, np.float32)
    nf = len(f)
    grad = np.stack([cv2.magnitude(cv2.Sobel(k, cv2.CV_32F, 1, 0), cv2.Sobel(k, cv2.CV_32F, 0, 1)) for k in f])
    half = np.array([inscribed_square(c, m) for c, m in zip(contours, centroids)]) * 0.85 - 1.0
    pts, valid, mag = _edge_points(grad, centroids, half, rng)
    E = len(centroids)
    in1 = _ransac_lines(pts, valid, rng)
    rest = valid & ~in1
    in2 = _ransac_lines(pts, rest, rng)
    # weights: the gradient magnitude, so that a thick edge band fits at its middle
    w = np.concatenate((in1, in2)) * np.concatenate((mag, mag))
    P = np.concatenate((pts, pts))
    m, d, coef, okc = _fit_quadratic(P, w)
    # refit each curve on the points within INLIER_PX of it (a RANSAC-style consensus step)
    r, _ = _curve_residuals_points(P, m, d, coef)
    w = w * (np.abs(r) < INLIER_PX)
    m, d, coef, okc2 = _fit_quadratic(P, w)
    okc &= okc2
    # (2B,) -> (E, 2*nf) curves per element
    def per_element(a):
        a = a.reshape((2, E, nf) + a.shape[1:])
        return np.moveaxis(a, 0, 2).reshape((E, 2 * nf) + a.shape[3:])

    m, d, coef, okc = per_element(m), per_element(d), per_element(coef), per_element(okc)
    wc = okc.astype(float)
    # start: least-squares intersection of the tangent lines at the curve centres
    q = centroids.astype(float).copy()
    for _ in range(8):
        r, g = _curve_residuals(q, m, d, coef)
        JtJ = np.einsum("ec,eci,ecj->eij", wc, g, g) + 1e-9 * np.eye(2)
        Jtr = np.einsum("ec,eci,ec->ei", wc, g, r)
        step = -np.linalg.solve(JtJ, Jtr[..., None])[..., 0]
        q += step
        if np.all(np.abs(step) < 1e-3):
            break
    ok = (wc.sum(axis=1) >= 4) & np.all(np.isfinite(q), axis=1)
    ok &= np.max(np.abs(q - centroids), axis=1) <= np.maximum(half, 1)
    return q, ok


def _curve_residuals_points(P, m, d, coef):
    """Distances of every point (B, M, 2) to its batch's curve"""
    normal = np.stack((-d[:, 1], d[:, 0]), axis=-1)
    x = P - m[:, None, :]
    u = (x * d[:, None, :]).sum(-1)
    v = (x * normal[:, None, :]).sum(-1)
    f = coef[:, 0, None] + coef[:, 1, None] * u + coef[:, 2, None] * u * u
    return v - f, u

"""Do the identities agree with the image? Each element against its labelled neighbours

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.detect.consistency import label_consistency
    >>> j, i = np.mgrid[0:4, 0:5]
    >>> labels = np.column_stack((i.ravel(), j.ravel()))
    >>> points = 30.0 * labels + [100, 50]               # the image of a 5 x 4 grid
    >>> labels[7] = (4, 3)                                # one identity misread as another element's ...
    >>> labels = np.delete(labels, 19, axis=0); points = np.delete(points, 19, axis=0)   # ... not in view
    >>> ok, reason = label_consistency(labels, points)
    >>> np.flatnonzero(~ok).tolist(), reason[7]
    ([7], 'identity disagrees with its neighbours (85 px from where they put it)')

The identities name the elements; the element graph checks them. An element
is accepted when at least three of its labelled neighbours (the 8 around its
label, not all on a line) are in view and the affine map from labels to the
image fitted to them (the element itself left out) puts it within TOLERANCE
grid steps of where it is; the step is the map's smaller singular value, so
a steep tilt does not loosen the test. A misread identity sits at least one
step away from where its label belongs (or has no neighbours there at all).
The worst offender (farthest in pixels) is dropped and the test repeated, so that one wrong
element does not condemn the neighbours it leans on. An element with too
few labelled neighbours cannot be checked and is dropped.
"""

from __future__ import annotations

import cv2
import numpy as np

TOLERANCE = 0.3  # grid steps
OFFSETS = np.array([(di, dj) for dj in (-1, 0, 1) for di in (-1, 0, 1) if di or dj])


def _label_table(labels: np.ndarray, pad: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(table, lo): table[j - lo[1], i - lo[0]] is the index of label (i, j), -1 where none; pad: margin of -1"""
    lo = labels.min(axis=0) - pad
    nx, ny = labels.max(axis=0) - lo + 1 + pad
    table = np.full((ny, nx), -1)
    table[labels[:, 1] - lo[1], labels[:, 0] - lo[0]] = np.arange(len(labels))
    return table, lo


def _neighbour_table(labels: np.ndarray) -> np.ndarray:
    """(N, 8) index of the element at label + OFFSETS[k], -1 where none"""
    table, lo = _label_table(labels, pad=1)
    q = labels[:, None, :] + OFFSETS[None] - lo
    return table[q[..., 1], q[..., 0]]


def predict_from_neighbours(labels: np.ndarray, points: np.ndarray, active: np.ndarray):
    """(prediction (N, 2), step (N,)): each element's place from its active neighbours' affine map

    NaN where fewer than three active neighbours, or all on a line.
    """
    nb = _neighbour_table(labels)
    use = (nb >= 0) & active[np.maximum(nb, 0)]
    X = np.concatenate((np.broadcast_to(OFFSETS, nb.shape + (2,)), np.ones(nb.shape + (1,))), axis=-1) * use[..., None]
    Y = np.where(use[..., None], points[np.maximum(nb, 0)], 0.0)
    XtX = np.einsum("nki,nkj->nij", X, X)
    XtY = np.einsum("nki,nkj->nij", X, Y)
    good = (use.sum(axis=1) >= 3) & (np.abs(np.linalg.det(XtX)) > 1e-6)
    coef = np.full((len(labels), 3, 2), np.nan)
    if good.any():
        coef[good] = np.linalg.solve(XtX[good], XtY[good])
    A = coef[:, :2, :]  # rows: d/di, d/dj of the image point
    step = np.full(len(labels), np.nan)
    if good.any():
        step[good] = np.linalg.svd(A[good], compute_uv=False)[:, -1]
    return coef[:, 2, :], step


def drop_worst(n: int, offsets, tolerance: float, why_off, why_lonely, min_kept: int = 1):
    """(ok (n,), reason (n,)): drop the worst offender, measure again, until every kept one is within tolerance

    offsets(ok) -> (off, rank): (n,) offsets of the kept elements (NaN: too
    few neighbours to measure; ignored where not ok) and the (n,) values by
    which the worst is chosen (largest first); why_off(k, off, rank) the
    reason of a dropped one. At the end the unmeasurable are dropped with
    why_lonely; with fewer than min_kept left, all are.

    SYNOPSIS

        >>> import numpy as np
        >>> x = np.array([0.0, 1.0, 2.0, 9.0, 4.0])     # one outlier among points on a line
        >>> def offsets(ok):                           # distance from the mean of the others kept
        ...     off = np.array([abs(x[k] - x[ok & (np.arange(5) != k)].mean()) for k in range(5)])
        ...     return off, off
        >>> ok, why = drop_worst(5, offsets, 3.5, lambda k, o, r: f"{o[k]:.1f} off", "alone")
        >>> ok.tolist(), why[3]
        ([True, True, True, False, True], '7.2 off')
    """
    ok = np.ones(n, bool)
    reason = np.full(n, "", dtype=object)
    off = np.full(n, np.nan)
    while ok.sum() >= min_kept and ok.any():
        off, rank = offsets(ok)
        bad = ok & np.isfinite(off) & (off > tolerance)
        if not bad.any():
            lonely = ok & ~np.isfinite(off)
            ok[lonely] = False
            reason[lonely] = why_lonely
            return ok, reason
        worst = int(np.flatnonzero(bad)[np.argmax(rank[bad])])
        ok[worst] = False
        reason[worst] = why_off(worst, off, rank)
    reason[ok] = why_lonely
    ok[:] = False
    return ok, reason


def label_consistency(labels: np.ndarray, points: np.ndarray, tolerance: float = TOLERANCE):
    """(ok (N,), reason (N,)): which labelled elements agree with their neighbours; see the module doc

    labels: (N, 2) distinct (i, j); points: (N, 2) image positions of the corners.
    The farthest in pixels is dropped first: a wrong neighbour also shrinks
    the step its neighbours are judged by.
    """
    labels = np.asarray(labels, int)
    points = np.asarray(points, float)

    def offsets(ok):
        pred, step = predict_from_neighbours(labels, points, ok)
        dist = np.linalg.norm(points - pred, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            return dist / step, dist

    return drop_worst(len(labels), offsets, tolerance,
                      lambda k, off, dist: f"identity disagrees with its neighbours ({dist[k]:.0f} px from where "
                                           "they put it)",
                      "too few identified neighbours to check its identity against")


def projective_offsets(labels: np.ndarray, points: np.ndarray, radius: int = 2) -> np.ndarray:
    """(N,) each point's distance, in grid steps, from where the homography of its neighbours puts it

    The homography (label -> image) is fitted to the labelled points within
    `radius` grid steps of the element, the element left out (at least 6 of
    them, not all on a line); NaN where there are too few. Sharper than the
    affine test, for refined corners: a board seen close up bends an affine
    map by a fifth of a step, a homography by hundredths.
    """
    labels = np.asarray(labels, int)
    points = np.asarray(points, float)
    out = np.full(len(labels), np.nan)
    table, lo = _label_table(labels)
    for e, (i, j) in enumerate(labels - lo):
        win = table[max(j - radius, 0) : j + radius + 1, max(i - radius, 0) : i + radius + 1].ravel()
        nb = win[(win >= 0) & (win != e)]
        if len(nb) < 6:
            continue
        src = labels[nb].astype(np.float64)
        if np.linalg.matrix_rank(src - src.mean(axis=0), tol=1e-6) < 2:
            continue
        Hm, _ = cv2.findHomography(src, points[nb], 0)
        if Hm is None:
            continue
        l = np.array([*labels[e], 1.0])
        p = Hm @ l
        pred = p[:2] / p[2]
        # the local step: the smaller singular value of the homography's Jacobian at the label
        J = (Hm[:2, :2] - np.outer(pred, Hm[2, :2])) / p[2]
        out[e] = np.linalg.norm(points[e] - pred) / np.linalg.svd(J, compute_uv=False)[-1]
    return out


PROJECTIVE_TOLERANCE = 0.08  # grid steps; refined corners on simulated D435 views: <= 0.0065


def refined_consistency(labels: np.ndarray, points: np.ndarray, tolerance: float = PROJECTIVE_TOLERANCE):
    """(ok (N,), reason (N,)): refined corners that sit where their neighbours' homography puts them

    As label_consistency, the farthest offender first, but with the
    homography of the neighbours within two steps (projective_offsets): a
    corner cut by the image edge whose refinement found a wrong point of
    symmetry is off by a fraction of a step, which this sees and the affine
    test may not. A corner with too few neighbours to fit is dropped.
    """
    labels = np.asarray(labels, int)
    points = np.asarray(points, float)

    def offsets(ok):
        off = np.full(len(labels), np.nan)
        off[ok] = projective_offsets(labels[ok], points[ok])
        return off, off

    return drop_worst(len(labels), offsets, tolerance,
                      lambda k, off, _: f"corner off the homography of its neighbours by {off[k]:.2f} grid steps",
                      "too few refined neighbours to check its corner against", min_kept=6)

"""Nearest-element queries of the grid indexing, in numpy (no scipy import at start-up)

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.detect.nearest import nearest_label
    >>> lab = np.zeros((5, 9), np.int32); lab[:, :2] = 1; lab[:, 7:] = 2
    >>> nearest_label(lab, max_dist=3.0)[0].tolist()   # ties go to the smaller column
    [1, 1, 1, 1, 1, 2, 2, 2, 2]

`nearest_label` is `lab[indices]` of scipy.ndimage.distance_transform_edt(lab
== 0, return_indices=True), zeroed where the distance exceeds max_dist, with
the same choice among equally near element pixels: scipy's exact transform
works column by column first (the nearest element pixel of each column,
the upper one of two as near), then along the rows (the nearest of those,
the leftmost of several as near); here the same two passes, the second over
the columns within max_dist only.

`knn_third_party` answers contact_graph's question about a boundary point
between elements a and b: among its k nearest contour points (scipy's
cKDTree.query(p, k)), is the nearest point of a third element more than
`ratio` times farther than the nearest point of a or b? The k nearest are
found shell by shell of equal distance on the pixel grid, stopping as soon as
the answer is settled (the nearest point of a or b is known, and so is the
nearest third point or every point left is too far to matter). Where the k-th and
(k+1)-th nearest are equally far and the choice between them could change the
answer (cKDTree keeps whichever it met first), the query is marked undecided
and the caller asks cKDTree itself.
"""

from __future__ import annotations

import functools

import numpy as np

_BIG = 1 << 20


def nearest_label(lab: np.ndarray, max_dist: float) -> np.ndarray:
    """Label of the nearest nonzero pixel of lab (scipy's choice), 0 beyond max_dist"""
    H, W = lab.shape
    feat = lab > 0
    rows = np.arange(H)[:, None]
    up = np.maximum.accumulate(np.where(feat, rows, -_BIG), axis=0)
    dn = np.minimum.accumulate(np.where(feat, rows, _BIG)[::-1], axis=0)[::-1]
    use_up = rows - up <= dn - rows
    frow = np.where(use_up, up, dn)  # nearest element row in each column; huge where none
    dy = np.abs(frow - rows).astype(np.int64)
    R = int(np.floor(max_dist)) if np.isfinite(max_dist) else W
    R = max(min(R, W), 0)
    g = np.full((H, W + 2 * R), np.int64(_BIG) ** 2)
    g[:, R:R + W] = dy * dy
    best = np.full((H, W), np.int64(_BIG) ** 2)
    col = np.zeros((H, W), np.intp)
    xs = np.arange(W)
    for dx in range(-R, R + 1):  # increasing column: strict improvement keeps the leftmost of ties
        d2 = g[:, R + dx:R + dx + W] + dx * dx
        better = d2 < best
        np.copyto(best, d2, where=better)
        np.copyto(col, xs + dx, where=better)
    ok = np.sqrt(best.astype(np.float64)) <= max_dist
    colc = np.clip(col, 0, W - 1)
    rowc = np.clip(np.take_along_axis(frow, colc, axis=1), 0, H - 1)
    return np.where(ok, lab[rowc, colc], 0)


@functools.lru_cache(maxsize=4)
def _shells(half_axis: int, radius: int):
    """Integer offsets about a point half a pixel off the grid along axis half_axis (0: x, 1: y),
    grouped in shells of equal distance: (offsets (M, 2) as (dx, dy), squared distances, shell starts)"""
    r = np.arange(-radius, radius + 2)
    dx, dy = np.meshgrid(r, r, indexing="xy")
    dx, dy = dx.ravel(), dy.ravel()
    fx = dx - 0.5 if half_axis == 0 else dx.astype(float)
    fy = dy - 0.5 if half_axis == 1 else dy.astype(float)
    d2 = fx * fx + fy * fy
    keep = d2 <= radius * radius
    order = np.argsort(d2[keep], kind="stable")
    off = np.column_stack((dx[keep], dy[keep]))[order]
    d2 = d2[keep][order]
    starts = np.flatnonzero(np.r_[True, d2[1:] != d2[:-1]])
    return off, d2, starts


def knn_third_party(points: np.ndarray, owner: np.ndarray, p: np.ndarray, a: np.ndarray, b: np.ndarray,
                    k: int = 24, ratio: float = 1.25, radius: int = 24):
    """(keep, undecided) per query p: d_3 > ratio * d_ab over the k nearest points, as contact_graph asks

    points: (M, 2) integer pixels (contour points, with repeats), owner (M,)
    their element; p (Q, 2) queries each half a pixel off the grid along x
    or y; a, b (Q,) the two elements each query lies between. d_ab / d_3:
    the distance of the nearest of the k nearest points owned by a or b / by
    another element (inf if none). undecided: ties at the k-th distance could
    change the answer, or the k nearest lie beyond `radius`; the caller must
    then ask a k-d tree.
    """
    Q = len(p)
    keep = np.zeros(Q, bool)
    undecided = np.zeros(Q, bool)
    if Q == 0:
        return keep, undecided
    pts = np.asarray(points, np.int64)
    box = np.vstack((pts, np.floor(p).astype(np.int64)))
    lo = box.min(axis=0) - radius - 2
    size = box.max(axis=0) - lo + radius + 3
    W = int(size[0])
    flat = (pts[:, 1] - lo[1]) * W + (pts[:, 0] - lo[0])
    u, first, inv, count = np.unique(flat, return_index=True, return_inverse=True, return_counts=True)
    own_u = owner[first]
    if np.any(owner != own_u[inv]):
        return keep, np.ones(Q, bool)  # one pixel on two elements' contours: leave it to the k-d tree
    cnt_img = np.zeros(int(size[0] * size[1]), np.int32)
    own_img = np.full(int(size[0] * size[1]), -1, np.int32)
    cnt_img[u] = count
    own_img[u] = own_u
    halfx = (p[:, 0] % 1) != 0
    for half_axis, sel in ((0, np.flatnonzero(halfx)), (1, np.flatnonzero(~halfx))):
        if len(sel):
            kp, un = _knn_group(cnt_img, own_img, W, lo, np.floor(p[sel]).astype(np.int64), a[sel], b[sel],
                                half_axis, k, ratio, radius)
            keep[sel], undecided[sel] = kp, un
    return keep, undecided


def _knn_group(cnt_img, own_img, W, lo, base, aa, bb, half_axis, k, ratio, radius, block=12):
    """knn_third_party for queries half a pixel right of (or below) the grid points `base`"""
    Q = len(base)
    keep = np.zeros(Q, bool)
    undecided = np.ones(Q, bool)
    bflat = (base[:, 1] - lo[1]) * W + (base[:, 0] - lo[0])
    off, d2, starts = _shells(half_axis, radius)
    oflat = off[:, 1] * W + off[:, 0]
    shell = np.repeat(np.arange(len(starts)), np.diff(np.r_[starts, len(off)]))  # shell of each offset
    dist = np.sqrt(d2)
    used = np.zeros(Q, np.int64)  # points taken so far
    aa32, bb32 = aa.astype(np.int32), bb.astype(np.int32)
    d_ab = np.full(Q, np.inf)
    d_3 = np.full(Q, np.inf)
    active = np.arange(Q)
    # blocks of whole shells
    cuts = [0]
    for st in np.r_[starts, len(off)]:
        if st - cuts[-1] >= block * len(cuts):  # blocks of growing size: most queries settle early
            cuts.append(int(st))
    if cuts[-1] != len(off):
        cuts.append(len(off))
    for j0, j1 in zip(cuts[:-1], cuts[1:]):
        if not len(active):
            break
        idx = bflat[active, None] + oflat[None, j0:j1]
        c = cnt_img[idx]
        ow = own_img[idx]
        isab = (ow == aa32[active, None]) | (ow == bb32[active, None])
        c_ab = np.where(isab, c, 0)
        c_o = c - c_ab
        cum = used[active, None] + np.cumsum(c, axis=1)  # points taken up to and including each offset
        reach = cum >= k
        hit = reach.any(axis=1)
        pos = np.where(hit, np.argmax(reach, axis=1), j1 - j0 - 1)  # where the k-th point lies
        sh = shell[j0 + pos]
        # offsets of shells entirely before the k-th point's shell (or the whole block) are all taken
        s_first = np.searchsorted(shell[j0:j1], sh, side="left")  # block-relative start of that shell
        s_end = np.searchsorted(shell[j0:j1], sh, side="right")
        col = np.arange(j1 - j0)[None, :]
        before = np.where(hit[:, None], col < s_first[:, None], True)
        fa = (c_ab > 0) & before
        fo = (c_o > 0) & before
        ia, io = np.argmax(fa, axis=1), np.argmax(fo, axis=1)
        t_ab = np.where(fa.any(axis=1), dist[j0 + ia], np.inf)
        t_o = np.where(fo.any(axis=1), dist[j0 + io], np.inf)
        da = np.where(np.isinf(d_ab[active]), t_ab, d_ab[active])
        d3 = np.where(np.isinf(d_3[active]), t_o, d_3[active])
        d_ab[active], d_3[active] = da, d3
        used[active[~hit]] = cum[~hit, -1]
        h = np.flatnonzero(hit)
        if len(h):
            in_shell = (col[0][None, :] >= s_first[h, None]) & (col[0][None, :] < s_end[h, None])
            n_ab = np.where(in_shell, c_ab[h], 0).sum(axis=1)
            n_o = np.where(in_shell, c_o[h], 0).sum(axis=1)
            prior = np.where(s_first[h] > 0, cum[h, np.maximum(s_first[h] - 1, 0)], used[active[h]])
            m = k - prior  # picks from the k-th point's shell
            sd = dist[j0 + s_first[h]]
            val = np.zeros(len(h), int)  # bit 1: some choice keeps, bit 2: some choice drops
            for inc_ab, inc_o, feasible in ((True, True, (m >= 2) & (n_ab >= 1) & (n_o >= 1)),
                                            (True, False, n_ab >= m), (False, True, n_o >= m)):
                dab = np.where(np.isinf(da[h]) & inc_ab, sd, da[h])
                dd3 = np.where(np.isinf(d3[h]) & inc_o, sd, d3[h])
                val |= np.where(feasible, np.where(dd3 > ratio * dab, 1, 2), 0)
            q = active[h]
            keep[q] = val == 1
            undecided[q] = val == 3
        # settled early: the nearest of a or b is known, and so is the nearest third point or
        # every point left is farther than ratio x that (then it cannot matter)
        settled = ~hit & np.isfinite(da) & (np.isfinite(d3) | (dist[j1 - 1] >= ratio * da))
        q = active[settled]
        keep[q] = d3[settled] > ratio * da[settled]
        undecided[q] = False
        active = active[~hit & ~settled]
    return keep, undecided

"""Element identities: the identity frames name every element in view (issue 13)

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.pattern.identity import IdentityCode
    >>> from rotstar_mrcal.detect.identity import read_identities
    >>> code = IdentityCode.for_grid(3, 3)
    >>> ident = np.zeros((code.nframes, 60, 70), np.float32)
    >>> for e, (x, y) in enumerate([(5, 5), (25, 5), (45, 5), (5, 25)]):   # four elements, the last cut
    ...     ident[:, y:y + 15, max(x - 8 * (e == 3), 0):x + 15] = 200 * code.codewords[e][:, None, None]
    >>> ids = read_identities(np.full((2, 60, 70), 200, np.float32), ident, code)
    >>> sorted(zip(ids.index.tolist(), ids.touches_edge.tolist()))
    [(0, False), (1, False), (2, False), (3, True)]

The identity frames show every element's square white or black, the border
bands black: an element pixel changes between identity frames, a band pixel
and the screen's surround do not. The *identity map* is each pixel's
contrast over the identity frames (max - min) over its brightness in all
frames (floored at a quarter of the image's white, so that dark noise does
not count; not smoothed, which would close the thin bands of small, steep
elements); the elements are the connected regions
where it exceeds MAP_THRESHOLD, whether whole or cut by the image edge or an
occluder. A region whose code does not read may be two elements joined
across a band that blur or saturation closed: it is cut again at the higher
SPLIT_THRESHOLD, and the parts are read on their own. Each element's level in each identity frame is the mean of a
5 x 5 lattice of points spread over the largest square inside it, and the
code (pattern/identity.py) reads its index from those levels or rejects it
with a reason. Labels never come from the elements' arrangement here; that
is checked afterwards (consistency.py).
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from ..pattern.identity import IdentityCode
from .boundaries import inscribed_square

MAP_THRESHOLD = 0.7
SPLIT_THRESHOLD = 0.85  # inside regions whose code is unreadable: the bands closed by blur or saturation
WHITE_FLOOR = 0.25  # the brightness floor, a fraction of the image's white (99.9th percentile)
MIN_AREA = 12.0  # px: smaller regions are noise
SAMPLES = 5  # per side of the lattice of points an element's level is measured on


@dataclasses.dataclass
class Identities:
    """The elements seen in the identity frames and what their codes say"""

    contours: list  # (M, 2) int boundary of each element region
    centroids: np.ndarray  # (N, 2)
    areas: np.ndarray  # (N,)
    touches_edge: np.ndarray  # (N,) bool: the region reaches the image border
    index: np.ndarray  # (N,) element index j * nx + i, -1 where not read
    reason: np.ndarray  # (N,) '' or why the code was not read
    inscribed: np.ndarray  # (N,) half-side of the largest axis-aligned square about the centroid
    mask: np.ndarray  # (H, W) uint8, the element regions

    def labels(self, nx: int) -> np.ndarray:
        """(N, 2) (i, j) of every element (-1, -1 where not read)"""
        return np.where(self.index[:, None] >= 0, np.stack((self.index % nx, self.index // nx), axis=-1), -1)


def identity_map(rotstar: np.ndarray, identity: np.ndarray) -> np.ndarray:
    """(H, W) float32 in [0, 1]: contrast over the identity frames / brightness; see the module doc"""
    hi = np.asarray(identity[0], np.float32).copy()
    lo = hi.copy()
    for f in identity[1:]:
        f = np.asarray(f, np.float32)
        cv2.max(hi, f, dst=hi)
        cv2.min(lo, f, dst=lo)
    bright = hi.copy()
    for f in rotstar:
        cv2.max(bright, np.asarray(f, np.float32), dst=bright)
    white = float(np.percentile(bright[::4, ::4], 99.9))
    return (hi - lo) / np.maximum(bright, WHITE_FLOOR * white + 1e-12)


def element_regions(mask: np.ndarray, min_area: float = MIN_AREA):
    """(contours, centroids, areas, touches_edge) of the connected regions of a binary mask"""
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    cs = [c[:, 0, :] for c in contours]
    moments = [cv2.moments(c) for c in cs]
    keep = [m["m00"] >= min_area for m in moments]
    cs = [c for c, k in zip(cs, keep) if k]
    moments = [m for m, k in zip(moments, keep) if k]
    centroids = np.array([(m["m10"] / m["m00"], m["m01"] / m["m00"]) for m in moments]).reshape(-1, 2)
    areas = np.array([m["m00"] for m in moments])
    H, W = mask.shape
    edge = np.array([bool((c[:, 0].min() <= 0) | (c[:, 1].min() <= 0) | (c[:, 0].max() >= W - 1)
                          | (c[:, 1].max() >= H - 1)) for c in cs], bool)
    return cs, centroids, areas, edge


def element_levels(identity: np.ndarray, centres: np.ndarray, halfsides: np.ndarray) -> np.ndarray:
    """(N, nidentity) mean of each identity frame over a SAMPLES x SAMPLES lattice in each element's square"""
    t = np.linspace(-0.6, 0.6, SAMPLES)
    oy, ox = np.meshgrid(t, t, indexing="ij")
    x = np.rint(centres[:, 0, None] + halfsides[:, None] * ox.ravel()).astype(int)
    y = np.rint(centres[:, 1, None] + halfsides[:, None] * oy.ravel()).astype(int)
    H, W = identity.shape[1:]
    x, y = np.clip(x, 0, W - 1), np.clip(y, 0, H - 1)
    return identity[:, y, x].mean(axis=-1).T  # (N, nf)


def pixel_noise(frames: np.ndarray) -> float:
    """Robust standard deviation of one pixel, from horizontal neighbour differences of two frames"""
    d = np.diff(np.asarray(frames[:2, ::8, :], np.float32), axis=-1)
    return max(float(np.median(np.abs(d - np.median(d)))) * 1.4826 / np.sqrt(2), 0.3)


def _read(mask, identity, code, noise):
    cs, centroids, areas, edge = element_regions(mask)
    inscribed = np.array([inscribed_square(c, m) for c, m in zip(cs, centroids)]).reshape(-1)
    if not cs:
        return cs, centroids, areas, edge, inscribed, np.zeros(0, int), np.zeros(0, object)
    levels = element_levels(identity, centroids, np.maximum(inscribed, 0.5))
    index, reason = code.decode(levels, noise=noise)
    return cs, centroids, areas, edge, inscribed, index, reason


def read_identities(rotstar: np.ndarray, identity: np.ndarray, code: IdentityCode) -> Identities:
    """Find the elements in the identity frames and read their codes; see the module doc"""
    identity = np.asarray(identity, np.float32)
    if len(identity) != code.nframes:
        raise ValueError(f"{len(identity)} identity frames; the code has {code.nframes}")
    imap = identity_map(rotstar, identity)
    mask = (imap > MAP_THRESHOLD).astype(np.uint8)
    noise = pixel_noise(identity) / SAMPLES  # of the mean of SAMPLES^2 pixels
    parts = [list(_read(mask, identity, code, noise))]
    # regions whose code reads as neither: two elements joined across a band closed by blur or
    # saturation? The band is darker in the map than the elements: split them at SPLIT_THRESHOLD
    failed = np.flatnonzero(parts[0][5] < 0)
    if len(failed):
        inside = np.zeros_like(mask)
        cv2.drawContours(inside, [parts[0][0][k].reshape(-1, 1, 2) for k in failed], -1, 1, cv2.FILLED)
        split = list(_read(inside & (imap > SPLIT_THRESHOLD).astype(np.uint8), identity, code, noise))
        if (split[5] >= 0).any():
            keep = np.ones(len(parts[0][0]), bool)
            keep[failed] = False
            parts = [[[c for c, k in zip(v, keep) if k] if isinstance(v, list) else v[keep] for v in parts[0]],
                     split]
    cs = [c for p in parts for c in p[0]]
    centroids, areas, edge, inscribed, index, reason = (
        np.concatenate([p[k] for p in parts]) for k in range(1, 7))
    # an index read twice names two places: neither can be trusted
    uniq, counts = np.unique(index[index >= 0], return_counts=True)
    twice = np.isin(index, uniq[counts > 1])
    reason[twice] = "identity read in two places"
    index = np.where(twice, -1, index)
    return Identities(cs, centroids.reshape(-1, 2), areas, edge.astype(bool), index, reason, inscribed, mask)

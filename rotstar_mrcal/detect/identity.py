"""Element identities: the identity frames name every element in view (codes in time, beside the paper's graph)

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
is checked afterwards (consistency.py). When most codes do not read because
one identity frame is inverted or two are swapped, `misordered` says which
(IdentityCode.misordered), and the pose is refused with that reason.

An identity frame that was not recorded is all NaN (dataset.identity_stack):
the map is that of the other frames, its level in every element NaN, and
the code reads each element from the other frames (IdentityCode.decode).
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from rotstar_mrcal.pattern.identity import MISORDER_READ, IdentityCode
from rotstar_mrcal.detect.boundaries import inscribed_square, on_border
from rotstar_mrcal.detect.response import pixel_noise

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
    touches_edge: np.ndarray  # (N,) bool: the region reaches the image border
    inscribed: np.ndarray  # (N,) half-side of the largest axis-aligned square about the centroid
    index: np.ndarray  # (N,) element index j * nx + i, -1 where not read
    reason: np.ndarray  # (N,) '' or why the code was not read
    misordered: tuple = ()  # IdentityCode.misordered of the elements' levels: a frame inverted, two swapped

    def labels(self, nx: int) -> np.ndarray:
        """(N, 2) (i, j) of every element (-1, -1 where not read)"""
        return np.where(self.index[:, None] >= 0, np.stack((self.index % nx, self.index // nx), axis=-1), -1)

    def without(self, drop: np.ndarray, other: "Identities") -> "Identities":
        """These elements less those at indices `drop`, followed by other's"""
        keep = np.ones(len(self.index), bool)
        keep[drop] = False
        arrays = {f.name: np.concatenate((getattr(self, f.name)[keep], getattr(other, f.name)))
                  for f in dataclasses.fields(self) if f.name not in ("contours", "misordered")}
        return Identities([c for c, k in zip(self.contours, keep) if k] + other.contours, **arrays)


def absent_frames(identity: np.ndarray) -> np.ndarray:
    """(nidentity,) bool: the identity frames that were not recorded (all NaN; dataset.identity_stack)

    >>> absent_frames(np.array([[[1.0, 2.0]], [[np.nan, np.nan]], [[np.nan, 0.0]]])).tolist()
    [False, True, False]
    """
    return np.array([bool(np.isnan(f.flat[0]) and np.isnan(f).all()) for f in identity], bool)


def identity_map(rotstar: np.ndarray, identity: np.ndarray) -> np.ndarray:
    """(H, W) float32 in [0, 1]: contrast over the identity frames / brightness; see the module doc

    A frame that was not recorded (all NaN) is left out: the map of the others.
    """
    identity = [f for f, m in zip(identity, absent_frames(identity)) if not m]
    if not identity:
        return np.zeros(np.shape(rotstar)[1:], np.float32)
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
    """(contours, centroids, touches_edge) of the connected regions of a binary mask"""
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    moments = [(c[:, 0, :], cv2.moments(c)) for c in contours]
    moments = [(c, m) for c, m in moments if m["m00"] >= min_area]
    cs = [c for c, _ in moments]
    centroids = np.array([(m["m10"] / m["m00"], m["m01"] / m["m00"]) for _, m in moments]).reshape(-1, 2)
    edge = np.array([on_border(c, mask.shape).any() for c in cs], bool)
    return cs, centroids, edge


def element_levels(identity: np.ndarray, centres: np.ndarray, halfsides: np.ndarray) -> np.ndarray:
    """(N, nidentity) mean of each identity frame over a SAMPLES x SAMPLES lattice in each element's square

    NaN in the column of a frame that was not recorded (IdentityCode.decode reads one such).
    """
    t = np.linspace(-0.6, 0.6, SAMPLES)
    oy, ox = np.meshgrid(t, t, indexing="ij")
    x = np.rint(centres[:, 0, None] + halfsides[:, None] * ox.ravel()).astype(int)
    y = np.rint(centres[:, 1, None] + halfsides[:, None] * oy.ravel()).astype(int)
    H, W = identity.shape[1:]
    x, y = np.clip(x, 0, W - 1), np.clip(y, 0, H - 1)
    return identity[:, y, x].mean(axis=-1).T  # (N, nf)


def _read(mask, identity, code, noise) -> Identities:
    """The elements of the regions of mask, and their codes"""
    cs, centroids, edge = element_regions(mask)
    inscribed = np.array([inscribed_square(c, m) for c, m in zip(cs, centroids)]).reshape(-1)
    if cs:
        index, reason = code.decode(element_levels(identity, centroids, np.maximum(inscribed, 0.5)), noise=noise)
    else:
        index, reason = np.zeros(0, int), np.zeros(0, object)
    return Identities(cs, centroids, edge, inscribed, index, reason)


def undo_inversion(identity: np.ndarray, k: int, missing: np.ndarray | None = None) -> np.ndarray:
    """The identity frames with frame k inverted back within the other frames' range, pixel by pixel

    An inverted image (full scale - value) makes the screen's surround and
    bands, dark in every other identity frame, bright in frame k: the
    identity map then joins everything into one region. Within the other
    frames' per-pixel range [lo, hi], lo + hi - frame k restores an
    element's bit and leaves what never changes at its level.

    >>> f = np.array([[10.0, 10], [10, 200], [200, 10]])[:, None, :]    # pixel 1 is surround (10 throughout)
    >>> inv = f.copy(); inv[0] = 255 - f[0]                             # frame 0 written inverted
    >>> undo_inversion(inv, 0)[:, 0].tolist()
    [[10.0, 10.0], [10.0, 200.0], [200.0, 10.0]]

    missing: (nidentity,) bool, the frames not recorded (absent_frames), left out of the range.
    """
    keep = np.ones(len(identity), bool) if missing is None else ~np.asarray(missing, bool)
    keep[k] = False
    others = identity[keep]
    lo, hi = others.min(axis=0), others.max(axis=0)
    out = identity.copy()
    out[k] = np.clip(lo + hi - identity[k], lo, hi)
    return out


def inverted_frame(rotstar: np.ndarray, identity: np.ndarray, code: IdentityCode, read: int, noise: float) -> tuple:
    """() or ('inverted', k, read, fixed, n) when undoing frame k's inversion (undo_inversion) reads the board

    Tried when the frames as recorded read fewer than 4 elements (no board):
    fixed of the n elements then found read, at least MISORDER_READ of them.
    A frame that was not recorded (absent_frames) is neither tried nor used.
    """
    missing = absent_frames(identity)
    for k in np.flatnonzero(~missing):
        fixed = undo_inversion(identity, k, missing)
        ids = _read((identity_map(rotstar, fixed) > MAP_THRESHOLD).astype(np.uint8), fixed, code, noise)
        n, ok = len(ids.index), int(np.sum(ids.index >= 0))
        if ok >= 4 and ok >= MISORDER_READ * n:
            return ("inverted", int(k), read, ok, n)
    return ()


def read_identities(rotstar: np.ndarray, identity: np.ndarray, code: IdentityCode) -> Identities:
    """Find the elements in the identity frames and read their codes; see the module doc"""
    identity = np.asarray(identity, np.float32)
    if len(identity) != code.nframes:
        raise ValueError(f"{len(identity)} identity frames; the code has {code.nframes}")
    imap = identity_map(rotstar, identity)
    present = identity[np.flatnonzero(~absent_frames(identity))[:2]]  # pixel_noise reads two frames
    noise = pixel_noise(present) / SAMPLES if len(present) else 0.0  # of the mean of SAMPLES^2 pixels
    ids = _read((imap > MAP_THRESHOLD).astype(np.uint8), identity, code, noise)
    if len(ids.index):  # most codes unread: a frame inverted, or two swapped?
        levels = element_levels(identity, ids.centroids, np.maximum(ids.inscribed, 0.5))
        ids.misordered = code.misordered(levels, noise)
        if ids.misordered:
            return ids
    if np.sum(ids.index >= 0) < 4:  # no board: a frame inverted as a whole image (its surround white too)?
        ids.misordered = inverted_frame(rotstar, identity, code, int(np.sum(ids.index >= 0)), noise)
        if ids.misordered:
            return ids
    # regions whose code reads as neither: two elements joined across a band closed by blur or
    # saturation? The band is darker in the map than the elements: split them at SPLIT_THRESHOLD
    failed = np.flatnonzero(ids.index < 0)
    if len(failed):
        inside = np.zeros(imap.shape, np.uint8)
        cv2.drawContours(inside, [ids.contours[k].reshape(-1, 1, 2) for k in failed], -1, 1, cv2.FILLED)
        split = _read(inside & (imap > SPLIT_THRESHOLD).astype(np.uint8), identity, code, noise)
        if (split.index >= 0).any():
            ids = ids.without(failed, split)
    # an index read twice names two places: neither can be trusted
    uniq, counts = np.unique(ids.index[ids.index >= 0], return_counts=True)
    twice = np.isin(ids.index, uniq[counts > 1])
    ids.reason[twice] = "identity read in two places"
    ids.index = np.where(twice, -1, ids.index)
    return ids

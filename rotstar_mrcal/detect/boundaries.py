"""Element boundaries: the border lattice and the elements it encloses (paper 3.2)

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.detect.boundaries import element_boundaries
    >>> mask = np.zeros((60, 90), np.uint8); mask[5:55, 5:85] = 1
    >>> mask[10:30, 10:30] = 0; mask[10:30, 35:55] = 0; mask[35:50, 60:80] = 0
    >>> el = element_boundaries(mask)
    >>> len(el.contours), el.touches_edge
    (3, False)

The binary response is traced with OpenCV's contour hierarchy. The longest
contour is the outer edge of the border lattice; its child contours (the holes
in the lattice) are the elements, one per corner. Holes much smaller than the
typical element (noise) are dropped.
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np


@dataclasses.dataclass
class Elements:
    contours: list  # one (M, 2) int array per element
    centroids: np.ndarray  # (N, 2) float
    areas: np.ndarray  # (N,)
    lattice: np.ndarray  # (M, 2) the outer contour of the border lattice
    touches_edge: bool  # the lattice reaches the image border

    @property
    def inscribed(self) -> np.ndarray:
        """(N,) half-side of the largest axis-aligned square about each centroid"""
        return np.array([inscribed_square(c, m) for c, m in zip(self.contours, self.centroids)])


def on_border(points: np.ndarray, shape) -> np.ndarray:
    """(M,) bool: which of the pixel points (M, 2) lie on the image's outermost rows or columns

        >>> on_border(np.array([[0, 5], [3, 4], [9, 2]]), (6, 10)).tolist()
        [True, False, True]
    """
    H, W = shape
    p = np.asarray(points)
    return (p[:, 0] <= 0) | (p[:, 1] <= 0) | (p[:, 0] >= W - 1) | (p[:, 1] >= H - 1)


def inscribed_square(contour: np.ndarray, centre: np.ndarray) -> float:
    """Half-side of the largest axis-aligned square centred at centre inside contour"""
    d = np.abs(np.asarray(contour, float) - centre)
    return float(np.min(np.max(d, axis=-1))) if len(d) else 0.0


def element_boundaries(mask: np.ndarray, min_area: float = 12.0, min_rel_area: float = 0.2) -> Elements:
    """Contours of the elements enclosed by the longest contour of the mask"""
    contours, hierarchy = cv2.findContours(mask, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
    if not contours:
        return Elements([], np.zeros((0, 2)), np.zeros(0), np.zeros((0, 2), int), False)
    hierarchy = hierarchy[0]
    lengths = np.array([len(c) for c in contours])
    # the lattice is the longest outer (parent-less) contour
    outer = np.flatnonzero(hierarchy[:, 3] < 0)
    ilat = outer[np.argmax(lengths[outer])]
    children = np.flatnonzero(hierarchy[:, 3] == ilat)
    cs = [contours[i][:, 0, :] for i in children]
    moments = [cv2.moments(c) for c in cs]
    areas = np.array([m["m00"] for m in moments])
    keep = areas >= min_area
    if keep.any():
        keep &= areas >= min_rel_area * np.median(areas[keep])
    cs = [c for c, k in zip(cs, keep) if k]
    moments = [m for m, k in zip(moments, keep) if k]
    centroids = np.array([(m["m10"] / m["m00"], m["m01"] / m["m00"]) for m in moments]).reshape(-1, 2)
    lattice = contours[ilat][:, 0, :]
    touches = bool(on_border(lattice, mask.shape).any())
    return Elements(cs, centroids, areas[keep], lattice, touches)

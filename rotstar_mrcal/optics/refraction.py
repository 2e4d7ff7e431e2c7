"""Cover glass over a screen's emitting layer: rays refracted at the glass surface (Snell's law)

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.optics.refraction import Glass, emitting_hits, apparent_points
    >>> glass = Glass(thickness_m=0.001, index=1.5)
    >>> c = np.array((0.0, 0.0, -0.3))                     # a camera 30 cm in front of the screen
    >>> d = np.array((0.3, 0.0, 0.3))                      # looking 45 degrees off the normal
    >>> p = emitting_hits(c, d, glass)                     # where that ray meets the emitting layer
    >>> round(float(p[0] - 0.3) * 1e3, 4)                  # mm nearer the camera than a straight ray
    -0.4655
    >>> a = apparent_points(c, np.array((*p, 0.0)), glass) # the inverse: where the camera sees that point
    >>> bool(abs(a[0] - 0.3) < 1e-12)
    True

Geometry (board frame: the emitting layer is the plane z = 0, the camera on
the -z side; the glass of thickness t fills -t <= z <= 0). A camera ray
meets the glass surface z = -t at E at the angle theta to the normal, bends
to theta_g with sin(theta) = n sin(theta_g), and meets the emitting layer at
P, t tan(theta_g) beyond E along the ray's in-plane direction. A straight
ray would have gone on t tan(theta) instead: the emitting point P is seen
where a flat board model puts the point A = P + t (tan(theta) - tan(theta_g))
(away from the camera). Equivalently, relative to a board lifted onto the
glass surface (a rigid shift along the normal, which a pose absorbs), every
point appears moved toward the camera by t tan(theta_g). The shift grows
with the viewing angle, so it changes across a tilted board and from pose to
pose: no rigid board and no one warp shared by all poses can absorb it.

emitting_hits traces rays forward (the simulator); apparent_points solves
the inverse (the calibration's correction): the camera centre and an
emitting point given, the in-plane angle in the glass is the root of
t tan(theta_g) + h tan(theta) = D (h the camera's height above the glass,
D the in-plane distance from the point to the camera's foot), found by
Newton's method from the right of the root (the function is increasing
and convex in tan(theta_g)).
"""

from __future__ import annotations

import dataclasses

import numpy as np

DEFAULT_INDEX = 1.5
"""Refractive index of display cover glass (soda-lime and aluminosilicate glass: 1.50-1.52)"""

NEWTON_STEPS = 40


@dataclasses.dataclass(frozen=True)
class Glass:
    """A plane-parallel cover glass over the emitting layer: thickness (metres) and refractive index"""

    thickness_m: float = 0.0
    index: float = DEFAULT_INDEX

    def __post_init__(self):
        if not (np.isfinite(self.thickness_m) and self.thickness_m >= 0):
            raise ValueError(f"glass thickness must be a finite number >= 0, not {self.thickness_m!r}")
        if not (np.isfinite(self.index) and self.index >= 1):
            raise ValueError(f"glass index must be a finite number >= 1, not {self.index!r}")

    @property
    def none(self) -> bool:
        """No glass: thickness 0 or index 1 (rays go straight)"""
        return self.thickness_m == 0 or self.index == 1

    @classmethod
    def mm(cls, thickness_mm: float, index: float = DEFAULT_INDEX) -> "Glass":
        return cls(float(thickness_mm) * 1e-3, float(index))


def emitting_hits(c: np.ndarray, d: np.ndarray, glass: Glass) -> np.ndarray:
    """(x, y) where rays from c (3,) along d (..., 3), board frame, metres, meet the emitting layer

    NaN where a ray misses the glass or runs away from it, or the camera is
    not in front of the glass (c_z < -t).

        >>> emitting_hits(np.array((0, 0, -1.0)), np.array((0, 0, 1.0)), Glass(0.002)).tolist()
        [0.0, 0.0]
    """
    t, n = glass.thickness_m, glass.index
    c = np.asarray(c, float)
    d = np.asarray(d, float)
    if not c[2] < -t:
        return np.full(d.shape[:-1] + (2,), np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = (-t - c[2]) / d[..., 2]
        lam = np.where(lam > 0, lam, np.nan)
        e = c[:2] + lam[..., None] * d[..., :2]  # on the glass surface
        dxy = d[..., :2]
        # t tan(theta_g) along the in-plane direction: sin(theta_g) = |d_xy| / (n |d|)
        k = t / np.sqrt(n * n * np.sum(d * d, axis=-1) - np.sum(dxy * dxy, axis=-1))
    return e + k[..., None] * dxy


def tan_in_glass(D: np.ndarray, h: np.ndarray, glass: Glass) -> np.ndarray:
    """tan(theta_g) of the ray from a camera h above the glass to an emitting point D away in the plane

    The root x of t x + h tan(theta(x)) = D, tan(theta) = n x / sqrt(1 + (1 - n^2) x^2).

        >>> x = tan_in_glass(np.array(0.3), np.array(0.299), Glass(0.001))
        >>> th_g = np.arctan(x); th = np.arcsin(1.5 * np.sin(th_g))
        >>> round(float(0.001 * np.tan(th_g) + 0.299 * np.tan(th)), 12)
        0.3
    """
    t, n = glass.thickness_m, glass.index
    D, h = np.broadcast_arrays(np.asarray(D, float), np.asarray(h, float))
    lim = 1 / np.sqrt(n * n - 1) if n > 1 else np.inf
    x = np.minimum(D / (t + h * n), 0.999999 * lim)  # the small-angle root: right of the true one
    for _ in range(NEWTON_STEPS):
        q = 1 + (1 - n * n) * x * x
        f = t * x + h * n * x / np.sqrt(q) - D
        x = np.maximum(x - f / (t + h * n * q ** -1.5), 0.0)
    return x


def apparent_points(c: np.ndarray, p: np.ndarray, glass: Glass) -> np.ndarray:
    """Where on its own plane a flat board model sees emitting points p (..., 3) from the camera at c

    c and p in the board frame (metres, glass normal z; the glass is on the
    camera's side); each point's glass surface is t in front of it (a warped
    board is flat locally). Returns (..., 3): p moved away from the camera's foot by
    t (tan(theta) - tan(theta_g)); NaN where the camera is not in front of
    the glass.
    """
    t = glass.thickness_m
    c = np.asarray(c, float)
    p = np.asarray(p, float)
    p = np.broadcast_to(p, np.broadcast_shapes(p.shape, c.shape))
    if glass.none:
        return p.copy()
    h = np.abs(p[..., 2] - c[..., 2]) - t  # whichever side of the board the camera is on
    v = c[..., :2] - p[..., :2]
    D = np.linalg.norm(v, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        x = tan_in_glass(D, np.where(h > 0, h, np.nan), glass)
        tan_air = (D - t * x) / h
        u = np.where(D[..., None] > 0, v / D[..., None], 0.0)
    a = p.copy()
    a[..., :2] -= (t * (tan_air - x))[..., None] * u
    return np.where((h > 0)[..., None], a, np.nan)

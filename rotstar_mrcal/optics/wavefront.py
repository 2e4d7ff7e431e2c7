"""Primary (Seidel) wavefront aberrations over a circular pupil

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.optics.wavefront import Seidel, wavefront
    >>> coma = Seidel(coma=4.0)                      # waves, the paper's example
    >>> float(wavefront(coma, np.array(1.0), np.array(0.0)))   # rho = 1, theta = 0
    4.0
    >>> coma.symmetric, Seidel(spherical=1, focus=-1, astigmatism=0.5).symmetric
    (False, True)

The wavefront error in waves at normalised pupil radius rho in [0, 1] and
pupil angle theta (Wyant and Creath, "Basic wavefront aberration theory",
1992, Table 1; the standard assignment of the Seidel terms):

    W = W_tilt rho cos(theta - a_tilt)
      + W_focus rho^2
      + W_sph rho^4
      + W_coma rho^3 cos(theta - a_coma)
      + W_ast rho^2 cos^2(theta - a_ast)

The paper's Eq. 2 prints the spherical and astigmatism coefficients swapped
(W_ast rho^4 and W_sph rho^2 cos^2 theta); the terms above are the standard
ones, the only reading under which its "spherical" PSF is rotationally
symmetric. The a_* are the directions of the odd and of the astigmatic terms
(radians, in the image: from +x toward +y, y down; see psf.py for how pupil
angle maps to image direction). In a real lens coma and astigmatism point
along the field radius, so a field-dependent PSF sets a_coma = a_ast = the
azimuth of the image point (psf.radial_psf).

W(rho, theta + pi) = W(rho, theta) for focus, spherical and astigmatism:
their pupil function is point-symmetric, hence so is their PSF. Tilt and coma
are odd in the pupil and break that symmetry (tilt only shifts the PSF).
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np

TERMS = ("tilt", "focus", "spherical", "coma", "astigmatism")


@dataclasses.dataclass(frozen=True)
class Seidel:
    """Seidel coefficients in waves and the directions of the oriented terms (radians)"""

    tilt: float = 0.0
    focus: float = 0.0
    spherical: float = 0.0
    coma: float = 0.0
    astigmatism: float = 0.0
    tilt_angle: float = 0.0
    coma_angle: float = 0.0
    astigmatism_angle: float = 0.0

    @property
    def symmetric(self) -> bool:
        """True if W(rho, theta + pi) = W(rho, theta): a point-symmetric PSF"""
        return self.tilt == 0 and self.coma == 0

    def rotated(self, angle: float) -> "Seidel":
        """The same aberration with every oriented term turned by `angle` radians"""
        return dataclasses.replace(
            self,
            tilt_angle=self.tilt_angle + angle,
            coma_angle=self.coma_angle + angle,
            astigmatism_angle=self.astigmatism_angle + angle,
        )

    def to_dict(self) -> dict:
        return {k: float(v) for k, v in dataclasses.asdict(self).items()}


def wavefront(seidel: Seidel, rho: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """W(rho, theta) in waves; broadcasts rho and theta"""
    s = seidel
    rho = np.asarray(rho, float)
    theta = np.asarray(theta, float)
    r2 = rho * rho
    return (
        s.tilt * rho * np.cos(theta - s.tilt_angle)
        + s.focus * r2
        + s.spherical * r2 * r2
        + s.coma * r2 * rho * np.cos(theta - s.coma_angle)
        + s.astigmatism * r2 * np.cos(theta - s.astigmatism_angle) ** 2
    )


def pupil_function(seidel: Seidel, n: int, radius: float) -> np.ndarray:
    """P exp(2 pi i W) on an n x n grid (n odd), pupil of `radius` samples, centred

    SYNOPSIS

        >>> U = pupil_function(Seidel(), 9, 3.0)
        >>> U.shape, int((abs(U) > 0).sum()), complex(U[4, 4])
        ((9, 9), 29, (1+0j))

    Sample [r, c] is the pupil point ((c - n//2) / radius, (r - n//2) / radius)
    in normalised units (x right, y down); the circular pupil P is 1 where
    rho <= 1, else 0. The grid is symmetric about its centre sample, so a
    point-symmetric W gives a pupil function that is exactly symmetric on the
    grid.
    """
    if n % 2 == 0:
        raise ValueError(f"the pupil grid needs an odd size (a centre sample), not {n}")
    flat, rho, theta = _pupil_disc(n, float(radius))
    U = np.zeros(n * n, complex)
    U[flat] = np.exp(2j * math.pi * wavefront(seidel, rho, theta))
    return U.reshape(n, n)


@functools.lru_cache(maxsize=16)
def _pupil_disc(n: int, radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(flat indices, rho, theta) of the n x n grid's samples inside the pupil (rho <= 1): only they are computed
    (a pupil of 27 samples' radius is 4 % of the 237 x 237 grid the PSF's sampling needs)"""
    t = (np.arange(n) - n // 2) / radius
    y, x = t[:, None], t[None, :]
    rho = np.hypot(x, y)
    theta = np.arctan2(y, x)
    flat = np.flatnonzero(rho <= 1.0)
    return flat, rho.ravel()[flat], theta.ravel()[flat]

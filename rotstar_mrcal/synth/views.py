"""The poses of the synthetic experiment (paper 4.1): a board tilted about its corner

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.synth.views import tilt_rotation, view_jacobian
    >>> R = tilt_rotation(np.radians(60), 0.0)          # tilt 60 deg about the board x axis
    >>> (R @ [0, 0, 1]).round(3)                          # the board normal leans toward -y
    array([ 0.   , -0.866,  0.5  ])
    >>> view_jacobian(np.radians(60), 0.0).round(3)      # board y foreshortened by cos 60
    array([[1. , 0. ],
           [0. , 0.5]])

The camera is fixed; the world origin is the measured corner of the board.
At the initial pose the board faces the camera, its axes along the camera's
(x right, y down, z into the scene). The paper describes each pose as "a
rotation by phi about the world Z axis, then by alpha about X", which taken
literally turns the board edge-on at alpha = 90 degrees and makes phi an
in-plane roll. We implement the reading the issue adopts: a tilt by phi
about an in-plane axis whose direction is alpha,

    R(phi, alpha) = Rodrigues(phi * (cos alpha, sin alpha, 0)),

phi in {10, ..., 60} degrees, alpha in {0, 15, ..., 165} degrees. For one
phi, the 12 alphas show the same physical corner foreshortened by cos phi in
12 directions; the camera does not move and the corner does not move, so
every detection of it should land on the same image point.

The corner is at distance Z on the ray of normalised image point
field = (x_n, y_n) (default: the optical axis). Projection is a pinhole
(the experiment measures refinement, not a lens model); the image of the
board near the corner is then exactly a star (patterns.Star.mapped) through
the corner's image with edge directions J u, where J, the Jacobian of
board -> image at the corner, is up to a positive scale

    J ~ R[:2, :2] - field R[2, :2]          (rows of R restricted to board x, y).

The scale does not matter for infinite wedges, so view_jacobian returns J
divided by f / Z.
"""

from __future__ import annotations

import numpy as np

PHIS_DEG = (10, 20, 30, 40, 50, 60)
ALPHAS_DEG = tuple(range(0, 180, 15))


def tilt_rotation(phi, alpha) -> np.ndarray:
    """Rotation by phi about the in-plane axis (cos alpha, sin alpha, 0); broadcasts to (..., 3, 3)"""
    phi = np.asarray(phi, float)
    alpha = np.asarray(alpha, float)
    phi, alpha = np.broadcast_arrays(phi, alpha)
    a = np.stack((np.cos(alpha), np.sin(alpha), np.zeros_like(alpha)), axis=-1)
    K = np.zeros(phi.shape + (3, 3))
    K[..., 0, 2], K[..., 1, 2] = a[..., 1], -a[..., 0]
    K[..., 2, 0], K[..., 2, 1] = -a[..., 1], a[..., 0]
    c, s = np.cos(phi)[..., None, None], np.sin(phi)[..., None, None]
    return c * np.eye(3) + s * K + (1 - c) * a[..., :, None] * a[..., None, :]


def view_jacobian(phi, alpha, field=(0.0, 0.0)) -> np.ndarray:
    """(..., 2, 2) Jacobian of board (x, y) -> image at the corner, in units of f / Z"""
    R = tilt_rotation(phi, alpha)
    f = np.asarray(field, float)
    return R[..., :2, :2] - f[:, None] * R[..., 2:3, :2]

"""mrcal's projection uncertainty of a calibration, on a grid over the imager

SYNOPSIS

    import mrcal
    from rotstar_mrcal.evaluate.uncertainty import imager_grid, projection_uncertainty
    model = mrcal.cameramodel("cal/camera-0.cameramodel")   # with optimization_inputs
    q = imager_grid(model.imagersize(), 40)                  # (25, 40, 2) pixels
    sigma = projection_uncertainty(model, q)                 # (25, 40) px, 1-sigma

    >>> imager_grid((1280, 800), 4)[0, :, 0]
    array([   0.        ,  426.33333333,  852.66666667, 1279.        ])

What it is: mrcal propagates the noise of the calibration's own corner
observations (sigma estimated from its residuals) through the solve to the
projection of a point seen at pixel q: how far, 1-sigma, a recalibration from
equally noisy corners of the same poses would move that projection. By
default the worst direction of the 2x2 covariance (what
mrcal-show-projection-uncertainty plots), for a point at infinity.

It is small where boards were seen and grows where they were not. It covers
noise only: a lens model that cannot represent the lens, or corners biased
in a consistent way, are invisible to it (the cross-validation diff is what
catches those).
"""

from __future__ import annotations

import mrcal
import numpy as np


def imager_grid(imagersize, gridn_width: int = 40, gridn_height: int | None = None) -> np.ndarray:
    """(gridn_height, gridn_width, 2) pixel coordinates spanning the imager (mrcal.sample_imager)"""
    W, H = (int(v) for v in imagersize)
    return mrcal.sample_imager(gridn_width, gridn_height, W, H)


def projection_uncertainty(model: mrcal.cameramodel, q, distance: float | None = None,
                           what: str = "worstdirection-stdev") -> np.ndarray:
    """1-sigma projection uncertainty (px) of the points seen at pixels q (..., 2)

    distance None: points at infinity; otherwise at that range (metres)
    along each pixel's ray. what: 'worstdirection-stdev' or 'rms-stdev'
    (mrcal.projection_uncertainty's names).
    """
    v = mrcal.unproject(np.asarray(q, float), *model.intrinsics(), normalize=True)
    return uncertainty_of_points(model, v, distance, what)


def uncertainty_of_points(model: mrcal.cameramodel, v, distance: float | None = None,
                          what: str = "worstdirection-stdev") -> np.ndarray:
    """1-sigma projection uncertainty (px) of camera-frame directions v (..., 3)"""
    v = np.asarray(v, float)
    if distance is None:
        return mrcal.projection_uncertainty(v, model=model, atinfinity=True, what=what)
    p = v / np.linalg.norm(v, axis=-1, keepdims=True) * distance
    return mrcal.projection_uncertainty(p, model=model, what=what)

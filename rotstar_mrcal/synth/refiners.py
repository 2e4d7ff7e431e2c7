"""The three corner refiners of the experiment, on a mosaic of noisy tiles

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.synth.refiners import REFINERS, refine
    >>> sorted(REFINERS)                      # the registry, rotstar_mrcal.methods
    ['opencv', 'saddle', 'symmetric']
    >>> y, x = np.mgrid[0:30, 0:60].astype(float)
    >>> u = np.where(x < 30, x - 14.3, x - 44.3)            # two tiles, corner at (14.3, 15.6) in each
    >>> frames = (128 + 100 * np.tanh(u) * np.tanh(y - 15.6))[None]
    >>> starts = np.array(((15.0, 15.0), (44.0, 16.0)))
    >>> np.round(refine("symmetric", frames, starts, window=6), 2)
    array([[14.3, 15.6],
           [44.3, 15.6]])

Every refiner takes frames (K, H, W) and starts (N, 2) and returns (N, 2)
corners, NaN where it failed (mrcal's pixel convention, as the wrapped
functions):

- opencv: cv2.cornerSubPix (Forstner), detect.baselines.opencv_subpix, half
  window `window`;
- saddle: the Lucchese-Mitra quadratic saddle fit,
  detect.baselines.saddle_refine, half window `window`, no cone pre-filter
  (the images are already smooth: the optics blur them);
- symmetric: the paper's Eq. 1, detect.refine.symmetric_refine, on all K
  frames jointly, half window `window`.

With several frames (the rotating star) OpenCV and the saddle fit, which see
one image at a time, refine every frame from the same start and return the
mean of the K results; a corner that fails in any frame fails. The symmetric
refinement is the only one that uses the frames jointly, as the paper's
Eq. 1 does.
"""

from __future__ import annotations

import numpy as np

from ..methods import REFINERS, refiner


def refine(name: str, frames: np.ndarray, starts: np.ndarray, window: int = 10) -> np.ndarray:
    """Refine starts (N, 2) on frames (K, H, W) with refiner `name`; (N, 2), NaN = failed"""
    return refiner(name).refine(frames, starts, window)


__all__ = ["REFINERS", "refine"]

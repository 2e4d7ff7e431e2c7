"""The corner refiners of the experiment, on a mosaic of noisy tiles; which applies to which pattern

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.synth.refiners import REFINERS, applies, refine
    >>> sorted(REFINERS)                      # the registry rotstar_mrcal.peers.registry, and phase
    ['opencv', 'phase', 'saddle', 'symmetric']
    >>> applies("rotstar", "saddle"), applies("phase", "saddle"), applies("phase", "phase")
    (True, False, True)
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
  frames jointly, half window `window`;
- phase: the phase-shift corner (detect.phase.phase_corners, the finder of
  real sequences): the 8 frames are the 4 steps along x then along y, the
  corner is where both local phase planes take the corner's phase 0. It
  fits its planes in the paper's half-window of 3 px (detect.phase.
  HALF_WINDOW: "a fixed neighborhood with a half-window size of 3 pixels"
  gave the paper its best phase results), whatever `window` the others use.
  The experiment has no saturation (it isolates the PSF), so clipped
  samples are kept, not rejected.

With several frames (the rotating star) OpenCV and the saddle fit, which see
one image at a time, refine every frame from the same start and return the
mean of the K results; a corner that fails in any frame fails. The symmetric
refinement is the only one of these three that uses the frames jointly, as
the paper's Eq. 1 does.

Which refiner applies to which pattern (applies): the wedge refiners
(opencv, saddle, symmetric) need edges meeting at the corner, which fringes
do not have; the phase refiner needs fringes, which wedges are not. The
experiment runs only the pairs that apply; the others are "n/a" in its
tables. The phase refiner is not in rotstar_mrcal.peers.registry.REFINERS (whose
refiners rotstar-detect --refine runs on the rotating-star or the
checkerboard frames); on real sequences the same finder is the "phase"
method of METHODS.
"""

from __future__ import annotations

import numpy as np

from rotstar_mrcal.peers.registry import REFINERS as WEDGE_REFINERS, refiner
from rotstar_mrcal.peers.phase import phase_corners

PHASE = "phase"
REFINERS = tuple(n for n, r in WEDGE_REFINERS.items() if r.correct is None) + (PHASE,)
"""The experiment's refiners: the registry's, but those that correct a whole pose's corners afterwards (psf: it
reads the PSF from the edges of a pose, which the experiment's tiles are not), and phase"""
FULL_SCALE = 255.0  # DN of the experiment's images (black 28, white 228): the phase finder's modulation scale


def applies(pattern: str, refiner_name: str) -> bool:
    """True if refiner `refiner_name` can refine the corner of `pattern` (phase with phase, wedges with stars)"""
    return (pattern == "phase") == (refiner_name == PHASE)


def refine_phase(frames: np.ndarray, starts: np.ndarray, window=None) -> np.ndarray:
    """detect.phase.phase_corners on 8 frames (x steps 0..3, y steps 0..3), corner phase 0; (N, 2)

    SYNOPSIS

        >>> import numpy as np
        >>> from rotstar_mrcal.synth.patterns import phase_frames
        >>> y, x = np.mgrid[0:20, 0:20].astype(float)
        >>> frames = np.stack([28 + 200 * f.value_at(x - 9.3, y - 10.6) for f in phase_frames(12.0)])
        >>> np.round(refine_phase(frames, [[9.0, 11.0]]), 6).tolist()
        [[9.3, 10.6]]

    `window` is ignored: the planes are fitted in detect.phase.HALF_WINDOW.
    """
    f = np.asarray(frames, float)
    if f.ndim != 3 or f.shape[0] != 8:
        raise ValueError(f"the phase refiner needs 8 frames (4 steps along x, then y), not {f.shape}")
    starts = np.asarray(starts, float).reshape(-1, 2)
    r = phase_corners(f.reshape(2, 4, *f.shape[1:]), starts, np.zeros_like(starts), FULL_SCALE,
                      saturation="keep")
    return r.corners


def refine(name: str, frames: np.ndarray, starts: np.ndarray, window: int = 10) -> np.ndarray:
    """Refine starts (N, 2) on frames (K, H, W) with refiner `name`; (N, 2), NaN = failed"""
    if name == PHASE:
        return refine_phase(frames, starts, window)
    return refiner(name).refine(frames, starts, window)


__all__ = ["REFINERS", "PHASE", "applies", "refine", "refine_phase"]

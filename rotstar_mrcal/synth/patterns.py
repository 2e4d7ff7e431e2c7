"""The four patterns of the synthetic experiment: stars of wedges around one corner, and fringes

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.synth.patterns import pattern_frames, PATTERNS
    >>> PATTERNS
    ('checkerboard', 'rotstar', 'star16', 'phase')
    >>> [len(pattern_frames(p)) for p in PATTERNS]            # distinct frames
    [1, 8, 1, 8]
    >>> f = pattern_frames("rotstar")[1]
    >>> np.degrees(f.edges[:2]).round(2).tolist(), f.colours.tolist()
    ([11.25, 101.25], [0.0, 1.0, 0.0, 1.0])
    >>> f = pattern_frames("phase")[5]                         # fringes along y, step 1
    >>> np.round(f.k, 4).tolist(), round(float(f.shift / (np.pi / 2)), 6)
    ([0.0, 0.3142], 1.0)

Around the corner that the experiment measures, every pattern is a *star*:
n wedges (angular sectors) with a common apex at the corner, alternately
black (0) and white (1). Wedge i runs from edges[i] to edges[i + 1]
(counter-clockwise in board coordinates, x right, y down, angles from x
toward y), edges ascending in [edges[0], edges[0] + 2 pi).

- checkerboard: 4 wedges, edges at 0, 90, 180, 270 degrees; the wedge
  0..90 (x > 0, y > 0) is black, as in pattern.render.checker_coverage at
  theta = 0 and frame 0 of the rotating star;
- rotstar: 8 frames, the checkerboard corner turned by k pi/16 (the layout's
  step), frame 0 aligned with the checkerboard;
- star16: Schops et al.'s 16-segment star, edges every 22.5 degrees.

Only the corner's neighbourhood is modelled: the wedges are infinite, i.e.
the squares (elements) are larger than the refinement window plus the PSF
at every pose, so no neighbouring corner or element border enters the
window. A projective map sends lines through the corner to lines through its
image, so the image of a star is again a star with its apex at the image of
the corner: `Star.mapped(J)` with J the 2x2 Jacobian of board -> image at
the corner is exact, not a local approximation.

- phase: the paper's 4-step phase shifts (section 4.2, after Xu et al.'s
  local phase planes): 8 frames, 0.5 + 0.5 cos(phi + n pi / 2), n = 0..3,
  with phi = 2 pi x / PHASE_PERIOD (fringes along x), then the same along y
  (phi = 2 pi y / PHASE_PERIOD); phi = 0 at the corner along both axes, as
  the real pattern puts phase 0 on the grid corners (pattern.layout
  phase_zero, pattern.render.phase_profile; detect.phase reads the corner
  where both phases vanish). A `Fringe` is one such frame.

The real pattern's period is one element (rotstar-pattern --paper-sequence:
phase_period = pitch); here the elements are only known to be larger than
the refiners' 21 x 21 px window, so PHASE_PERIOD = 20 board units, where a
board unit is one camera pixel at the head-on view (views.view_jacobian is
the identity at phi = 0): the window holds one period head-on and up to two
at phi = 60 degrees (the period shrinks to 10 px across the tilt axis). The
phase refiner fits its planes in the paper's 7 x 7 px (detect.phase), which
then spans 0.3 to 0.7 of a period.

Fringes are not scale-free and a projective map does not keep a sinusoid's
period constant: the true image of the fringes is a sinusoid of a
projective function of the image point. `Fringe.mapped(J)` uses the Jacobian
at the corner, the first-order (affine) approximation, under which the
fringes are exactly planar in phase (wavevector J^-T k). Over the phase
refiner's 7 x 7 px window the neglected curvature of the phase is of order
(window / distance to the camera) times the phase change across it, far
below anything the experiment resolves; the approximation makes the
phase-plane fit exact without blur, so that what moves its corner is the
PSF and the noise, which is what the experiment varies.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

PATTERNS = ("checkerboard", "rotstar", "star16", "phase")

ROTSTAR_FRAMES = 8
ROTSTAR_STEP = math.pi / 16
PHASE_PERIOD = 20.0  # board units = camera pixels at the head-on view
PHASE_STEPS = 4


@dataclasses.dataclass(frozen=True)
class Star:
    """Wedges around an apex: edge angles (n,) ascending over one turn, wedge colours (n,)"""

    edges: np.ndarray
    colours: np.ndarray

    def mapped(self, J) -> "Star":
        """The star seen through a linear map J (2x2, det > 0): edge directions J u

        SYNOPSIS

            >>> s = Star.regular(4).mapped([[1.0, 0.0], [0.0, 0.5]])   # squashed in y
            >>> np.degrees(s.edges).round(3).tolist()
            [0.0, 90.0, 180.0, 270.0]
            >>> np.degrees(Star.regular(4, 0.25 * np.pi).mapped([[1, 0], [0, 0.5]]).edges).round(2).tolist()
            [26.57, 153.43, 206.57, 333.43]
        """
        J = np.asarray(J, float)
        if not np.linalg.det(J) > 0:
            raise ValueError("the map must keep the orientation (the board seen from the front)")
        d = np.stack((np.cos(self.edges), np.sin(self.edges)))
        img = J @ d
        a = np.arctan2(img[1], img[0])
        a = a[0] + np.mod(a - a[0], 2 * math.pi)  # ascending from the first edge
        return Star(a, self.colours)

    @staticmethod
    def regular(n: int, theta: float = 0.0, first: float = 0.0) -> "Star":
        """n equal wedges, first edge at theta, the first wedge of colour `first`"""
        if n < 2 or n % 2:
            raise ValueError(f"a star needs an even number of wedges, not {n}")
        edges = theta + 2 * math.pi * np.arange(n) / n
        colours = np.where(np.arange(n) % 2 == 0, first, 1.0 - first)
        return Star(edges, colours.astype(float))

    def colour_at(self, angle: np.ndarray) -> np.ndarray:
        """Colour of the wedge holding direction `angle` (radians, any range)"""
        a = np.mod(np.asarray(angle, float) - self.edges[0], 2 * math.pi) + self.edges[0]
        i = np.searchsorted(self.edges, a, side="right") - 1
        return self.colours[np.clip(i, 0, len(self.edges) - 1)]


@dataclasses.dataclass(frozen=True)
class Fringe:
    """One phase-shift frame 0.5 + 0.5 cos(k . d + shift), d the offset from the corner

    k: (2,) wavevector, radians per unit; shift: the step's phase shift (radians).
    """

    k: np.ndarray
    shift: float

    def mapped(self, J) -> "Fringe":
        """The fringe seen through a linear map J (2x2, det > 0): wavevector J^-T k

        SYNOPSIS

            >>> f = Fringe(np.array((2 * np.pi / 20, 0.0)), 0.0).mapped([[0.5, 0.0], [0.0, 1.0]])
            >>> round(float(2 * np.pi / f.k[0]), 6)      # foreshortened along x: period 10
            10.0

        The value at image offset J d equals the value at board offset d:
        k . d = (J^-T k) . (J d). Exact for a linear map; for the board's
        projective image it is the first-order approximation at the corner
        (see the module doc).
        """
        J = np.asarray(J, float)
        if not np.linalg.det(J) > 0:
            raise ValueError("the map must keep the orientation (the board seen from the front)")
        return Fringe(np.linalg.solve(J.T, np.asarray(self.k, float)), self.shift)

    def value_at(self, dx, dy) -> np.ndarray:
        """The fringe at offsets (dx, dy) from the corner, in [0, 1]"""
        return 0.5 + 0.5 * np.cos(self.k[0] * np.asarray(dx, float) + self.k[1] * np.asarray(dy, float) + self.shift)


def phase_frames(period: float = PHASE_PERIOD) -> list[Fringe]:
    """The 8 phase-shift frames: 4 steps along x, then 4 along y, phase 0 at the corner

    SYNOPSIS

        >>> from rotstar_mrcal.peers.phase import wrapped_phase
        >>> f = phase_frames(20.0)
        >>> x = np.array([[0.0, 5.0, -2.5]])                   # offsets along x (y = 0)
        >>> phi, _ = wrapped_phase(np.stack([g.value_at(x, 0 * x) for g in f[:4]]))
        >>> (np.round(phi / (2 * np.pi) * 20, 9) + 0.0).tolist()    # the phase, in board units
        [[0.0, 5.0, -2.5]]
    """
    if not period > 0:
        raise ValueError(f"the fringe period must be positive, not {period}")
    w = 2 * math.pi / float(period)
    return [Fringe(np.array(k), n * 2 * math.pi / PHASE_STEPS)
            for k in ((w, 0.0), (0.0, w)) for n in range(PHASE_STEPS)]


def pattern_frames(name: str, phase_period: float = PHASE_PERIOD) -> list:
    """The distinct frames of a pattern (before captures are repeated and averaged): Stars, or Fringes for phase"""
    if name == "phase":
        return phase_frames(phase_period)
    if name == "checkerboard":
        return [Star.regular(4)]
    if name == "rotstar":
        return [Star.regular(4, k * ROTSTAR_STEP) for k in range(ROTSTAR_FRAMES)]
    if name == "star16":
        return [Star.regular(16)]
    raise ValueError(f"unknown pattern {name!r}; known: {', '.join(PATTERNS)}")

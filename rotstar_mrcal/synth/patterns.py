"""The three patterns of the synthetic experiment, as wedges around one corner

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.synth.patterns import pattern_frames, PATTERNS
    >>> PATTERNS
    ('checkerboard', 'rotstar', 'star16')
    >>> [len(pattern_frames(p)) for p in PATTERNS]            # distinct frames
    [1, 8, 1]
    >>> f = pattern_frames("rotstar")[1]
    >>> np.degrees(f.edges[:2]).round(2).tolist(), f.colours.tolist()
    ([11.25, 101.25], [0.0, 1.0, 0.0, 1.0])

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
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

PATTERNS = ("checkerboard", "rotstar", "star16")

ROTSTAR_FRAMES = 8
ROTSTAR_STEP = math.pi / 16


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


def pattern_frames(name: str) -> list[Star]:
    """The distinct frames of a pattern (before captures are repeated and averaged)"""
    if name == "checkerboard":
        return [Star.regular(4)]
    if name == "rotstar":
        return [Star.regular(4, k * ROTSTAR_STEP) for k in range(ROTSTAR_FRAMES)]
    if name == "star16":
        return [Star.regular(16)]
    raise ValueError(f"unknown pattern {name!r}; known: {', '.join(PATTERNS)}")

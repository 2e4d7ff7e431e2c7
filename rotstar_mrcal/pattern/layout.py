"""Geometry of the rotating-star display sequence and the pattern.json contract

SYNOPSIS

    >>> from rotstar_mrcal.pattern.layout import make_layout
    >>> layout = make_layout(screen=(2360, 1640), pixel_pitch_m=0.0254/264)
    >>> layout.nx, layout.ny, layout.pitch, layout.origin
    (14, 9, 150, (205, 220))
    >>> layout.corner_screen_xy()[0, 1]          # corner (i=1, j=0), display pixels
    array([355., 220.])

Coordinates on the screen are display pixels: pixel (u, v) covers [u, u+1) x
[v, v+1), x right, y down. Corner (i, j) sits at origin + pitch*(i, j), on a
pixel boundary, and is the mrcal board point (i, j, 0) * pitch * pixel_pitch_m.

Each corner is the centre of one *element*: a square of side pitch - band
holding a checkerboard corner (two lines through the centre) turned by
k*step in frame k. Elements are separated by the *border band*, a lattice of
width band that is white in even frames and black in odd frames. The band
lattice also closes around the outside of the grid. Outside it the screen is
a constant grey.

Orientation marker: one element has its checker colours inverted. An inverted
checker corner is still point-symmetric about its centre, so the marker does
not disturb that corner; it is placed where no symmetry of the grid (flips,
the 180-degree turn and, for a square grid, the transposes) maps it onto
itself, so that the detected marker fixes the labelling uniquely.
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np

PATTERN_FORMAT = "rotstar-pattern/1"


@dataclasses.dataclass(frozen=True)
class Layout:
    """The rotating-star pattern on one screen (all lengths in display pixels)"""

    screen_width: int
    screen_height: int
    pixel_pitch_m: float
    nx: int
    ny: int
    pitch: int
    band: int
    origin: tuple[int, int]
    nframes: int = 8
    step: float = math.pi / 16
    marker: tuple[int, int] = (0, 0)
    background: float = 0.5

    # ---- derived geometry -------------------------------------------------
    @property
    def half_element(self) -> int:
        """Half the side of an element's checker square"""
        return (self.pitch - self.band) // 2

    @property
    def spacing_m(self) -> float:
        """Board corner spacing in metres (mrcal's --object-spacing)"""
        return self.pitch * self.pixel_pitch_m

    def angle(self, k: int) -> float:
        """Rotation of frame k, radians, from screen x toward screen y"""
        return k * self.step

    def band_white(self, k: int) -> bool:
        return k % 2 == 0

    def corner_screen_xy(self) -> np.ndarray:
        """(ny, nx, 2) display-pixel positions of the corners, mrcal order"""
        j, i = np.mgrid[0 : self.ny, 0 : self.nx]
        return np.stack(
            (self.origin[0] + self.pitch * i, self.origin[1] + self.pitch * j), axis=-1
        ).astype(float)

    def board_points(self) -> np.ndarray:
        """(ny, nx, 3) mrcal board points in metres; record j*nx+i is (i, j)"""
        j, i = np.mgrid[0 : self.ny, 0 : self.nx]
        return np.stack((i, j, np.zeros_like(i)), axis=-1) * self.spacing_m

    def board_extent(self) -> tuple[int, int, int, int]:
        """(x0, y0, x1, y1): the outer edge of the band lattice, display pixels"""
        r = self.pitch // 2 + self.band // 2
        ox, oy = self.origin
        return (
            ox - r,
            oy - r,
            ox + (self.nx - 1) * self.pitch + r,
            oy + (self.ny - 1) * self.pitch + r,
        )

    def checkerboard_extent(self) -> tuple[int, int, int, int]:
        """(x0, y0, x1, y1) of the baseline checkerboard's (nx+1) x (ny+1) squares"""
        ox, oy = self.origin
        return (
            ox - self.pitch,
            oy - self.pitch,
            ox + self.nx * self.pitch,
            oy + self.ny * self.pitch,
        )

    def mrcal_object_args(self) -> list[str]:
        return [
            "--object-spacing", f"{self.spacing_m:.9g}",
            "--object-width-n", str(self.nx),
            "--object-height-n", str(self.ny),
        ]

    # ---- pattern.json -----------------------------------------------------
    def frames(self) -> list[dict]:
        """The display sequence: nframes rotating-star frames, then the checkerboard"""
        out = [
            {
                "file": f"rotstar_{k:02d}.png",
                "kind": "rotstar",
                "index": k,
                "angle_rad": self.angle(k),
                "angle_deg": math.degrees(self.angle(k)),
                "band": "white" if self.band_white(k) else "black",
            }
            for k in range(self.nframes)
        ]
        out.append({"file": "checkerboard.png", "kind": "checkerboard"})
        return out

    def to_dict(self) -> dict:
        return {
            "format": PATTERN_FORMAT,
            "screen": {
                "width": self.screen_width,
                "height": self.screen_height,
                "pixel_pitch_m": self.pixel_pitch_m,
            },
            "grid": {
                "nx": self.nx,
                "ny": self.ny,
                "pitch": self.pitch,
                "origin": list(self.origin),
                "spacing_m": self.spacing_m,
            },
            "element": {
                "band": self.band,
                "half_size": self.half_element,
                "step_rad": self.step,
                "marker": list(self.marker),
                "marker_meaning": "element (i, j) whose checker colours are inverted",
                "background": self.background,
            },
            "coordinates": "display pixel (u, v) covers [u, u+1) x [v, v+1), x right, y down; "
            "corner (i, j) at origin + pitch*(i, j) is mrcal board point "
            "(i, j, 0) * pitch * pixel_pitch_m",
            "mrcal": {
                "object_spacing": self.spacing_m,
                "object_width_n": self.nx,
                "object_height_n": self.ny,
            },
            "frames": self.frames(),
        }

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2) + "\n"


def marker_orbit(m: tuple[int, int], nx: int, ny: int) -> set[tuple[int, int]]:
    """The images of element m under the symmetries of an nx x ny grid"""
    i, j = m
    I, J = nx - 1 - i, ny - 1 - j
    orbit = {(i, j), (I, j), (i, J), (I, J)}
    if nx == ny:
        orbit |= {(j, i), (J, i), (j, I), (J, I)}
    return orbit


def choose_marker(nx: int, ny: int) -> tuple[int, int]:
    """The element nearest the centre, a little up and left, with a full orbit

    SYNOPSIS

        >>> choose_marker(14, 9), choose_marker(9, 9)
        ((5, 3), (3, 2))
    """
    full = 8 if nx == ny else 4
    target = np.array(((nx - 1) / 2 - 1.0, (ny - 1) / 2 - 1.4))
    cands = [
        (i, j)
        for j in range(1, ny - 1)
        for i in range(1, nx - 1)
        if len(marker_orbit((i, j), nx, ny)) == full
    ]
    if not cands:
        raise ValueError(f"a {nx}x{ny} grid has no element that can carry the marker")
    return min(cands, key=lambda c: (np.hypot(*(np.array(c) - target)), c))


def make_layout(
    screen: tuple[int, int] = (2360, 1640),
    pixel_pitch_m: float = 0.0254 / 264,
    pitch: int = 150,
    band: int = 40,
    nframes: int = 8,
    step: float = math.pi / 16,
    quiet: int = 50,
    nx: int | None = None,
    ny: int | None = None,
) -> Layout:
    """Fit the largest grid of the given pitch on the screen

    The baseline checkerboard has (nx+1) x (ny+1) squares of side pitch and
    needs a quiet zone of at least `quiet` display pixels on each side; nx and
    ny default to the most that fit. The grid is centred on the screen.
    """
    W, H = screen
    if pitch % 2 or band % 2:
        raise ValueError("pitch and band must be even, so that corners and element edges fall on pixel boundaries")
    if not 0 < band < pitch // 2:
        raise ValueError(f"band {band} must be between 0 and pitch/2 = {pitch // 2}")
    fit_x = (W - 2 * quiet) // pitch - 1
    fit_y = (H - 2 * quiet) // pitch - 1
    nx = fit_x if nx is None else nx
    ny = fit_y if ny is None else ny
    if nx < 3 or ny < 3:
        raise ValueError(f"only {fit_x}x{fit_y} corners fit on a {W}x{H} screen at pitch {pitch}; need at least 3x3")
    if nx > fit_x or ny > fit_y:
        raise ValueError(f"{nx}x{ny} corners at pitch {pitch} do not fit on a {W}x{H} screen (at most {fit_x}x{fit_y})")
    origin = ((W - (nx - 1) * pitch) // 2, (H - (ny - 1) * pitch) // 2)
    return Layout(
        screen_width=W,
        screen_height=H,
        pixel_pitch_m=pixel_pitch_m,
        nx=nx,
        ny=ny,
        pitch=pitch,
        band=band,
        origin=origin,
        nframes=nframes,
        step=step,
        marker=choose_marker(nx, ny),
    )


def layout_from_dict(d: dict) -> Layout:
    """Read a pattern.json dictionary; raises ValueError naming what is wrong"""
    try:
        screen, grid = d["screen"], d["grid"]
        element = d.get("element", {})
        nframes = sum(1 for f in d["frames"] if f["kind"] == "rotstar")
        return Layout(
            screen_width=int(screen["width"]),
            screen_height=int(screen["height"]),
            pixel_pitch_m=float(screen["pixel_pitch_m"]),
            nx=int(grid["nx"]),
            ny=int(grid["ny"]),
            pitch=int(grid["pitch"]),
            band=int(element.get("band", 0)),
            origin=(int(grid["origin"][0]), int(grid["origin"][1])),
            nframes=nframes,
            step=float(element.get("step_rad", math.pi / 16)),
            marker=tuple(int(v) for v in element.get("marker", (0, 0))),
            background=float(element.get("background", 0.5)),
        )
    except (KeyError, TypeError, IndexError, ValueError) as e:
        raise ValueError(f"not a rotstar pattern description ({type(e).__name__}: {e})") from None

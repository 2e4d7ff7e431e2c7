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
PHASE_STEPS = 4  # the phase-shift frames per axis, shifted by 2 pi / PHASE_STEPS


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
    identity: bool = False  # identity frames after the rotating-star frames (pattern/identity.py)
    phase_period: float = 0.0  # 4-step phase-shift fringes along x and y, period in display pixels (0: none)
    phase_origin: tuple[float, float] | None = None  # display point of phase 0 (None: corner (0, 0))
    star_segments: int = 0  # Schops et al.'s star per corner after the checkerboard, segments (0: none)

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
    @property
    def identity_code(self):
        """The IdentityCode of this grid, or None without identity frames"""
        from rotstar_mrcal.pattern.identity import IdentityCode

        return IdentityCode.for_grid(self.nx, self.ny) if self.identity else None

    @property
    def phase(self) -> bool:
        """Whether the sequence holds the phase-shift frames"""
        return self.phase_period > 0

    @property
    def phase_zero(self) -> tuple[float, float]:
        """The display point (x, y) where both fringes have phase 0"""
        return tuple(float(v) for v in (self.origin if self.phase_origin is None else self.phase_origin))

    def corner_phase(self) -> np.ndarray:
        """(ny, nx, 2) the phases (along x, along y) of the fringes at the corners, radians in [0, 2 pi)

        SYNOPSIS

            >>> L = make_layout(screen=(800, 600), pitch=100, band=24, phase_period=40)
            >>> L.corner_phase()[0, :3, 0].round(4).tolist()      # corners 100 px apart, period 40
            [0.0, 3.1416, 0.0]
        """
        d = self.corner_screen_xy() - np.array(self.phase_zero)
        return np.mod(2 * math.pi * d / self.phase_period, 2 * math.pi)

    def frames(self) -> list[dict]:
        """The display sequence, in the paper's order: the rotating-star frames, the identity frames,
        the phase shifts along x then y, the checkerboard, the star"""
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
        code = self.identity_code
        for b in range(code.nframes if code else 0):
            out.append({
                "file": f"identity_{b:02d}.png",
                "kind": "identity",
                "index": b,
                "encodes": f"bit {b} of every element's codeword (identity.codewords): the element's square "
                           "white for 1, black for 0; border bands black",
            })
        if self.phase:
            for axis in "xy":
                for n in range(PHASE_STEPS):
                    out.append({
                        "file": f"phase_{axis}_{n}.png",
                        "kind": "phase",
                        "axis": axis,
                        "step": n,
                        "shift_rad": n * 2 * math.pi / PHASE_STEPS,
                        "period_px": self.phase_period,
                        "phase_origin": list(self.phase_zero),
                        "encodes": f"linear luminance 0.5 + 0.5 cos(2 pi ({axis} - phase_origin.{axis}) / period_px "
                                   f"+ shift_rad) at display pixel centres {axis}, inside the board's outline "
                                   "(background outside)",
                    })
        out.append({"file": "checkerboard.png", "kind": "checkerboard"})
        if self.star_segments:
            out.append({
                "file": "star.png",
                "kind": "star",
                "segments": self.star_segments,
                "cell_px": self.pitch,
                "first_edge_rad": 0.0,
                "encodes": "every corner the centre of a star of `segments` black/white wedges filling the "
                           "pitch x pitch cell around it; wedge 0 (from the first edge toward +y) black at "
                           "corners with i + j even, colours inverted where i + j is odd",
            })
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
            **({"identity": self.identity_code.describe()} if self.identity else {}),
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
    identity: bool = True,
    phase_period: float = 0.0,
    star_segments: int = 0,
) -> Layout:
    """Fit the largest grid of the given pitch on the screen

    identity: show the identity frames (each element's index in time) after
    the rotating-star frames. phase_period > 0 adds the 4-step phase shifts
    along x and y (fringes of that period, display pixels, phase 0 at corner
    (0, 0)), star_segments > 0 the star of Schops et al. with that many
    segments after the checkerboard (the paper's sequence: pitch and 16). The baseline checkerboard has (nx+1) x (ny+1) squares of side pitch and
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
    if identity:
        from rotstar_mrcal.pattern.identity import IdentityCode

        try:
            IdentityCode.for_grid(nx, ny)
        except ValueError as e:
            raise ValueError(f"{e}: leave the identity frames out, or use fewer corners") from None
    check_extras(phase_period, star_segments)
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
        identity=identity,
        phase_period=float(phase_period),
        star_segments=int(star_segments),
    )


MIN_PHASE_PERIOD = 4  # display pixels: a shorter period is barely a sinusoid on the display's pixels


def check_extras(phase_period: float, star_segments: int) -> None:
    """ValueError unless the phase period and the star's segments are usable (0 = the frames left out)"""
    if phase_period and not (math.isfinite(phase_period) and phase_period >= MIN_PHASE_PERIOD):
        raise ValueError(f"phase period {phase_period:g}; must be at least {MIN_PHASE_PERIOD} display pixels")
    if star_segments and (star_segments % 4 or not 4 <= star_segments <= 64):
        raise ValueError(f"star segments {star_segments}; must be a multiple of 4 between 4 and 64")


MAX_SCREEN = 100_000  # display pixels; sanity bounds of pattern.json's values
MAX_CORNERS = 1000


def _get(d: dict, field: str, default=None, kind=int, lo=None, hi=None):
    """d["a"]["b"] for field "a.b", checked: raises ValueError("a.b <what is wrong>")"""
    v = d
    for key in field.split("."):
        if not isinstance(v, dict):
            raise ValueError(f"{field} missing ({field.rsplit('.', 1)[0]} is not an object)")
        if key not in v:
            if default is not None:
                return default
            raise ValueError(f"{field} missing")
        v = v[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError(f"{field} is {json.dumps(v)[:40]}; must be a number")
    if not math.isfinite(v):
        raise ValueError(f"{field} is {v}; must be finite")
    if kind is int:
        if v != int(v):
            raise ValueError(f"{field} is {v}; must be an integer")
        v = int(v)
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        rng = f"between {lo:g} and {hi:g}" if lo is not None and hi is not None else f">= {lo:g}"
        raise ValueError(f"{field} is {v:g}; must be {rng}")
    return kind(v)


FRAME_KINDS = ("rotstar", "identity", "phase", "checkerboard", "star")

SPARE_KINDS = {"identity": 1, "checkerboard": 1, "star": 1}
"""Frames a pose may lack, per kind, and still be detected: one identity frame (the identity code has a
constant weight, so one erased frame's bit is what the others leave: pattern.identity.IdentityCode.decode)
and the checkerboard and the star frame (read only by the peers' refinements, never by rotstar's)."""


def unspared(frames: list[dict], missing: list[str]) -> list[str]:
    """The files of `missing` that a pose cannot do without (SPARE_KINDS), in pattern.json's order

    >>> frames = [{"file": "r0", "kind": "rotstar"}, {"file": "i0", "kind": "identity"},
    ...           {"file": "i1", "kind": "identity"}, {"file": "cb", "kind": "checkerboard"}]
    >>> unspared(frames, ["i1", "cb"]), unspared(frames, ["i0", "i1"]), unspared(frames, ["r0"])
    ([], ['i0', 'i1'], ['r0'])
    """
    kind = {f["file"]: f["kind"] for f in frames}
    counts: dict[str, int] = {}
    for f in missing:
        counts[kind.get(f)] = counts.get(kind.get(f), 0) + 1
    return [f["file"] for f in frames if f["file"] in missing and counts[f["kind"]] > SPARE_KINDS.get(f["kind"], 0)]


def _check_frames(frames) -> int:
    """The "frames" list: file names and kinds; returns the number of rotating-star frames"""
    if not isinstance(frames, list):
        raise ValueError("frames missing or not a list")
    names = set()
    for k, f in enumerate(frames):
        if not isinstance(f, dict) or not isinstance(f.get("file"), str) or not isinstance(f.get("kind"), str):
            raise ValueError(f"frames[{k}] must be an object with a file name and a kind")
        name = f["file"]
        if not name or name != name.strip() or "/" in name or "\\" in name or name in (".", ".."):
            raise ValueError(f"frames[{k}].file {name!r} is not a plain file name")
        if name in names:
            raise ValueError(f"frames[{k}].file {name!r} appears twice")
        names.add(name)
        if f["kind"] not in FRAME_KINDS:
            raise ValueError(f"frames[{k}].kind {f['kind']!r}; must be one of {', '.join(FRAME_KINDS)}")
    n = sum(1 for f in frames if f["kind"] == "rotstar")
    if n < 2:
        raise ValueError(f"frames has {n} rotating-star frame(s); need at least 2 (the corners are where "
                         "the rotated frames agree)")
    return n


def _check_identity(d: dict, nx: int, ny: int) -> bool:
    """Whether pattern.json lists identity frames; ValueError when they do not match the grid's code"""
    from rotstar_mrcal.pattern.identity import code_from_dict

    idx = [f.get("index") for f in d["frames"] if f["kind"] == "identity"]
    if not idx and "identity" not in d:
        return False
    if "identity" not in d:
        raise ValueError(f"identity missing: frames lists {len(idx)} identity frame(s), and their code is not described")
    code = code_from_dict(d["identity"], nx, ny)
    if not idx:
        raise ValueError(f"frames: no identity frames, though the identity section describes {code.nframes}")
    if idx != list(range(code.nframes)):
        raise ValueError(f"frames: identity frames with indices {idx[:20]}; the {nx}x{ny} grid's code needs "
                         f"0..{code.nframes - 1} in order")
    return True


def _field(f: dict, k: int, key: str, default=None, **kw):
    """frames[k].key, checked like _get (ValueError naming frames[k].key)"""
    return _get({f"frames[{k}]": f}, f"frames[{k}].{key}", default, **kw)


def _check_phase(frames: list[dict]) -> tuple[float, tuple[float, float] | None]:
    """(period, origin) of the phase-shift frames, or (0, None) without them; ValueError naming the field"""
    idx = [k for k, f in enumerate(frames) if f["kind"] == "phase"]
    if not idx:
        return 0.0, None
    period = origin = None
    steps = {"x": [], "y": []}
    for k in idx:
        f = frames[k]
        if f.get("axis") not in steps:
            raise ValueError(f"frames[{k}].axis is {json.dumps(f.get('axis'))[:40]}; must be \"x\" or \"y\"")
        n = _field(f, k, "step", lo=0, hi=PHASE_STEPS - 1)
        shift = _field(f, k, "shift_rad", kind=float)
        if abs(shift - n * 2 * math.pi / PHASE_STEPS) > 1e-9:
            raise ValueError(f"frames[{k}].shift_rad is {shift:g}; step {n} of {PHASE_STEPS} is "
                             f"{n * 2 * math.pi / PHASE_STEPS:g}")
        p = _field(f, k, "period_px", kind=float, lo=MIN_PHASE_PERIOD, hi=MAX_SCREEN)
        o = f.get("phase_origin")
        if not isinstance(o, list) or len(o) != 2:
            raise ValueError(f"frames[{k}].phase_origin is {json.dumps(o)[:40]}; must be [x, y]")
        o = (_get({"o": {"x": o[0]}}, "o.x", kind=float, lo=-MAX_SCREEN, hi=MAX_SCREEN),
             _get({"o": {"y": o[1]}}, "o.y", kind=float, lo=-MAX_SCREEN, hi=MAX_SCREEN))
        if period is not None and (p != period or o != origin):
            raise ValueError(f"frames[{k}]: period_px {p:g} and phase_origin {list(o)} differ from the first phase "
                             f"frame's ({period:g}, {list(origin)})")
        period, origin = p, o
        steps[f["axis"]].append(n)
    for axis, got in steps.items():
        if got != list(range(PHASE_STEPS)):
            raise ValueError(f"frames: the phase frames along {axis} have steps {got}; need "
                             f"{list(range(PHASE_STEPS))} in order")
    return period, origin


def _check_star(frames: list[dict], pitch: int) -> int:
    """The star frame's segments, or 0 without one; ValueError naming the field"""
    idx = [k for k, f in enumerate(frames) if f["kind"] == "star"]
    if not idx:
        return 0
    if len(idx) > 1:
        raise ValueError(f"frames[{idx[1]}]: a second star frame; the sequence has one")
    k = idx[0]
    n = _field(frames[k], k, "segments", lo=4, hi=64)
    if n % 4:
        raise ValueError(f"frames[{k}].segments is {n}; must be a multiple of 4 (point-symmetric, black and white "
                         "alternating)")
    cell = _field(frames[k], k, "cell_px", pitch, lo=2, hi=MAX_SCREEN)
    if cell != pitch:
        raise ValueError(f"frames[{k}].cell_px is {cell}; the star's cells are the grid's pitch, {pitch}")
    if _field(frames[k], k, "first_edge_rad", 0.0, kind=float) != 0.0:
        raise ValueError(f"frames[{k}].first_edge_rad must be 0 (an edge along the grid's x axis)")
    return n


def layout_from_dict(d: dict) -> Layout:
    """Read a pattern.json dictionary; raises ValueError naming the field and what is wrong

    SYNOPSIS

        >>> d = make_layout().to_dict()
        >>> d["grid"]["nx"] = 0
        >>> layout_from_dict(d)
        Traceback (most recent call last):
        ValueError: grid.nx is 0; must be between 3 and 1000
    """
    if not isinstance(d, dict):
        raise ValueError("not a rotstar pattern description (not a JSON object)")
    for key in ("screen", "grid"):
        if not isinstance(d.get(key), dict):
            raise ValueError(f"{key} missing or not an object: not a rotstar pattern description")
    nframes = _check_frames(d.get("frames"))
    W = _get(d, "screen.width", lo=1, hi=MAX_SCREEN)
    H = _get(d, "screen.height", lo=1, hi=MAX_SCREEN)
    pitch = _get(d, "grid.pitch", lo=2, hi=MAX_SCREEN)
    origin = d["grid"].get("origin")
    if not isinstance(origin, list) or len(origin) != 2:
        raise ValueError(f"grid.origin is {json.dumps(origin)[:40]}; must be [x, y]")
    g = {"origin": {"x": origin[0], "y": origin[1]}}
    element = d.get("element", {})
    if not isinstance(element, dict):
        raise ValueError("element is not an object")
    marker = element.get("marker", [0, 0])
    if not isinstance(marker, list) or len(marker) != 2:
        raise ValueError(f"element.marker is {json.dumps(marker)[:40]}; must be [i, j]")
    nx = _get(d, "grid.nx", lo=3, hi=MAX_CORNERS)
    ny = _get(d, "grid.ny", lo=3, hi=MAX_CORNERS)
    m = {"element": {"marker": {"i": marker[0], "j": marker[1]}}}
    step = _get(d, "element.step_rad", math.pi / 16, kind=float)
    if step == 0 or (nframes - 1) * abs(step) >= math.pi:
        raise ValueError(f"element.step_rad is {step:g}; {nframes} frames need 0 < |step| < pi/{nframes - 1} "
                         "(frames turned by pi look the same)")
    layout = Layout(
        screen_width=W,
        screen_height=H,
        pixel_pitch_m=_get(d, "screen.pixel_pitch_m", kind=float, lo=1e-7, hi=1.0),
        nx=nx,
        ny=ny,
        pitch=pitch,
        band=_get(d, "element.band", 0, lo=0, hi=pitch // 2),
        origin=(_get(g, "origin.x", lo=-MAX_SCREEN, hi=MAX_SCREEN), _get(g, "origin.y", lo=-MAX_SCREEN, hi=MAX_SCREEN)),
        nframes=nframes,
        step=step,
        marker=(_get(m, "element.marker.i", lo=0, hi=nx - 1), _get(m, "element.marker.j", lo=0, hi=ny - 1)),
        background=_get(d, "element.background", 0.5, kind=float, lo=0.0, hi=1.0),
        identity=_check_identity(d, nx, ny),
        star_segments=_check_star(d["frames"], pitch),
    )
    period, porigin = _check_phase(d["frames"])
    if period:
        layout = dataclasses.replace(layout, phase_period=period,
                                     phase_origin=None if porigin == tuple(map(float, layout.origin)) else porigin)
    x0, y0, x1, y1 = layout.board_extent()
    if x0 < 0 or y0 < 0 or x1 > W or y1 > H:
        raise ValueError(f"grid: {nx}x{ny} corners at pitch {pitch} from origin {tuple(layout.origin)} do not fit "
                         f"on the {W}x{H} screen")
    return layout

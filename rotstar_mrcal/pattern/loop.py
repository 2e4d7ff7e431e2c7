"""The loop the player shows: a start marker, then the frames of pattern.json

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.pattern.layout import make_layout
    >>> from rotstar_mrcal.pattern.loop import player_loop, expected_levels
    >>> layout = make_layout(screen=(800, 600), pitch=100, band=24)
    >>> loop = player_loop(layout.frames())
    >>> len(loop), loop[0]["kind"], loop[1]["file"], loop[9]["file"], loop[-1]["file"]
    (20, 'start-marker', 'rotstar_00.png', 'identity_00.png', 'checkerboard.png')
    >>> np.round(expected_levels(layout, loop), 3)
    array([0.   , 0.631, 0.369, 0.631, 0.369, 0.631, 0.369, 0.631, 0.369,
           0.381, 0.357, 0.381, 0.357, 0.393, 0.357, 0.381, 0.357, 0.381,
           0.345, 0.625])

The start marker, the 8 rotating-star frames (band white, black, ...), the
identity frames (6 x 4 grid: 10 frames; bands black, about half of the
elements white, so their levels differ only by a few elements' area), then
the checkerboard.

This is the contract between the player (display/player.py) and
segmentation (capture/segment.py). One loop entry is held for a number of
display refreshes; the loop repeats forever. Entry 0, the start marker, is an
all-black screen: the darkest thing the player shows, by a wide margin (every
other frame shows the grey background and a white band or about half of the
elements white: more than a quarter of full white on the default screen), so
segmentation finds it by its level alone and reads the order of the rest
from it. pattern.json is not changed: the marker is not a dataset frame.

expected_levels gives the mean linear luminance of each entry over the whole
screen (what the screen emits; 0 black, 1 white). The camera sees a part of
the screen and the room around it, so recorded levels are an affine function
of these only roughly; segmentation compares them by correlation.
"""

from __future__ import annotations

import numpy as np

from rotstar_mrcal.pattern.layout import Layout
from rotstar_mrcal.pattern.render import render_frame

MARKER = {"file": None, "kind": "start-marker", "level": 0.0}
"""Loop entry 0: the whole screen black"""


def player_loop(frames: list[dict]) -> list[dict]:
    """[MARKER] + frames (copies): the entries the player cycles through"""
    return [dict(MARKER)] + [dict(f) for f in frames]


def frame_level(layout: Layout, frame: dict) -> float:
    """Mean linear luminance of one entry over the whole screen

    Closed form for the known kinds (a checker corner's square is exactly half
    white at any angle: turning it by 90 degrees swaps the colours and maps the
    square onto itself); other kinds are rendered and averaged.
    """
    W, H = layout.screen_width, layout.screen_height
    kind = frame["kind"]
    if kind == "start-marker":
        return float(frame.get("level", 0.0))
    if kind == "rotstar":
        x0, y0, x1, y1 = layout.board_extent()
        board = (x1 - x0) * (y1 - y0)
        elements = layout.nx * layout.ny * (2 * layout.half_element) ** 2
        band = 1.0 if layout.band_white(int(frame["index"])) else 0.0
        total = layout.background * (W * H - board) + band * (board - elements) + 0.5 * elements
        return total / (W * H)
    if kind == "identity":
        x0, y0, x1, y1 = layout.board_extent()
        white = int(layout.identity_code.frame_bits(int(frame["index"])).sum()) * (2 * layout.half_element) ** 2
        return (layout.background * (W * H - (x1 - x0) * (y1 - y0)) + white) / (W * H)
    if kind == "phase":  # the fringe inside the board's outline: a 1-D profile times the outline's other side
        from rotstar_mrcal.pattern.render import phase_profile

        x0, y0, x1, y1 = layout.board_extent()
        if frame["axis"] == "x":
            inside = phase_profile(layout, "x", int(frame["step"]), W)[x0:x1].sum() * (y1 - y0)
        else:
            inside = phase_profile(layout, "y", int(frame["step"]), H)[y0:y1].sum() * (x1 - x0)
        return (layout.background * (W * H - (x1 - x0) * (y1 - y0)) + inside) / (W * H)
    if kind == "star":  # every cell half white: a reflection across its x axis swaps the colours
        cells = layout.nx * layout.ny * layout.pitch**2
        return (layout.background * (W * H - cells) + 0.5 * cells) / (W * H)
    if kind == "checkerboard":
        na, nb = layout.nx + 1, layout.ny + 1
        black = sum(1 for a in range(na) for b in range(nb) if (a + b) % 2 == 0)
        return (W * H - black * layout.pitch**2) / (W * H)
    return float(np.mean(render_frame(layout, frame)))


SHORT_HOLDS = {"rotstar": 11, "identity": 6, "checkerboard": 6, "start-marker": 3}
"""Display refreshes per frame kind for a short capture (60 Hz): measured with the capture's simulated camera,
every timing flaw on (tests/capture/test_timing_flaws.py): at 25 fps with 8 ms exposures, 6 refreshes (100 ms)
give two consecutive clean camera frames of an entry in 96 % of the passes (5: 65 %, 4: 29 %), at 30 fps 97 %
(5: 95 %), so every frame that is only read (identity, checkerboard) gets 6; the start marker, which the split by
content does not need, 3; the rotating-star frames, whose camera frames are averaged for the corners, the rest
of a 3 s look: 11 (183 ms, about four clean camera frames at 25 fps, five at 30). One loop of the default
sequence: 8 x 11 + 13 x 6 + 6 + 3 = 175 refreshes, 2.9 s; with --until-enough's two more camera frames 3.0 s at
25 fps."""


def entry_holds(loop: list[dict], hold: int | None = None, kind_holds: dict | None = None,
                marker_hold: int | None = None) -> np.ndarray:
    """(len(loop),) display refreshes each loop entry is held

    hold: every kind's hold (None: SHORT_HOLDS per kind, the rotating star's
    for kinds it does not list); kind_holds: {kind: refreshes} over that; marker_hold: the
    start marker's (None: as its kind says).

    >>> loop = player_loop([{"file": "a", "kind": "rotstar"}, {"file": "b", "kind": "identity"}])
    >>> entry_holds(loop, 30).tolist(), entry_holds(loop).tolist(), entry_holds(loop, 30, {"identity": 6}, 45).tolist()
    ([30, 30, 30], [3, 11, 6], [45, 30, 6])
    """
    base = dict(SHORT_HOLDS) if hold is None else {}
    base.update(kind_holds or {})
    if marker_hold:
        base["start-marker"] = marker_hold
    default = SHORT_HOLDS["rotstar"] if hold is None else hold
    return np.array([int(base.get(e["kind"], default)) for e in loop])


def expected_levels(layout: Layout, loop: list[dict]) -> np.ndarray:
    """(len(loop),) mean linear luminance of every loop entry"""
    return np.array([frame_level(layout, e) for e in loop])

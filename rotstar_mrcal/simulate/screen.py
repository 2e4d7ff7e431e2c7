"""The screen as a light source: piecewise-constant display pixels on the board plane

SYNOPSIS

    >>> from rotstar_mrcal.pattern.layout import make_layout
    >>> from rotstar_mrcal.simulate.screen import exact_frames, make_screen, board_to_screen
    >>> layout = make_layout(screen=(800, 600), pitch=100, band=24)
    >>> frames = exact_frames(layout)                  # every entry of layout.frames()
    >>> frames.shape, frames.dtype                     # 8 rotating-star, 10 identity, the checkerboard
    ((19, 600, 800), dtype('float32'))
    >>> screen = make_screen(frames, layout, room=0.02)
    >>> screen.nframes, screen.sat.shape
    (19, (601, 801, 19))
    >>> board_to_screen(layout.board_points()[0, 1], layout)   # corner (1, 0)
    array([250., 150.])

A frame is a (height, width) array of linear luminance in [0, 1]; display
pixel (u, v) emits frame[floor(v), floor(u)] over [u, u+1) x [v, v+1). Around
the screen (and wherever a ray misses it) the camera sees a constant "room"
level.

make_screen stores the summed-area table of (frame - room) for every frame,
float64, laid out (Hs+1, Ws+1, nframes) so that one look-up reads all frames.
Bilinear interpolation of a summed-area table of a piecewise-constant image is
its exact integral, so the renderer gets the exact mean luminance over any
axis-aligned box on the screen with 16 look-ups. Memory: 8 * nframes bytes per
display pixel (680 MB for the 22 frames of the default sequence on a 2360x1640
screen, 280 MB for the 9 without identity frames, 960 MB for the 31 of the paper's
whole sequence).
"""

from __future__ import annotations

import dataclasses
import functools
import os

import cv2
import numpy as np

from rotstar_mrcal.pattern.layout import Layout
from rotstar_mrcal.pattern.render import decode_display, encode_display, render_frame


@dataclasses.dataclass(frozen=True)
class Screen:
    """Frames ready for rendering (see make_screen)"""

    layout: Layout
    room: float
    sat: np.ndarray  # (Hs+1, Ws+1, nframes) float64: sat[v, u] = sum(frame[:v, :u] - room)

    @property
    def nframes(self) -> int:
        return self.sat.shape[-1]

    @property
    def width(self) -> int:
        return self.sat.shape[1] - 1

    @property
    def height(self) -> int:
        return self.sat.shape[0] - 1

    def frames(self) -> np.ndarray:
        """The frames back, (nframes, Hs, Ws)"""
        s = self.sat
        d = s[1:, 1:] - s[:-1, 1:] - s[1:, :-1] + s[:-1, :-1]
        return np.moveaxis(d, -1, 0) + self.room


def make_screen(frames: np.ndarray, layout: Layout, room: float = 0.02) -> Screen:
    """Summed-area tables of (nframes, Hs, Ws) or (Hs, Ws) frames of linear luminance"""
    f = np.asarray(frames)
    if f.ndim == 2:
        f = f[None]
    if f.shape[1:] != (layout.screen_height, layout.screen_width):
        raise ValueError(
            f"frames are {f.shape[2]}x{f.shape[1]}, the layout's screen is "
            f"{layout.screen_width}x{layout.screen_height}"
        )
    sat = np.zeros((f.shape[1] + 1, f.shape[2] + 1, f.shape[0]))
    sat[1:, 1:] = np.moveaxis(f, 0, -1)
    sat[1:, 1:] -= room
    np.cumsum(sat, axis=0, out=sat)
    np.cumsum(sat, axis=1, out=sat)
    return Screen(layout=layout, room=float(room), sat=sat)


def exact_frames(layout: Layout, frames: list[dict] | None = None) -> np.ndarray:
    """render_frame of every entry of layout.frames() (or of `frames`), float32

    The whole sequence of a layout is kept for the next call (read-only: copy it to change it); rendering it
    takes 1-2 s for the default screen, and a run that writes several datasets asks for the same one again.
    """
    if frames is None:
        return _whole_sequence(layout)
    return np.stack([render_frame(layout, f).astype(np.float32) for f in frames])


@functools.lru_cache(maxsize=1)
def _whole_sequence(layout: Layout) -> np.ndarray:
    out = exact_frames(layout, layout.frames())
    out.flags.writeable = False
    return out


def shown_light(frames: np.ndarray, gamma: float = 2.2, screen_gamma: float | None = None) -> np.ndarray:
    """The light a screen emits for linear frames: 8-bit encoded for `gamma`, decoded with the screen's own

    rotstar-pattern writes each frame as 8-bit values pre-compensated for a
    display gamma of `gamma` (encode_display); a screen whose gamma is
    `screen_gamma` (default: the same) emits decode_display(values,
    screen_gamma). With equal gammas only the 8-bit quantisation remains;
    black and white frames are unchanged either way. A mismatch bends the
    sinusoid of a phase-shift frame (luminance^(screen_gamma / gamma)), which
    the 4-step phase turns into a periodic phase error; binary frames do not
    notice it.

    SYNOPSIS

        >>> import numpy as np
        >>> f = np.array([[0.0, 0.25, 0.5, 1.0]], np.float32)
        >>> [round(float(v), 3) for v in shown_light(f)[0]]
        [0.0, 0.251, 0.5, 1.0]
        >>> [round(float(v), 3) for v in shown_light(f, 2.2, 2.6)[0]]      # the screen's gamma is higher
        [0.0, 0.195, 0.44, 1.0]
    """
    g = gamma if screen_gamma is None else screen_gamma
    return decode_display(encode_display(np.asarray(frames, float), gamma), g).astype(np.float32)


def png_frames(folder: str, layout: Layout, gamma: float = 2.2) -> np.ndarray:
    """The pattern PNGs a screen shows, decoded to linear luminance, float32

    Reads folder/<file> for every entry of layout.frames() (as rotstar-pattern
    writes them) and undoes the display gamma with decode_display.
    """
    out = []
    for f in layout.frames():
        fn = os.path.join(folder, f["file"])
        img = cv2.imread(fn, cv2.IMREAD_GRAYSCALE)
        if img is None:
            raise FileNotFoundError(f"{fn}: missing or unreadable pattern image")
        if img.shape != (layout.screen_height, layout.screen_width):
            raise ValueError(f"{fn}: {img.shape[1]}x{img.shape[0]}, expected the screen size")
        out.append(decode_display(img, gamma).astype(np.float32))
    return np.stack(out)


def board_to_screen(p_board: np.ndarray, layout: Layout) -> np.ndarray:
    """Board points (..., 2 or 3) in metres -> screen points (..., 2), display pixels"""
    p = np.asarray(p_board, float)[..., :2]
    return p / layout.pixel_pitch_m + np.array(layout.origin, float)


def screen_to_board(uv: np.ndarray, layout: Layout) -> np.ndarray:
    """Screen points (..., 2), display pixels -> board points (..., 3), z = 0"""
    p = (np.asarray(uv, float) - np.array(layout.origin, float)) * layout.pixel_pitch_m
    return np.concatenate((p, np.zeros(p.shape[:-1] + (1,))), axis=-1)

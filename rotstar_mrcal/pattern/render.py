"""Exact rendering of the display frames

SYNOPSIS

    >>> from rotstar_mrcal.pattern.layout import make_layout
    >>> from rotstar_mrcal.pattern.render import render_frame
    >>> layout = make_layout(screen=(800, 600), pitch=100, band=24)
    >>> img = render_frame(layout, layout.frames()[1])
    >>> img.shape, img.dtype, float(img.min()), float(img.max())
    ((600, 800), dtype('float64'), 0.0, 1.0)

Every display pixel holds the area fraction of white inside it (linear
luminance, 0 = black, 1 = white). Element edges, bands and the checkerboard
squares lie on pixel boundaries; a checker line at angle theta crosses pixels
whose coverage is the closed-form area of a unit square on one side of a line
(the CDF of a sum of two uniform variables). The few pixels that both lines of
an element cross (at its centre) are supersampled 64x64.

`encode_display` applies the display gamma for the 8-bit PNG that the screen
shows, and `decode_display` undoes it.
"""

from __future__ import annotations

import numpy as np

from rotstar_mrcal.pattern.layout import Layout

CENTRE_SUPERSAMPLING = 64


def _halfplane_coverage(s: np.ndarray, a: float, b: float) -> np.ndarray:
    """Fraction of a unit pixel on the positive side of a line

    s is the signed distance of the pixel centre from the line, (a, b) the
    absolute components of the line's unit normal.
    """
    a, b = max(a, b), min(a, b)
    x = np.clip(np.asarray(s, float) + (a + b) / 2, 0.0, a + b)
    if b < 1e-12:
        return x / a
    out = np.where(x <= b, x * x / (2 * a * b), (x - b / 2) / a)
    return np.where(x >= a, 1 - (a + b - x) ** 2 / (2 * a * b), out)


def _element_pixels(layout: Layout):
    """Pixel centres of every element's checker square, relative to its centre

    Returns (u, v, dx, dy, flip): u, v integer pixel indices of shape
    (ny, nx, 2h, 2h); dx, dy the offsets of the pixel centres; flip True where
    the element's colours are the inverse of parity (i + j) even.
    """
    h = layout.half_element
    c = layout.corner_screen_xy().astype(int)  # (ny, nx, 2)
    oy, ox = np.mgrid[-h:h, -h:h]
    u = c[..., 0, None, None] + ox
    v = c[..., 1, None, None] + oy
    dx = (ox + 0.5).astype(float)
    dy = (oy + 0.5).astype(float)
    j, i = np.mgrid[0 : layout.ny, 0 : layout.nx]
    flip = ((i + j) % 2 == 1)
    flip[layout.marker[1], layout.marker[0]] ^= True
    return u, v, dx, dy, flip


def checker_coverage(dx: np.ndarray, dy: np.ndarray, theta: float) -> np.ndarray:
    """White area fraction of pixels centred at (dx, dy) around a checker corner

    The corner's lines run along directions theta and theta + pi/2 (angles
    from screen x toward screen y); white are the quadrants where the two
    rotated coordinates have opposite signs, so at theta = 0 the quadrant
    below-right of the corner (x > 0, y > 0) is black.
    """
    c, s = np.cos(theta), np.sin(theta)
    s1 = c * dx + s * dy  # distance across the line along (-s, c)
    s2 = -s * dx + c * dy
    a, b = abs(c), abs(s)
    p1 = _halfplane_coverage(s1, a, b)
    p2 = _halfplane_coverage(s2, a, b)
    out = p1 * (1 - p2) + (1 - p1) * p2
    both = (p1 > 0) & (p1 < 1) & (p2 > 0) & (p2 < 1)
    if np.any(both):
        n = CENTRE_SUPERSAMPLING
        t = (np.arange(n) + 0.5) / n - 0.5
        sy, sx = np.meshgrid(t, t, indexing="ij")
        px = dx[both][:, None, None] + sx
        py = dy[both][:, None, None] + sy
        r1 = c * px + s * py
        r2 = -s * px + c * py
        out[both] = np.mean((r1 * r2 < 0) + 0.5 * ((r1 * r2) == 0), axis=(-1, -2))
    return out


def render_rotstar(layout: Layout, k: int) -> np.ndarray:
    """Frame k of the rotating-star sequence, (height, width) float in [0, 1]"""
    img = np.full((layout.screen_height, layout.screen_width), layout.background)
    x0, y0, x1, y1 = layout.board_extent()
    img[y0:y1, x0:x1] = 1.0 if layout.band_white(k) else 0.0
    u, v, dx, dy, flip = _element_pixels(layout)
    w = checker_coverage(dx, dy, layout.angle(k))
    w = np.where(flip[..., None, None], 1 - w, w)
    img[v, u] = w
    return img


def render_identity(layout: Layout, b: int) -> np.ndarray:
    """Identity frame b: each element's square white where bit b of its codeword is 1, black where 0

    The border bands are black and the screen outside them is the background,
    as in the rotating-star frames; the squares are the checker squares of
    those frames, so every element pixel changes between identity frames and
    no band pixel does.
    """
    code = layout.identity_code
    if code is None or not 0 <= b < code.nframes:
        raise ValueError(f"identity frame {b}: the layout has {code.nframes if code else 0} identity frames")
    img = np.full((layout.screen_height, layout.screen_width), layout.background)
    x0, y0, x1, y1 = layout.board_extent()
    img[y0:y1, x0:x1] = 0.0
    u, v, _, _, _ = _element_pixels(layout)
    img[v, u] = code.frame_bits(b).astype(float)[..., None, None]
    return img


def render_checkerboard(layout: Layout) -> np.ndarray:
    """The baseline checkerboard: (nx+1) x (ny+1) squares, inner corners = the grid

    White background; square (a, b) (a = 0..nx, b = 0..ny, top-left square
    (0, 0)) is black where a + b is even, matching frame 0 of the sequence.
    """
    img = np.ones((layout.screen_height, layout.screen_width))
    x0, y0, x1, y1 = layout.checkerboard_extent()
    yy, xx = np.mgrid[y0:y1, x0:x1]
    a = (xx - x0) // layout.pitch
    b = (yy - y0) // layout.pitch
    img[y0:y1, x0:x1] = ((a + b) % 2).astype(float)
    return img


def phase_profile(layout: Layout, axis: str, step: int, length: int) -> np.ndarray:
    """(length,) the fringe of phase-shift frame (axis, step) at display pixel centres 0.5, 1.5, ... along axis

    Linear luminance 0.5 + 0.5 cos(phi + step 2 pi / 4), phi = 2 pi (u + 0.5 - phase_origin) / period:
    the light the screen emits is this sinusoid once encode_display has
    pre-compensated the display gamma (the PNG values are not sinusoidal).

    SYNOPSIS

        >>> from rotstar_mrcal.pattern.layout import make_layout
        >>> L = make_layout(screen=(800, 600), pitch=100, band=24, phase_period=100)
        >>> p = [phase_profile(L, "x", n, 800) for n in range(4)]
        >>> x0 = L.origin[0]                       # corner (0, 0) lies on the pixel boundary at x0
        >>> phi = np.arctan2(p[3] - p[1], p[0] - p[2])
        >>> np.round(phi[x0 - 1 : x0 + 1] * 100 / (2 * np.pi), 6).tolist()   # +-0.5 px from phase 0
        [-0.5, 0.5]
    """
    from rotstar_mrcal.pattern.layout import PHASE_STEPS

    o = layout.phase_zero[0 if axis == "x" else 1]
    phi = 2 * np.pi * (np.arange(length) + 0.5 - o) / layout.phase_period
    return 0.5 + 0.5 * np.cos(phi + step * 2 * np.pi / PHASE_STEPS)


def render_phase(layout: Layout, axis: str, step: int) -> np.ndarray:
    """Phase-shift frame `step` along `axis` ("x": fringes vary with x) inside the board's outline

    The fringes fill the board's outline (the border bands' outer edge, as in
    the rotating-star frames); outside it the screen is the background.
    """
    if not layout.phase:
        raise ValueError("the layout has no phase-shift frames")
    img = np.full((layout.screen_height, layout.screen_width), layout.background)
    x0, y0, x1, y1 = layout.board_extent()
    if axis == "x":
        img[y0:y1, x0:x1] = phase_profile(layout, "x", step, layout.screen_width)[None, x0:x1]
    elif axis == "y":
        img[y0:y1, x0:x1] = phase_profile(layout, "y", step, layout.screen_height)[y0:y1, None]
    else:
        raise ValueError(f"phase axis {axis!r}; must be x or y")
    return img


def star_coverage(dx: np.ndarray, dy: np.ndarray, segments: int) -> np.ndarray:
    """White area fraction of pixels centred at (dx, dy) around the centre of a star of `segments` wedges

    Wedge k runs from angle 2 pi k / segments to 2 pi (k + 1) / segments
    (from screen x toward screen y) and is black for even k, so segments = 4
    is checker_coverage at theta = 0. The colour is an XOR of the half-planes
    of the segments / 2 lines through the centre: exact area fractions where at
    most one line crosses a pixel, 64 x 64 supersampling where more do.

    SYNOPSIS

        >>> d = np.arange(-3, 3) + 0.5
        >>> dy, dx = np.meshgrid(d, d, indexing="ij")
        >>> bool(np.allclose(star_coverage(dx, dy, 4), checker_coverage(dx, dy, 0.0)))
        True
        >>> float(star_coverage(dx, dy, 16).mean())          # a square around the centre: half white
        0.5
    """
    n = segments // 2
    theta = np.pi * np.arange(n) / n
    prod = np.ones(np.broadcast(dx, dy).shape)
    fractional = np.zeros(prod.shape, int)
    for t in theta:  # p = area of the pixel where sin(angle - t) > 0
        p = _halfplane_coverage(-np.sin(t) * dx + np.cos(t) * dy, abs(np.sin(t)), abs(np.cos(t)))
        prod = prod * (1 - 2 * p)
        fractional += (p > 1e-9) & (p < 1 - 1e-9)
    out = (1 + prod) / 2
    many = fractional > 1
    if np.any(many):
        m = CENTRE_SUPERSAMPLING
        s = (np.arange(m) + 0.5) / m - 0.5
        sy, sx = np.meshgrid(s, s, indexing="ij")
        px = np.broadcast_to(dx, out.shape)[many][:, None, None] + sx
        py = np.broadcast_to(dy, out.shape)[many][:, None, None] + sy
        sign = np.ones(px.shape)
        for t in theta:  # trigonometry rounded so that the diagonals hit the samples on them exactly
            sign = sign * np.sign(np.round(np.cos(t), 12) * py - np.round(np.sin(t), 12) * px)
        out[many] = np.mean((1 + sign) / 2, axis=(-1, -2))  # a sample on a line counts half
    return out


def render_star(layout: Layout) -> np.ndarray:
    """The star frame of Schops et al.: every corner the centre of a star filling its pitch x pitch cell

    The cells tile the grid without gaps (corner (i, j)'s cell is the square
    of side pitch centred on it); colours are inverted where i + j is odd, so
    that the wedges continue across the cells' edges (with 4 segments this is
    the checkerboard). Outside the cells the screen is the background.
    """
    if not layout.star_segments:
        raise ValueError("the layout has no star frame")
    h = layout.pitch // 2
    oy, ox = np.mgrid[-h:h, -h:h]
    w = star_coverage(ox + 0.5, oy + 0.5, layout.star_segments)
    img = np.full((layout.screen_height, layout.screen_width), layout.background)
    c = layout.corner_screen_xy().astype(int)
    j, i = np.mgrid[0 : layout.ny, 0 : layout.nx]
    cells = np.where(((i + j) % 2 == 1)[..., None, None], 1 - w, w)
    img[c[..., 1, None, None] + oy, c[..., 0, None, None] + ox] = cells
    return img


def render_frame(layout: Layout, frame: dict) -> np.ndarray:
    """Render one entry of layout.frames()"""
    if frame["kind"] == "phase":
        return render_phase(layout, frame["axis"], int(frame["step"]))
    if frame["kind"] == "star":
        return render_star(layout)
    if frame["kind"] == "rotstar":
        return render_rotstar(layout, int(frame["index"]))
    if frame["kind"] == "identity":
        return render_identity(layout, int(frame["index"]))
    if frame["kind"] == "checkerboard":
        return render_checkerboard(layout)
    raise ValueError(f"unknown frame kind {frame['kind']!r}")


def encode_display(img: np.ndarray, gamma: float = 2.2) -> np.ndarray:
    """Linear luminance in [0, 1] -> 8-bit display values"""
    return np.round(255 * np.clip(img, 0, 1) ** (1 / gamma)).astype(np.uint8)


def decode_display(values: np.ndarray, gamma: float = 2.2) -> np.ndarray:
    """8-bit display values -> linear luminance in [0, 1]"""
    return (np.asarray(values, float) / 255) ** gamma

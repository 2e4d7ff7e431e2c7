"""A display that does not show every frame alike: one affine map per rotating-star frame, in display pixels

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.simulate.display import parse_display_maps, centred_maps, show_frames
    >>> maps = parse_display_maps("1:0,2; 2:0,0,0,1px@bottom", 3, (800, 500))
    >>> maps[1].tolist()                         # frame 1 shown 2 display px lower
    [[1.0, 0.0, 0.0], [0.0, 1.0, 2.0]]
    >>> maps[2].round(6).tolist()                # frame 2 one display px taller, its bottom row in place
    [[1.0, 0.0, 0.0], [0.0, 1.002, -1.0]]
    >>> f = np.zeros((3, 500, 800), np.float32); f[:, 250:] = 1    # an edge at v = 250
    >>> g = show_frames(f, maps)
    >>> [float(g[k, 248:254, 5].sum()) for k in range(3)]           # the edge shown at v = 250, 252, 249.5
    [4.0, 2.0, 4.5]

A real player, decoder or panel scaler can show the frames of the sequence
a display pixel or so apart, and one of them a pixel taller (measured on
recordings of a monitor, doc/detector.md). Such a map follows the screen:
it is the same in every pose. A map is a (2, 3) affine matrix A taking a
point p of the frame as rendered (display pixels, u right, v down) to the
point A @ (p, 1) where the screen shows it.

The spec (rotstar-simulate --display-map): entries 'K:DX,DY[,SX,SY][@ANCHOR]'
separated by ';', K the rotating-star frame (0-based), DX, DY the shift in
display px, SX, SY the stretch along u and v, in ppm, or in display pixels
over the screen's width / height with a 'px' suffix ('0,1px' = one display
pixel taller); ANCHOR the point the stretch keeps in place: center
(default), top, bottom, left, right, top-left, top-right, bottom-left,
bottom-right. Frames not named are shown as rendered.

show_frames resamples each frame through its map with bilinear
interpolation (what a player's scaler does): an edge of a piecewise-constant
frame is shown where the map puts it, in the area sense, to float precision
for a shift and within |stretch| / 2 display px for a stretch (0.0003 px for
one display pixel over 1600).
The truth of a simulated dataset is the board at the maps' mean
(centred_maps), where the joint refinement of all frames measures it.
"""

from __future__ import annotations

import re

import numpy as np

ANCHORS = {"center": (0.5, 0.5), "top": (0.5, 0.0), "bottom": (0.5, 1.0), "left": (0.0, 0.5), "right": (1.0, 0.5),
           "top-left": (0.0, 0.0), "top-right": (1.0, 0.0), "bottom-left": (0.0, 1.0), "bottom-right": (1.0, 1.0)}
MAX_STRETCH_PPM = 1e5  # a stretch beyond 10 % is not a display's flaw


def identity_maps(n: int) -> np.ndarray:
    """(n, 2, 3) maps that show every frame as rendered"""
    return np.repeat(np.eye(2, 3)[None], n, axis=0)


def offset_maps(offsets) -> np.ndarray:
    """(n, 2, 3) maps of (n, 2) display offsets (shifts only)

        >>> offset_maps([[1, 2]]).tolist()
        [[[1.0, 0.0, 1.0], [0.0, 1.0, 2.0]]]
    """
    off = np.asarray(offsets, float)
    maps = identity_maps(len(off))
    maps[:, :, 2] = off
    return maps


def stretch_map(shift, stretch, anchor) -> np.ndarray:
    """(2, 3) map: scale by 1 + stretch (2,) about the anchor point (2,), then shift (2,), display px

        >>> stretch_map((0, 0), (0, 0.5), (0, 10)).tolist()   # 50 % taller, v = 10 kept
        [[1.0, 0.0, 0.0], [0.0, 1.5, -5.0]]
    """
    s = 1 + np.asarray(stretch, float)
    a = np.asarray(anchor, float)
    return np.column_stack((np.diag(s), a - s * a + np.asarray(shift, float)))


def _stretch(text: str, extent: int) -> float:
    """One stretch value as a fraction: 'N' ppm, or 'Npx' display px over extent"""
    if text.endswith("px"):
        return float(text[:-2]) / extent
    return float(text) * 1e-6


def _entry(entry: str, n: int, size: tuple[int, int]) -> tuple[int, np.ndarray]:
    """(frame, (2, 3) map) of one entry 'K:DX,DY[,SX,SY][@ANCHOR]'; ValueError saying what is wrong"""
    m = re.fullmatch(r"\s*(\d+)\s*:\s*([^@]+?)\s*(?:@\s*([a-z-]+))?\s*", entry)
    if not m:
        raise ValueError(f"{entry.strip()!r} is not 'K:DX,DY[,SX,SY][@ANCHOR]'")
    k, values, anchor = int(m[1]), [v.strip() for v in m[2].split(",")], m[3] or "center"
    if not 0 <= k < n:
        raise ValueError(f"frame {k} out of range: the sequence has {n} rotating-star frames (0-{n - 1})")
    if len(values) not in (2, 4):
        raise ValueError(f"{entry.strip()!r}: give 2 numbers (DX,DY) or 4 (DX,DY,SX,SY)")
    if anchor not in ANCHORS:
        raise ValueError(f"anchor {anchor!r}: one of {', '.join(ANCHORS)}")
    try:
        shift = [float(v) for v in values[:2]]
        stretch = [_stretch(v, e) for v, e in zip(values[2:], size)] if len(values) == 4 else [0.0, 0.0]
    except ValueError:
        raise ValueError(f"{entry.strip()!r}: not numbers (stretch in ppm, or display px with 'px')") from None
    if not np.isfinite(shift + stretch).all() or max(abs(s) for s in stretch) * 1e6 > MAX_STRETCH_PPM:
        raise ValueError(f"{entry.strip()!r}: shifts must be finite and stretches within +-{MAX_STRETCH_PPM:.0f} ppm")
    a = np.multiply(ANCHORS[anchor], size)
    return k, stretch_map(shift, stretch, a)


def parse_display_maps(spec: str, n: int, size: tuple[int, int]) -> np.ndarray:
    """--display-map SPEC (module doc) -> (n, 2, 3) maps; size = (width, height) of the screen, display px

    ValueError (one line, naming --display-map) for a bad spec.

        >>> parse_display_maps("9:1,1", 8, (800, 600))
        Traceback (most recent call last):
        ...
        ValueError: --display-map '9:1,1': frame 9 out of range: the sequence has 8 rotating-star frames (0-7)
    """
    maps = identity_maps(n)
    seen = set()
    for entry in (e for e in spec.split(";") if e.strip()):
        try:
            k, a = _entry(entry, n, size)
            if k in seen:
                raise ValueError(f"frame {k} given twice")
        except ValueError as e:
            raise ValueError(f"--display-map {spec!r}: {e}") from None
        seen.add(k)
        maps[k] = a
    if not seen:
        raise ValueError(f"--display-map {spec!r}: no entry; expected 'K:DX,DY[,SX,SY][@ANCHOR];...'")
    return maps


def homogeneous(maps: np.ndarray) -> np.ndarray:
    """(..., 2, 3) affine maps -> (..., 3, 3)"""
    maps = np.asarray(maps, float)
    last = np.broadcast_to(np.array([0.0, 0.0, 1.0]), maps.shape[:-2] + (1, 3))
    return np.concatenate((maps, last), axis=-2)


def centred_maps(maps: np.ndarray) -> np.ndarray:
    """The maps relative to their mean (each composed with the mean's inverse): their mean is the identity

        >>> m = centred_maps(offset_maps([[2, 0], [0, 0]]))
        >>> m[:, :, 2].tolist(), m.mean(axis=0).round(12).tolist()
        ([[1.0, 0.0], [-1.0, 0.0]], [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    """
    h = homogeneous(maps)
    return (h @ np.linalg.inv(h.mean(axis=0)))[:, :2]


def show_frames(frames: np.ndarray, maps: np.ndarray) -> np.ndarray:
    """Frames (n, Hs, Ws) as the display shows them through maps (n, 2, 3): bilinear, edge pixels extended

    Display pixel (u, v) covers [u, u+1) x [v, v+1); the value shown at its
    centre is the frame's, interpolated, at the inverse map of that centre.
    """
    import scipy.ndimage  # 0.6-0.8 s to import after scipy.sparse (-X importtime), only for a flawed display

    frames = np.asarray(frames, np.float32)
    out = frames.copy()
    for k, a in enumerate(np.asarray(maps, float)):
        if np.array_equal(a, np.eye(2, 3)):
            continue
        inv = np.linalg.inv(homogeneous(a))
        # index (row, col) = (v - 0.5, u - 0.5): source index = P inv P^-1 (index + 0.5) - 0.5, P swapping u, v
        lin = inv[:2, :2][::-1, ::-1]
        off = inv[:2, 2][::-1] + lin @ np.full(2, 0.5) - 0.5
        out[k] = scipy.ndimage.affine_transform(frames[k], lin, offset=off, order=1, mode="nearest")
    return out

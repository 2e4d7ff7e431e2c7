"""Render what a camera sees of the screen: irradiance images, before the sensor

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.pattern.layout import make_layout
    >>> from rotstar_mrcal.simulate.camera import preset_model
    >>> from rotstar_mrcal.simulate.screen import exact_frames, make_screen
    >>> from rotstar_mrcal.simulate.irradiance import render_irradiance
    >>> layout = make_layout(screen=(800, 600), pitch=100, band=24)
    >>> screen = make_screen(exact_frames(layout), layout, room=0.02)
    >>> model = preset_model("pinhole-small")                 # 640x400, f = 320
    >>> rt = np.array((0, 0, 0, -0.0385, -0.0289, 0.12))      # head-on, 12 cm away
    >>> img = render_irradiance(screen, model, rt, supersample=4, psf=1.0)
    >>> img.shape, round(float(img[0, 0, 0]), 3)              # corner pixel sees the room
    ((19, 400, 640), 0.02)

For every camera pixel, s x s sub-pixels are traced: the sub-pixel rays
(interpolated from the per-camera ray cache, camera.camera_rays) are
intersected with the board plane z = 0 (board frame: origin at corner (0, 0),
x right, y down, +z into the screen). A ray that misses the plane, or hits it
from behind, or lands off the screen, sees the constant room level.

sampling="area" (default): every sub-pixel takes the exact mean luminance of
the screen over an axis-aligned box around the point its centre hits, read
from the summed-area table; the box has the footprint's second moments along
u and v (sides sqrt(a_u^2 + b_u^2) and sqrt(a_v^2 + b_v^2), with a and b the
screen displacements of one sub-pixel step in x and in y). For a head-on view
the boxes tile the screen exactly, so a camera pixel is the exact area
integral of the screen over its footprint; edges fall where the geometry puts
them to ~1e-6 px. Rotated footprints become a box of the same size: a
symmetric prefilter, so edges are not displaced. sampling="point" looks the
screen up at the sub-pixel centres only (the classical supersampler; edge
positions are then quantised to 1/s px).

The supersampled image is convolved with the PSF (optics.as_psf: None, a
Gaussian sigma in camera pixels, a sub-pixel kernel or a callable) and each
s x s block is averaged into a camera pixel (a PSF with a `pixels` method,
optics.SmoothPSF, does both at once).

Only the region of interest is traced: the camera pixels whose rays land on
the screen (found from the cached per-pixel rays), plus one pixel and the
PSF radius; the rest of the image is the room level.

rt_cam_board may be one pose (6,) or one pose per frame (nframes, 6); frames
that share a pose are rendered together.

glass (optics.refraction.Glass): a cover glass over the emitting layer. Each
sub-pixel ray is then refracted exactly at the glass surface (the plane
thickness_m in front of the board, on the camera's side) and meets the
emitting layer where the bent ray does; the board (and so the truth) stays
the emitting layer. Without glass (or thickness 0) the straight-ray code
runs unchanged.
"""

from __future__ import annotations

import math

import cv2
import mrcal
import numpy as np
import scipy.sparse

from rotstar_mrcal.optics.refraction import Glass, emitting_hits
from rotstar_mrcal.simulate.camera import RayGrid, camera_rays, subpixel_rays
from rotstar_mrcal.optics.blur import as_psf, psf_radius
from rotstar_mrcal.simulate.screen import Screen

MIN_BOX = 1e-3
"""Smallest box side in display pixels (area sampling where the footprint is unknown)"""

CHUNK = 1 << 17
"""Sub-pixels per sparse-matrix block"""


def board_hits(d_cam: np.ndarray, rt_cam_board: np.ndarray, layout,
               glass: Glass | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Screen coordinates (u, v) where camera rays d_cam (..., 3) meet the board plane

    NaN where the ray misses the plane, runs away from it, or the camera is
    behind the screen (on the +z side of the board). With glass, the rays
    are refracted at its surface on their way (optics.refraction).

    SYNOPSIS

        >>> from rotstar_mrcal.pattern.layout import make_layout
        >>> layout = make_layout(screen=(800, 600), pitch=100, band=24)
        >>> u, v = board_hits(np.array((0., 0., 1.)), np.array((0, 0, 0, 0, 0, 0.2)), layout)
        >>> float(u), float(v)                  # the optical axis hits corner (0, 0)
        (150.0, 150.0)
    """
    R = mrcal.R_from_r(rt_cam_board[:3])
    c = -R.T @ rt_cam_board[3:]  # camera centre, board frame
    if glass is not None and not glass.none:
        xy = emitting_hits(c, d_cam @ R, glass)  # metres on the emitting layer
        return (xy[..., 0] / layout.pixel_pitch_m + layout.origin[0],
                xy[..., 1] / layout.pixel_pitch_m + layout.origin[1])
    if not c[2] < 0:
        nan = np.full(np.shape(d_cam)[:-1], np.nan)
        return nan, nan.copy()
    db = d_cam @ (R / layout.pixel_pitch_m)  # directions in the board frame, display pixels
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = np.negative(c[2] / layout.pixel_pitch_m) / db[..., 2]
        lam = np.where(lam > 0, lam, np.nan)  # misses, runs away from the plane, NaN rays
        u = lam * db[..., 0] + (c[0] / layout.pixel_pitch_m + layout.origin[0])
        v = lam * db[..., 1] + (c[1] / layout.pixel_pitch_m + layout.origin[1])
    return u, v


def screen_roi(grid: RayGrid, rt_cam_board, layout, margin_px: float, glass: Glass | None = None):
    """(x0, y0, x1, y1) camera pixels to trace, or None if the screen is not seen

    The pixels whose centre ray lands on the screen, grown by 1 + margin_px
    and clipped to what the ray grid can interpolate.
    """
    u, v = board_hits(grid.rays, rt_cam_board, layout, glass)
    on = (u >= 0) & (u <= layout.screen_width) & (v >= 0) & (v <= layout.screen_height)
    rows = np.flatnonzero(on.any(axis=1))
    cols = np.flatnonzero(on.any(axis=0))
    if rows.size == 0:
        return None
    m = 1 + int(math.ceil(margin_px))
    p = grid.pad
    x0 = max(cols[0] - p - m, 1 - p)
    y0 = max(rows[0] - p - m, 1 - p)
    x1 = min(cols[-1] - p + 1 + m, grid.width + p - 1)
    y1 = min(rows[-1] - p + 1 + m, grid.height + p - 1)
    return x0, y0, x1, y1


def _taps(a0: np.ndarray, a1: np.ndarray, n: int):
    """Summed-area-table taps of the interval [a0, a1] clipped to [0, n]"""
    a0 = np.clip(a0, 0, n)
    a1 = np.clip(a1, 0, n)
    i0 = np.minimum(a0.astype(np.int32), n - 1)
    i1 = np.minimum(a1.astype(np.int32), n - 1)
    f0 = a0 - i0
    f1 = a1 - i1
    return np.stack((i0, i0 + 1, i1, i1 + 1), axis=-1), np.stack((f0 - 1, -f0, 1 - f1, f1), axis=-1)


def box_matrix(u0, u1, v0, v1, width: int, height: int) -> scipy.sparse.csr_array:
    """Sparse (n, (height+1)*(width+1)) map from a summed-area table to box means

    Row k averages the screen over [u0, u1] x [v0, v1] (display pixels); the
    part of the box off the screen contributes 0 (the table holds frame - room).
    """
    n = len(u0)
    area = (u1 - u0) * (v1 - v0)
    cols, cw = _taps(u0, u1, width)
    rows, rw = _taps(v0, v1, height)
    idx = rows[:, :, None] * np.int32(width + 1) + cols[:, None, :]
    data = rw[:, :, None] * cw[:, None, :] / area[:, None, None]
    indptr = np.arange(0, 16 * n + 1, 16, dtype=np.int32 if 16 * n < 2**31 else np.int64)
    return scipy.sparse.csr_array(
        (data.reshape(-1), idx.reshape(-1), indptr), shape=(n, (height + 1) * (width + 1))
    )


def sample_screen(screen: Screen, u: np.ndarray, v: np.ndarray, frames=None, sampling: str = "area") -> np.ndarray:
    """Luminance seen at screen points (u, v) of shape (H, W), every frame: (k, H, W) float32

    u, v are a regular grid of sample points (one per sub-pixel, NaN = no
    hit); with sampling="area" each sample is the exact mean over its box
    footprint (see the module docstring), with "point" the display pixel it
    lands in.
    """
    Ws, Hs = screen.width, screen.height
    S2 = screen.sat.reshape(-1, screen.nframes)
    if frames is not None and len(frames) != screen.nframes:
        S2 = np.ascontiguousarray(S2[:, frames])
    k = S2.shape[1]
    if sampling == "area":
        gu = np.gradient(u)
        gv = np.gradient(v)
        wu = np.hypot(gu[0], gu[1])
        wv = np.hypot(gv[0], gv[1])
        wu = np.where(np.isfinite(wu), np.maximum(wu, MIN_BOX), MIN_BOX)
        wv = np.where(np.isfinite(wv), np.maximum(wv, MIN_BOX), MIN_BOX)
        u0, u1 = u - wu / 2, u + wu / 2
        v0, v1 = v - wv / 2, v + wv / 2
    elif sampling == "point":
        u0, v0 = np.floor(u), np.floor(v)
        u1, v1 = u0 + 1, v0 + 1
    else:
        raise ValueError(f"sampling must be 'area' or 'point', not {sampling!r}")
    with np.errstate(invalid="ignore"):
        inside = (u1 > 0) & (u0 < Ws) & (v1 > 0) & (v0 < Hs)
    idx = np.flatnonzero(inside)
    u0, u1, v0, v1 = (a.reshape(-1)[idx] for a in (u0, u1, v0, v1))
    acc = np.zeros((u.size, k), np.float32)
    for a in range(0, idx.size, CHUNK):
        b = slice(a, a + CHUNK)
        acc[idx[b]] = box_matrix(u0[b], u1[b], v0[b], v1[b], Ws, Hs) @ S2
    acc += screen.room
    return np.moveaxis(acc, -1, 0).reshape((k,) + u.shape)


def block_average(sub: np.ndarray, s: int) -> np.ndarray:
    """Average s x s blocks: (..., H*s, W*s) -> (..., H, W)"""
    *lead, Hs_, Ws_ = sub.shape
    flat = sub.reshape((-1, Hs_, Ws_))
    out = np.empty((flat.shape[0], Hs_ // s, Ws_ // s), sub.dtype)
    for n in range(flat.shape[0]):
        # INTER_AREA with an integer factor is the exact block mean
        out[n] = cv2.resize(flat[n], (Ws_ // s, Hs_ // s), interpolation=cv2.INTER_AREA)
    return out.reshape(*lead, Hs_ // s, Ws_ // s)


def _pose_groups(rt: np.ndarray, nframes: int):
    if rt.shape == (6,):
        return [(rt, None)]
    if rt.shape != (nframes, 6):
        raise ValueError(f"rt_cam_board must have shape (6,) or ({nframes}, 6), not {rt.shape}")
    uniq, inv = np.unique(rt, axis=0, return_inverse=True)
    return [(uniq[g], np.flatnonzero(inv.reshape(-1) == g)) for g in range(len(uniq))]


def render_irradiance(
    screen: Screen,
    model: mrcal.cameramodel,
    rt_cam_board,
    *,
    supersample: int = 4,
    psf=1.0,
    sampling: str = "area",
    rays: RayGrid | None = None,
    glass: Glass | None = None,
) -> np.ndarray:
    """Camera images of every screen frame, (nframes, H, W) float64 irradiance

    Irradiance is in screen luminance units (white screen seen head-on = 1).
    psf: see optics.as_psf (default: Gaussian of sigma 1 camera pixel). rays:
    the camera's RayGrid (default: camera.camera_rays(model), cached).
    glass: a cover glass over the emitting layer (module doc; default none).
    """
    s = int(supersample)
    if s < 1:
        raise ValueError("supersample must be >= 1")
    rt = np.asarray(rt_cam_board, float)
    grid = camera_rays(model) if rays is None else rays
    W, H = grid.width, grid.height
    op = as_psf(psf, s)
    out = np.full((screen.nframes, H, W), screen.room)
    for rt_g, frames in _pose_groups(rt, screen.nframes):
        roi = screen_roi(grid, rt_g, screen.layout, psf_radius(op, s), glass)
        if roi is None:
            continue
        x0, y0, x1, y1 = roi
        u, v = board_hits(subpixel_rays(grid, x0, y0, x1, y1, s), rt_g, screen.layout, glass)
        sub = sample_screen(screen, u, v, frames, sampling)
        px = op.pixels(sub, (x0, y0), s) if hasattr(op, "pixels") else block_average(op(sub, (x0, y0), s), s)
        cx0, cy0, cx1, cy1 = max(x0, 0), max(y0, 0), min(x1, W), min(y1, H)
        if cx1 <= cx0 or cy1 <= cy0:
            continue
        tile = px[:, cy0 - y0 : cy1 - y0, cx0 - x0 : cx1 - x0]
        if frames is None:
            out[:, cy0:cy1, cx0:cx1] = tile
        else:
            out[frames, cy0:cy1, cx0:cx1] = tile
    return out

"""Camera presets and the per-camera cache of pixel rays

SYNOPSIS

    >>> from rotstar_mrcal.simulate.camera import preset_model, camera_rays, fov_deg
    >>> model = preset_model("d435")
    >>> model.intrinsics()[0], tuple(int(v) for v in model.imagersize())
    ('LENSMODEL_OPENCV8', (1280, 800))
    >>> fov_deg(preset_model("wide")).round(1)  # horizontal, vertical, diagonal
    array([111.5,  79. , 122.9])
    >>> grid = camera_rays(preset_model("pinhole-small"))   # unprojected once, then cached
    >>> grid.rays.shape                      # (H + 2 pad, W + 2 pad, 3)
    (416, 656, 3)

The renderer needs one ray per supersampled camera sub-pixel. mrcal.unproject
costs a few microseconds per point, so it is called once per camera, at every
camera *pixel centre* of the image grown by `pad` pixels on each side (the
margin lets the PSF see light from just outside the imager). Sub-pixel rays are
interpolated bilinearly from this grid (`subpixel_rays`). For models whose rays
all point forward the grid stores v / v_z (the normalised image plane), so the
interpolation is exact for a pinhole model; the OpenCV distortion terms vary on
a scale of hundreds of pixels and the interpolation error is ~1e-4 px. Wider
models (some ray with v_z <= 0.1 |v|) store unit vectors instead.

The grid is cached per (lens model, intrinsics, imager size, pad) in a small
LRU, so many poses rendered with one camera unproject once.

Presets are the rows of PRESETS; add a row to add a camera.
"""

from __future__ import annotations

import collections
import dataclasses

import cv2
import mrcal
import numpy as np

RAY_PAD = 8
"""Pixels of rays kept outside the imager on each side (the PSF margin limit)"""

PRESETS: dict[str, dict] = {
    # Intel RealSense D435, left IR imager in 1280x800 (Y16) mode: typical
    # units have fx = fy ~ 640 and a centre near the middle of the imager.
    # The lens is close to distortion-free; the mild OPENCV8 terms here make
    # the simulation exercise a real distortion fit. The radial map is
    # monotonic out to r = 1.85 in normalised units (the image corners are at
    # r = 1.18, where d r_distorted / d r = 0.99): no fold inside the image.
    "d435": dict(
        lensmodel="LENSMODEL_OPENCV8",
        imagersize=(1280, 800),
        # fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, k5, k6
        intrinsics=(640.0, 640.0, 638.5, 401.0, -0.05, 0.04, 5e-4, -3e-4, -0.01, 0.0, 0.0, 0.0),
        description="Intel RealSense D435 left IR, 1280x800 Y16, mild OPENCV8 distortion",
    ),
    # A wide-angle lens, ~112 degrees across the 1280 px width (79 across the
    # height, 123 on the diagonal), with strong barrel distortion from the
    # rational terms: r_d = r (1 + k1 r^2 + k2 r^4) / (1 + k4 r^2) shrinks the
    # image edge to 0.84 and the corners to 0.79 of a pinhole's. The radial
    # map is monotonic for every r (d r_d / d r > 0 as 3 k1 > k4), so it never
    # folds; the image corners are at r = 1.84 (61 degrees off axis).
    "wide": dict(
        lensmodel="LENSMODEL_OPENCV8",
        imagersize=(1280, 800),
        # fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, k5, k6
        intrinsics=(520.0, 520.0, 641.0, 398.5, 0.1, 0.002, 2e-4, -1e-4, 0.0, 0.2137, 0.0, 0.0),
        description="wide-angle, 1280x800, ~112 degrees horizontal, strong barrel OPENCV8 distortion",
    ),
    # A small pinhole camera for tests and quick experiments
    "pinhole-small": dict(
        lensmodel="LENSMODEL_PINHOLE",
        imagersize=(640, 400),
        intrinsics=(320.0, 320.0, 319.5, 199.5),
        description="640x400 pinhole, fx = fy = 320, centred",
    ),
}


def preset_model(name: str) -> mrcal.cameramodel:
    """The mrcal.cameramodel of a preset (see PRESETS)

    SYNOPSIS

        >>> preset_model("d435").intrinsics()[1][:4]
        array([640. , 640. , 638.5, 401. ])
    """
    try:
        p = PRESETS[name]
    except KeyError:
        raise ValueError(f"unknown camera preset {name!r}; known: {', '.join(PRESETS)}") from None
    return mrcal.cameramodel(
        intrinsics=(p["lensmodel"], np.array(p["intrinsics"], float)),
        imagersize=np.array(p["imagersize"]),
    )


def fov_deg(model: mrcal.cameramodel) -> np.ndarray:
    """Field of view (horizontal, vertical, diagonal), degrees: the angles between opposite image edges' rays

    Through the principal point for the horizontal and vertical ones; corner
    to corner for the diagonal.
    """
    W, H = (float(v) for v in model.imagersize())
    cx, cy = model.intrinsics()[1][2:4]
    q = np.array(((-0.5, cy), (W - 0.5, cy), (cx, -0.5), (cx, H - 0.5), (-0.5, -0.5), (W - 0.5, H - 0.5)))
    v = mrcal.unproject(q, *model.intrinsics(), normalize=True).reshape(3, 2, 3)
    return np.degrees(np.arccos(np.clip(np.sum(v[:, 0] * v[:, 1], axis=-1), -1, 1)))


@dataclasses.dataclass(frozen=True)
class RayGrid:
    """Rays through the pixel centres of an imager grown by `pad` pixels

    rays[y + pad, x + pad] is the camera-frame direction seen by pixel (x, y)
    (mrcal image coordinates); NaN where the model cannot unproject.
    """

    rays: np.ndarray  # (H + 2 pad, W + 2 pad, 3) float64
    pad: int
    width: int
    height: int


_CACHE: collections.OrderedDict = collections.OrderedDict()
_CACHE_SIZE = 4


def _model_key(model: mrcal.cameramodel, pad: int):
    lensmodel, intrinsics = model.intrinsics()
    return (lensmodel, np.asarray(intrinsics, float).tobytes(), tuple(int(v) for v in model.imagersize()), pad)


def unproject_grid(model: mrcal.cameramodel, pad: int = RAY_PAD) -> RayGrid:
    """Unproject every pixel centre of the grown imager (uncached; see camera_rays)"""
    W, H = (int(v) for v in model.imagersize())
    y, x = np.mgrid[-pad : H + pad, -pad : W + pad].astype(float)
    v = mrcal.unproject(np.stack((x, y), axis=-1), *model.intrinsics(), normalize=True)
    if np.nanmin(v[..., 2]) > 0.1:
        v = v / v[..., 2:]
    return RayGrid(rays=v, pad=pad, width=W, height=H)


def camera_rays(model: mrcal.cameramodel, pad: int = RAY_PAD) -> RayGrid:
    """The RayGrid of a camera, from the cache or unprojected now"""
    key = _model_key(model, pad)
    if key in _CACHE:
        _CACHE.move_to_end(key)
        return _CACHE[key]
    grid = unproject_grid(model, pad)
    remember_rays(model, grid)
    return grid


def remember_rays(model: mrcal.cameramodel, grid: RayGrid) -> None:
    """Put a RayGrid computed elsewhere (e.g. in a parent process) into the cache"""
    _CACHE[_model_key(model, grid.pad)] = grid
    _CACHE.move_to_end(_model_key(model, grid.pad))
    while len(_CACHE) > _CACHE_SIZE:
        _CACHE.popitem(last=False)


def subpixel_positions(n: int, start: int, s: int) -> np.ndarray:
    """Image coordinates of the centres of n*s sub-pixels starting at pixel `start`

    SYNOPSIS

        >>> subpixel_positions(1, 10, 4)
        array([ 9.625,  9.875, 10.125, 10.375])
    """
    return start - 0.5 + (np.arange(n * s) + 0.5) / s


def subpixel_rays(grid: RayGrid, x0: int, y0: int, x1: int, y1: int, s: int) -> np.ndarray:
    """Rays of the s x s sub-pixels of camera pixels [x0, x1) x [y0, y1)

    Returns ((y1-y0)*s, (x1-x0)*s, 3), interpolated bilinearly between pixel
    centres (cv2.resize INTER_LINEAR puts destination sample D at source
    coordinate (D + 0.5)/s - 0.5: exactly the sub-pixel centres); needs
    -pad < x0, x1 < W + pad (and likewise in y).
    """
    p = grid.pad
    if not (x0 - 1 >= -p and y0 - 1 >= -p and x1 + 1 <= grid.width + p and y1 + 1 <= grid.height + p):
        raise ValueError(f"ROI [{x0},{x1})x[{y0},{y1}) needs rays outside the cached grid (pad {p})")
    block = grid.rays[y0 - 1 + p : y1 + 1 + p, x0 - 1 + p : x1 + 1 + p]
    h, w = block.shape[:2]
    up = cv2.resize(block, (w * s, h * s), interpolation=cv2.INTER_LINEAR)
    return up[s : (h - 1) * s, s : (w - 1) * s]

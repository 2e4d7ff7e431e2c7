"""A colour camera's frames as grey images (the D435's RGB camera as a third calibration camera)

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.capture.colour import to_grey, pack_yuyv
    >>> y = np.array([[10, 20, 30, 40]], np.uint8)
    >>> raw = pack_yuyv(y, u=128, v=128)          # Y0 U Y1 V Y2 U Y3 V
    >>> raw.tolist()
    [[10, 128, 20, 128, 30, 128, 40, 128]]
    >>> to_grey("YUYV", raw, 4, 1).tolist()
    [[10, 20, 30, 40]]

The grey image of a YUV frame is its luma, Y (the camera's own weighting
of R, G and B, BT.601 on UVC cameras): the chroma is dropped, nothing is
resampled, so the geometry is the sensor's. YUYV carries Y in bytes 0 and
2 of every 4, UYVY in bytes 1 and 3. MJPG frames are decoded by OpenCV
straight to grey (IMREAD_GRAYSCALE: libjpeg's luma); JPEG is lossy, so
prefer YUYV where the camera offers the size. The result is uint8, full
scale 255, like a GREY stream.
"""

from __future__ import annotations

import cv2
import numpy as np

COLOUR_FORMATS = ("YUYV", "UYVY", "MJPG")


class ColourError(ValueError):
    """A colour frame that cannot be read; the message says which and why"""


def to_grey(code: str, raw: np.ndarray, width: int, height: int) -> np.ndarray:
    """A YUYV / UYVY frame's bytes (height, width * 2) or an MJPG buffer -> (height, width) uint8 luma"""
    code = (code + "    ")[:4]
    if code in ("YUYV", "UYVY"):
        raw = np.asarray(raw, np.uint8)
        if raw.shape != (height, width * 2):
            raise ColourError(f"{code} {width}x{height}: {raw.shape[1] if raw.ndim == 2 else raw.size} bytes a "
                              f"line, needs {width * 2}")
        return np.ascontiguousarray(raw[:, 0 if code == "YUYV" else 1 :: 2])
    if code == "MJPG":
        img = cv2.imdecode(np.asarray(raw, np.uint8).reshape(-1), cv2.IMREAD_GRAYSCALE)
        if img is None:
            raise ColourError(f"MJPG {width}x{height}: a frame that does not decode ({np.size(raw)} bytes)")
        if img.shape != (height, width):
            raise ColourError(f"MJPG: a {img.shape[1]}x{img.shape[0]} frame in a {width}x{height} stream")
        return img
    raise ColourError(f"{code.strip()!r} is not a colour format this tool reads ({', '.join(COLOUR_FORMATS)})")


def pack_yuyv(y: np.ndarray, u=128, v=128, code: str = "YUYV") -> np.ndarray:
    """The reference packing of a luma image (even width) with constant or per-pair chroma -> (H, W * 2) uint8"""
    y = np.asarray(y, np.uint8)
    h, w = y.shape
    if w % 2:
        raise ColourError(f"{code} needs an even width, not {w}")
    uv = np.empty((h, w), np.uint8)
    uv[:, 0::2], uv[:, 1::2] = np.broadcast_to(u, (h, w // 2)), np.broadcast_to(v, (h, w // 2))
    pair = (y, uv) if code == "YUYV" else (uv, y)
    return np.stack(pair, -1).reshape(h, 2 * w)

"""The D4xx stereo formats: one buffer holding the left and the right infrared imager

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.capture.interleaved import pack_y12i, unpack_y12i, pack_y8i, unpack_y8i
    >>> left = np.array([[0xABC, 0x000]], np.uint16); right = np.array([[0x123, 0xFFF]], np.uint16)
    >>> buf = pack_y12i(left, right)
    >>> buf.tobytes().hex()                      # 3 bytes a pixel: right's 12 bits low, left's high
    '23c1abff0f00'
    >>> l, r = unpack_y12i(buf, 2, 1)
    >>> [hex(v) for v in l[0]], [hex(v) for v in r[0]]
    (['0xabc', '0x0'], ['0x123', '0xfff'])
    >>> l, r = unpack_y8i(pack_y8i(np.uint8([[1, 2]]), np.uint8([[3, 4]])), 2, 1)
    >>> l.tolist(), r.tolist()
    ([[1, 2]], [[3, 4]])

Y12I ('Y12I') is the D4xx's unrectified calibration stream of both imagers
(1280x800 and 640x400, the sizes and rates of Y16): every pixel is one
24-bit little-endian word, w = b0 | b1 << 8 | b2 << 16, holding two 12-bit
values. Which half is the left imager, the sources disagree:

    librealsense (src/proc/y12i-to-y16y16.cpp, and every version since the
    legacy rsimpl image.cpp): struct y12i_pixel { rl:8, rh:4, ll:4, lh:8 },
    left = lh << 4 | ll, right = rh << 8 | rl: the RIGHT imager in the low
    12 bits (b0 and the low nibble of b1), the LEFT in the high 12 bits
    (its MIPI variant, y12i-to-y16y16-mipi.cpp for the D457, has the same
    bits and one byte of padding a pixel: not a USB D435's format);

    the kernel's description (Documentation/userspace-api/media/v4l/
    pixfmt-y12i.rst: "left0 = 0xfff & *(__u16 *)buf; right0 = *(__u16
    *)(buf + 1) >> 4"): the LEFT in the low 12 bits.

We follow librealsense, the code that reads this stream from D4xx cameras
every day; the kernel text is the generic description of the fourcc. The
choice is one line, Y12I_LEFT below; doc/capture.md says how to check it on
a real camera (cover one lens: the output that goes dark is that imager).
librealsense also treats the 12 bits as 10-bit data ("y12i_10": it scales
by 64 + 1/16); we keep the values as they come, raw 12-bit numbers in
uint16 words, like the D435's Y16 frames, and pose.value_scale scales a
stream that only reaches 10 or 12 bits up to 16 when the averages are
written (as for Y16: the value range seen is logged).

Y8I ('Y8I '), 8-bit and rectified by the camera: one 16-bit word a pixel,
the left imager in the low byte (byte 0), the right in the high byte
(byte 1); the kernel (pixfmt-y8i.rst) and librealsense (struct y8i_pixel
{ l, r }) agree. Rectified frames describe the camera's virtual rectified
pair, not the lenses: for a quick look only.

Buffers may carry padding at the end of every line (bytesperline); a buffer
of the wrong length raises InterleavedError naming the size and the format.
"""

from __future__ import annotations

import numpy as np

Y12I_LEFT = "high"  # librealsense's layout; the kernel's pixfmt-y12i text says "low" (see above)

BYTES_PER_PIXEL = {"Y12I": 3, "Y8I ": 2}


class InterleavedError(ValueError):
    """A buffer that does not hold a whole interleaved frame; the message says which and why"""


def y12i_halves(words: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """24-bit Y12I words -> (left, right) 12-bit values, per Y12I_LEFT

    SYNOPSIS

        >>> [hex(int(v[0])) for v in y12i_halves(np.array([0xABC123]))]
        ['0xabc', '0x123']
    """
    low, high = words & 0xFFF, words >> 12
    return (high, low) if Y12I_LEFT == "high" else (low, high)


def _rows(buf, width: int, height: int, bpp: int, code: str, bytesperline: int | None) -> np.ndarray:
    """(height, width * bpp) uint8: the image bytes of a buffer, line padding dropped"""
    a = np.frombuffer(buf, np.uint8) if not isinstance(buf, np.ndarray) else np.ascontiguousarray(buf).reshape(-1).view(np.uint8)
    bpl = bytesperline or width * bpp
    if bpl < width * bpp:
        raise InterleavedError(f"{code.strip()} {width}x{height}: {bpl} bytes per line, a line needs {width * bpp}")
    need, total = bpl * (height - 1) + width * bpp, bpl * height
    if not need <= a.size <= total:
        raise InterleavedError(f"{code.strip()} {width}x{height}: the buffer holds {a.size} bytes, a frame needs "
                               f"{total} ({bpp} bytes a pixel" + (f", {bpl} a line" if bytesperline else "") + ")")
    if a.size < total:  # the last line may come without its padding
        a = np.concatenate([a, np.zeros(total - a.size, np.uint8)])
    return a.reshape(height, bpl)[:, : width * bpp]


def unpack_y12i(buf, width: int, height: int, bytesperline: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A Y12I buffer -> (left, right), each (height, width) uint16 of raw 12-bit values; see the module doc"""
    b = _rows(buf, width, height, 3, "Y12I", bytesperline).reshape(height, width, 3).astype(np.uint32)
    left, right = y12i_halves(b[..., 0] | b[..., 1] << 8 | b[..., 2] << 16)
    return left.astype(np.uint16), right.astype(np.uint16)


def unpack_y8i(buf, width: int, height: int, bytesperline: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A Y8I buffer -> (left, right), each (height, width) uint8; left is byte 0 of each pixel"""
    b = _rows(buf, width, height, 2, "Y8I ", bytesperline).reshape(height, width, 2)
    return np.ascontiguousarray(b[..., 0]), np.ascontiguousarray(b[..., 1])


def pack_y12i(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """The reference packing: (left, right) 12-bit images -> (height, width * 3) uint8, per Y12I_LEFT"""
    left, right = np.asarray(left, np.uint32), np.asarray(right, np.uint32)
    if left.shape != right.shape or left.ndim != 2:
        raise InterleavedError(f"left {left.shape} and right {right.shape} must be images of one size")
    if max(int(left.max(initial=0)), int(right.max(initial=0))) > 0xFFF:
        raise InterleavedError("Y12I holds 12-bit values (0-4095)")
    hi, lo = (left, right) if Y12I_LEFT == "high" else (right, left)
    w = lo | hi << 12
    return np.stack([w & 0xFF, (w >> 8) & 0xFF, w >> 16], -1).astype(np.uint8).reshape(left.shape[0], -1)


def pack_y8i(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """The reference packing: (left, right) uint8 images -> (height, width * 2) uint8"""
    left, right = np.asarray(left), np.asarray(right)
    if left.shape != right.shape or left.ndim != 2:
        raise InterleavedError(f"left {left.shape} and right {right.shape} must be images of one size")
    return np.stack([left, right], -1).astype(np.uint8).reshape(left.shape[0], -1)


def unpack(code: str, buf, width: int, height: int, bytesperline: int | None = None):
    """unpack_y12i or unpack_y8i by fourcc

    SYNOPSIS

        >>> [a.dtype.name for a in unpack("Y8I", bytes(8), 2, 2)]
        ['uint8', 'uint8']
    """
    code = (code + "    ")[:4]
    if code == "Y12I":
        return unpack_y12i(buf, width, height, bytesperline)
    if code == "Y8I ":
        return unpack_y8i(buf, width, height, bytesperline)
    raise InterleavedError(f"{code.strip()!r} is not an interleaved stereo format (Y12I, Y8I)")

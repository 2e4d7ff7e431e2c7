"""A small V4L2 layer: ctypes structures, ioctl numbers, a Device with mmap streaming

SYNOPSIS

    from rotstar_mrcal.capture.v4l2 import Device, fourcc
    with Device("/dev/video2") as dev:
        print(dev.querycap().card, [f.fourcc for f in dev.formats()])
        fmt = dev.set_format(1280, 800, "Y16 ")
        dev.set_fps(25)
        dev.start(nbuffers=4)
        frame = dev.read(timeout=2.0)          # RawFrame: .image (800, 1280) uint16, .sequence
        dev.stop()

Only what a calibration capture needs: capabilities, the format list with
sizes and frame rates, format negotiation, the simple controls
(VIDIOC_QUERYCTRL / G_CTRL / S_CTRL and menus), and memory-mapped streaming
that returns each frame as a numpy array in the device's own units (GREY ->
uint8, Y16 -> uint16, Y8I -> the left imager's uint8; no colour conversion,
no scaling). Packed formats (PACKED_FORMATS: Y12I, the D4xx's two 12-bit
imagers in 3 bytes; YUYV, UYVY) come as their bytes, (height, width *
bytes a pixel) uint8, compressed ones (MJPG) as the buffer's bytes: the
stereo split is interleaved.py's, the colour conversion colour.py's.
Vendor extension-unit controls are in uvc_xu.py.

All system calls go through a Syscalls object (open, close, ioctl, mmap,
select), so tests replace the kernel with a fake device at exactly this
boundary. The structures follow <linux/videodev2.h> for 64-bit Linux; their
sizes are encoded in the ioctl numbers, and the numbers are checked against
the kernel's (e.g. VIDIOC_QUERYCAP = 0x80685600, VIDIOC_DQBUF = 0xc0585611).
"""

from __future__ import annotations

import ctypes as C
import dataclasses
import errno
import mmap
import os
import select

import numpy as np

# ---- ioctl numbers -----------------------------------------------------------
_IOC_WRITE, _IOC_READ = 1, 2


def _IOC(direction: int, kind: str, nr: int, size: int) -> int:
    return (direction << 30) | (size << 16) | (ord(kind) << 8) | nr


def _IOR(kind, nr, struct):
    return _IOC(_IOC_READ, kind, nr, C.sizeof(struct))


def _IOW(kind, nr, struct):
    return _IOC(_IOC_WRITE, kind, nr, C.sizeof(struct))


def _IOWR(kind, nr, struct):
    return _IOC(_IOC_READ | _IOC_WRITE, kind, nr, C.sizeof(struct))


def fourcc(code: str) -> int:
    """'Y16 ' -> the little-endian V4L2 pixel format number

    SYNOPSIS

        >>> hex(fourcc("GREY")), fourcc_str(fourcc("Y16"))
        ('0x59455247', 'Y16 ')
    """
    code = (code + "    ")[:4]
    return int.from_bytes(code.encode("ascii"), "little")


def fourcc_str(v: int) -> str:
    return int(v).to_bytes(4, "little").decode("ascii", "replace")


# ---- constants ---------------------------------------------------------------
BUF_TYPE_VIDEO_CAPTURE = 1
MEMORY_MMAP = 1
FIELD_NONE = 1
CAP_VIDEO_CAPTURE = 0x00000001
CAP_META_CAPTURE = 0x00800000
CAP_STREAMING = 0x04000000
CAP_DEVICE_CAPS = 0x80000000
FRMSIZE_TYPE_DISCRETE = 1
FRMIVAL_TYPE_DISCRETE = 1
BUF_FLAG_ERROR = 0x40
CTRL_FLAG_DISABLED = 0x0001
CTRL_FLAG_NEXT_CTRL = 0x80000000
CTRL_TYPE_INTEGER, CTRL_TYPE_BOOLEAN, CTRL_TYPE_MENU = 1, 2, 3
CTRL_TYPE_CTRL_CLASS = 6
CTRL_TYPE_INTEGER_MENU = 9
CAP_TIMEPERFRAME = 0x1000

CID_BASE = 0x00980900
CID_GAIN = CID_BASE + 19
CID_CAMERA_CLASS_BASE = 0x009A0900
CID_EXPOSURE_AUTO = CID_CAMERA_CLASS_BASE + 1  # menu: 1 = manual
CID_EXPOSURE_ABSOLUTE = CID_CAMERA_CLASS_BASE + 2  # 100 us units
EXPOSURE_MANUAL = 1

PIXEL_FORMATS = {
    # fourcc: (numpy dtype, samples per pixel, description)
    "GREY": ("u1", 1, "8-bit grey (D4xx: left IR, rectified by the camera)"),
    "Y16 ": ("<u2", 1, "16-bit grey (D4xx: left IR, unrectified calibration stream)"),
    "Y10 ": ("<u2", 1, "10-bit grey in 16-bit words"),
    "Y12 ": ("<u2", 1, "12-bit grey in 16-bit words"),
    "Y8I ": ("u1", 2, "8-bit left + right interleaved (D4xx, rectified); the left is kept"),
    "Z16 ": ("<u2", 1, "16-bit depth (not an image to calibrate from)"),
}
PACKED_FORMATS = {
    # fourcc: (bytes a pixel, description); read as raw bytes, converted by the backend
    "Y12I": (3, "12-bit left + right packed in 3 bytes (D4xx, unrectified calibration stream)"),
    "YUYV": (2, "colour, 4:2:2 Y U Y V"),
    "UYVY": (2, "colour, 4:2:2 U Y V Y"),
}
COMPRESSED_FORMATS = {"MJPG": "colour, motion JPEG"}


def bytes_per_pixel(code: str) -> int:
    """Bytes a pixel of a fourcc this layer reads (0 for compressed formats)

    SYNOPSIS

        >>> bytes_per_pixel("Y16"), bytes_per_pixel("Y8I"), bytes_per_pixel("Y12I"), bytes_per_pixel("MJPG")
        (2, 2, 3, 0)
    """
    code = (code + "    ")[:4]
    if code in PIXEL_FORMATS:
        dt, spp, _ = PIXEL_FORMATS[code]
        return spp * np.dtype(dt).itemsize
    if code in PACKED_FORMATS:
        return PACKED_FORMATS[code][0]
    return 0


# ---- structures (<linux/videodev2.h>, 64-bit) --------------------------------
class v4l2_capability(C.Structure):
    _fields_ = [("driver", C.c_char * 16), ("card", C.c_char * 32), ("bus_info", C.c_char * 32),
                ("version", C.c_uint32), ("capabilities", C.c_uint32), ("device_caps", C.c_uint32),
                ("reserved", C.c_uint32 * 3)]


class v4l2_fmtdesc(C.Structure):
    _fields_ = [("index", C.c_uint32), ("type", C.c_uint32), ("flags", C.c_uint32),
                ("description", C.c_char * 32), ("pixelformat", C.c_uint32), ("mbus_code", C.c_uint32),
                ("reserved", C.c_uint32 * 3)]


class v4l2_pix_format(C.Structure):
    _fields_ = [("width", C.c_uint32), ("height", C.c_uint32), ("pixelformat", C.c_uint32),
                ("field", C.c_uint32), ("bytesperline", C.c_uint32), ("sizeimage", C.c_uint32),
                ("colorspace", C.c_uint32), ("priv", C.c_uint32), ("flags", C.c_uint32),
                ("ycbcr_enc", C.c_uint32), ("quantization", C.c_uint32), ("xfer_func", C.c_uint32)]


class _v4l2_format_union(C.Union):
    # raw_data[200]; the kernel's union also holds struct v4l2_window (pointers: 8-byte alignment)
    _fields_ = [("pix", v4l2_pix_format), ("raw_data", C.c_uint8 * 200), ("_align", C.c_uint64)]


class v4l2_format(C.Structure):
    _fields_ = [("type", C.c_uint32), ("fmt", _v4l2_format_union)]


class v4l2_frmsize_discrete(C.Structure):
    _fields_ = [("width", C.c_uint32), ("height", C.c_uint32)]


class v4l2_frmsize_stepwise(C.Structure):
    _fields_ = [("min_width", C.c_uint32), ("max_width", C.c_uint32), ("step_width", C.c_uint32),
                ("min_height", C.c_uint32), ("max_height", C.c_uint32), ("step_height", C.c_uint32)]


class _frmsize_union(C.Union):
    _fields_ = [("discrete", v4l2_frmsize_discrete), ("stepwise", v4l2_frmsize_stepwise)]


class v4l2_frmsizeenum(C.Structure):
    _fields_ = [("index", C.c_uint32), ("pixel_format", C.c_uint32), ("type", C.c_uint32),
                ("u", _frmsize_union), ("reserved", C.c_uint32 * 2)]


class v4l2_fract(C.Structure):
    _fields_ = [("numerator", C.c_uint32), ("denominator", C.c_uint32)]


class v4l2_frmival_stepwise(C.Structure):
    _fields_ = [("min", v4l2_fract), ("max", v4l2_fract), ("step", v4l2_fract)]


class _frmival_union(C.Union):
    _fields_ = [("discrete", v4l2_fract), ("stepwise", v4l2_frmival_stepwise)]


class v4l2_frmivalenum(C.Structure):
    _fields_ = [("index", C.c_uint32), ("pixel_format", C.c_uint32), ("width", C.c_uint32),
                ("height", C.c_uint32), ("type", C.c_uint32), ("u", _frmival_union),
                ("reserved", C.c_uint32 * 2)]


class v4l2_captureparm(C.Structure):
    _fields_ = [("capability", C.c_uint32), ("capturemode", C.c_uint32), ("timeperframe", v4l2_fract),
                ("extendedmode", C.c_uint32), ("readbuffers", C.c_uint32), ("reserved", C.c_uint32 * 4)]


class _streamparm_union(C.Union):
    _fields_ = [("capture", v4l2_captureparm), ("raw_data", C.c_uint8 * 200)]


class v4l2_streamparm(C.Structure):
    _fields_ = [("type", C.c_uint32), ("parm", _streamparm_union)]


class v4l2_requestbuffers(C.Structure):
    _fields_ = [("count", C.c_uint32), ("type", C.c_uint32), ("memory", C.c_uint32),
                ("capabilities", C.c_uint32), ("flags", C.c_uint8), ("reserved", C.c_uint8 * 3)]


class timeval(C.Structure):
    _fields_ = [("tv_sec", C.c_long), ("tv_usec", C.c_long)]


class v4l2_timecode(C.Structure):
    _fields_ = [("type", C.c_uint32), ("flags", C.c_uint32), ("frames", C.c_uint8), ("seconds", C.c_uint8),
                ("minutes", C.c_uint8), ("hours", C.c_uint8), ("userbits", C.c_uint8 * 4)]


class _buffer_m(C.Union):
    _fields_ = [("offset", C.c_uint32), ("userptr", C.c_ulong), ("planes", C.c_void_p), ("fd", C.c_int32)]


class _buffer_tail(C.Union):
    _fields_ = [("request_fd", C.c_int32), ("reserved", C.c_uint32)]


class v4l2_buffer(C.Structure):
    _fields_ = [("index", C.c_uint32), ("type", C.c_uint32), ("bytesused", C.c_uint32), ("flags", C.c_uint32),
                ("field", C.c_uint32), ("timestamp", timeval), ("timecode", v4l2_timecode),
                ("sequence", C.c_uint32), ("memory", C.c_uint32), ("m", _buffer_m), ("length", C.c_uint32),
                ("reserved2", C.c_uint32), ("u", _buffer_tail)]


class v4l2_queryctrl(C.Structure):
    _fields_ = [("id", C.c_uint32), ("type", C.c_uint32), ("name", C.c_char * 32), ("minimum", C.c_int32),
                ("maximum", C.c_int32), ("step", C.c_int32), ("default_value", C.c_int32),
                ("flags", C.c_uint32), ("reserved", C.c_uint32 * 2)]


class v4l2_control(C.Structure):
    _fields_ = [("id", C.c_uint32), ("value", C.c_int32)]


class _querymenu_union(C.Union):
    _pack_ = 1
    _fields_ = [("name", C.c_char * 32), ("value", C.c_int64)]


class v4l2_querymenu(C.Structure):
    _pack_ = 1
    _fields_ = [("id", C.c_uint32), ("index", C.c_uint32), ("u", _querymenu_union), ("reserved", C.c_uint32)]


VIDIOC_QUERYCAP = _IOR("V", 0, v4l2_capability)
VIDIOC_ENUM_FMT = _IOWR("V", 2, v4l2_fmtdesc)
VIDIOC_G_FMT = _IOWR("V", 4, v4l2_format)
VIDIOC_S_FMT = _IOWR("V", 5, v4l2_format)
VIDIOC_REQBUFS = _IOWR("V", 8, v4l2_requestbuffers)
VIDIOC_QUERYBUF = _IOWR("V", 9, v4l2_buffer)
VIDIOC_QBUF = _IOWR("V", 15, v4l2_buffer)
VIDIOC_DQBUF = _IOWR("V", 17, v4l2_buffer)
VIDIOC_STREAMON = _IOW("V", 18, C.c_int)
VIDIOC_STREAMOFF = _IOW("V", 19, C.c_int)
VIDIOC_G_PARM = _IOWR("V", 21, v4l2_streamparm)
VIDIOC_S_PARM = _IOWR("V", 22, v4l2_streamparm)
VIDIOC_G_CTRL = _IOWR("V", 27, v4l2_control)
VIDIOC_S_CTRL = _IOWR("V", 28, v4l2_control)
VIDIOC_QUERYCTRL = _IOWR("V", 36, v4l2_queryctrl)
VIDIOC_QUERYMENU = _IOWR("V", 37, v4l2_querymenu)
VIDIOC_ENUM_FRAMESIZES = _IOWR("V", 74, v4l2_frmsizeenum)
VIDIOC_ENUM_FRAMEINTERVALS = _IOWR("V", 75, v4l2_frmivalenum)


# ---- the system-call boundary -------------------------------------------------
class Syscalls:
    """The kernel: what Device calls, and what tests replace with a fake device

    ioctl(fd, request, arg) mutates the ctypes object arg in place, like the
    kernel does; it raises OSError with the errno on failure.
    """

    def open(self, path: str) -> int:
        return os.open(path, os.O_RDWR | os.O_NONBLOCK)

    def close(self, fd: int) -> None:
        os.close(fd)

    def ioctl(self, fd: int, request: int, arg) -> None:
        import fcntl

        fcntl.ioctl(fd, request, arg, True)

    def mmap(self, fd: int, length: int, offset: int):
        return mmap.mmap(fd, length, mmap.MAP_SHARED, mmap.PROT_READ | mmap.PROT_WRITE, offset=offset)

    def select(self, fd: int, timeout: float) -> bool:
        r, _, _ = select.select([fd], [], [], timeout)
        return bool(r)


class V4L2Error(Exception):
    """A device that cannot do what was asked; the message says what and why"""


# ---- results -------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Capability:
    driver: str
    card: str
    bus_info: str
    capabilities: int
    device_caps: int

    @property
    def caps(self) -> int:
        return self.device_caps if self.capabilities & CAP_DEVICE_CAPS else self.capabilities

    @property
    def is_video_capture(self) -> bool:
        return bool(self.caps & CAP_VIDEO_CAPTURE)

    @property
    def can_stream(self) -> bool:
        return bool(self.caps & CAP_STREAMING)


@dataclasses.dataclass(frozen=True)
class FormatDesc:
    fourcc: str
    description: str
    flags: int


@dataclasses.dataclass(frozen=True)
class PixFormat:
    width: int
    height: int
    fourcc: str
    bytesperline: int
    sizeimage: int


@dataclasses.dataclass(frozen=True)
class Control:
    id: int
    name: str
    type: int
    minimum: int
    maximum: int
    step: int
    default: int
    flags: int
    menu: dict[int, str] = dataclasses.field(default_factory=dict)

    @property
    def disabled(self) -> bool:
        return bool(self.flags & CTRL_FLAG_DISABLED)


@dataclasses.dataclass
class RawFrame:
    image: np.ndarray  # (H, W) uint8 or uint16, a copy; packed: (H, W * bytes) uint8; compressed: (n,) uint8
    sequence: int  # the driver's frame counter: gaps are dropped frames
    timestamp_ns: int  # driver time stamp (uvcvideo: CLOCK_MONOTONIC)
    flags: int


def frame_array(data, fmt: PixFormat, bytesused: int | None = None) -> np.ndarray:
    """The image of one buffer as a (height, width) array, copied

    SYNOPSIS

        >>> fmt = PixFormat(4, 2, "Y16 ", 10, 20)     # 4 pixels + 2 bytes of padding per line
        >>> raw = bytes(range(20))
        >>> frame_array(raw, fmt).tolist()
        [[256, 770, 1284, 1798], [2826, 3340, 3854, 4368]]
    """
    if fmt.fourcc not in PIXEL_FORMATS:
        raise V4L2Error(f"pixel format {fmt.fourcc!r} is not supported here (supported: {', '.join(PIXEL_FORMATS)})")
    dtype, spp, _ = PIXEL_FORMATS[fmt.fourcc]
    dt = np.dtype(dtype)
    need = fmt.bytesperline * (fmt.height - 1) + fmt.width * spp * dt.itemsize
    n = len(data) if bytesused is None else min(bytesused, len(data))
    if n < need:
        raise V4L2Error(f"short frame: {n} bytes, a {fmt.width}x{fmt.height} {fmt.fourcc.strip()} image needs {need}")
    total = fmt.bytesperline * fmt.height
    buf = np.frombuffer(data, np.uint8, count=min(n, total))
    if len(buf) < total:  # the last line may come without its padding
        buf = np.concatenate([buf, np.zeros(total - len(buf), np.uint8)])
    rows = buf.reshape(fmt.height, fmt.bytesperline)[:, : fmt.width * spp * dt.itemsize]
    img = rows.copy().view(dt).reshape(fmt.height, fmt.width, spp)[..., 0]
    return np.ascontiguousarray(img)


def frame_bytes(data, fmt: PixFormat, bytesused: int | None = None) -> np.ndarray:
    """The bytes of one buffer of a packed format, (height, width * bytes a pixel) uint8, copied;
    of a compressed format, (bytesused,) uint8

    SYNOPSIS

        >>> frame_bytes(bytes(range(14)), PixFormat(2, 2, "Y12I", 7, 14)).tolist()   # 1 byte of padding a line
        [[0, 1, 2, 3, 4, 5], [7, 8, 9, 10, 11, 12]]
    """
    n = len(data) if bytesused is None else min(bytesused, len(data))
    if fmt.fourcc in COMPRESSED_FORMATS:
        if n == 0:
            raise V4L2Error(f"empty {fmt.fourcc.strip()} frame")
        return np.frombuffer(data, np.uint8, count=n).copy()
    if not bytes_per_pixel(fmt.fourcc):
        raise V4L2Error(f"pixel format {fmt.fourcc!r} is not supported here")
    row = fmt.width * bytes_per_pixel(fmt.fourcc)
    bpl = fmt.bytesperline or row
    need = bpl * (fmt.height - 1) + row
    if n < need:
        raise V4L2Error(f"short frame: {n} bytes, a {fmt.width}x{fmt.height} {fmt.fourcc.strip()} image needs {need}")
    buf = np.frombuffer(data, np.uint8, count=min(n, bpl * fmt.height))
    if len(buf) < bpl * fmt.height:
        buf = np.concatenate([buf, np.zeros(bpl * fmt.height - len(buf), np.uint8)])
    return buf.reshape(fmt.height, bpl)[:, :row].copy()


# ---- the device -----------------------------------------------------------------
class Device:
    """One V4L2 video node; see the module docstring"""

    def __init__(self, path: str, sys: Syscalls | None = None):
        self.path = path
        self.sys = sys or Syscalls()
        try:
            self.fd = self.sys.open(path)
        except OSError as e:
            raise V4L2Error(f"{path}: cannot open ({e.strerror}); is the camera plugged in, and may this user "
                            f"open it (group 'video')?") from None
        self.format: PixFormat | None = None
        self.raw_bytes = False  # read() returns every format's bytes (frame_bytes): both halves of Y8I
        self._buffers: list = []
        self._requested = False
        self._streaming = False

    def close(self) -> None:
        if self.fd is None:
            return
        try:
            if self._streaming:
                self.stop()
        finally:
            self._release_buffers()
            self.sys.close(self.fd)
            self.fd = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def ioctl(self, request: int, arg, what: str):
        try:
            self.sys.ioctl(self.fd, request, arg)
        except OSError as e:
            raise V4L2Error(f"{self.path}: {what}: {e.strerror or e}") from e
        return arg

    def _listed(self, request: int, arg, what: str) -> bool:
        """ioctl for one entry of a list the driver ends with EINVAL: False past the end"""
        try:
            self.sys.ioctl(self.fd, request, arg)
        except OSError as e:
            if e.errno == errno.EINVAL:
                return False
            raise V4L2Error(f"{self.path}: {what}: {e.strerror or e}") from e
        return True

    def _enum(self, request: int, make, what: str):
        """Call request with index 0, 1, ... until EINVAL"""
        out, i = [], 0
        while self._listed(request, arg := make(i), what):
            out.append(arg)
            i += 1
        return out

    # ---- what the device is ----------------------------------------------------
    def querycap(self) -> Capability:
        c = self.ioctl(VIDIOC_QUERYCAP, v4l2_capability(), "VIDIOC_QUERYCAP")
        return Capability(c.driver.decode(errors="replace"), c.card.decode(errors="replace"),
                          c.bus_info.decode(errors="replace"), c.capabilities, c.device_caps)

    def formats(self) -> list[FormatDesc]:
        def make(i):
            return v4l2_fmtdesc(index=i, type=BUF_TYPE_VIDEO_CAPTURE)

        return [FormatDesc(fourcc_str(f.pixelformat), f.description.decode(errors="replace"), f.flags)
                for f in self._enum(VIDIOC_ENUM_FMT, make, "VIDIOC_ENUM_FMT")]

    def frame_sizes(self, code: str) -> list[tuple[int, int]]:
        def make(i):
            return v4l2_frmsizeenum(index=i, pixel_format=fourcc(code))

        out = []
        for s in self._enum(VIDIOC_ENUM_FRAMESIZES, make, "VIDIOC_ENUM_FRAMESIZES"):
            if s.type == FRMSIZE_TYPE_DISCRETE:
                out.append((s.u.discrete.width, s.u.discrete.height))
            else:
                st = s.u.stepwise
                out += [(st.min_width, st.min_height), (st.max_width, st.max_height)]
                break
        return out

    def frame_rates(self, code: str, width: int, height: int) -> list[float]:
        def make(i):
            return v4l2_frmivalenum(index=i, pixel_format=fourcc(code), width=width, height=height)

        out = []
        for f in self._enum(VIDIOC_ENUM_FRAMEINTERVALS, make, "VIDIOC_ENUM_FRAMEINTERVALS"):
            fr = f.u.discrete if f.type == FRMIVAL_TYPE_DISCRETE else f.u.stepwise.min
            if fr.numerator:
                out.append(fr.denominator / fr.numerator)
        return sorted(set(out), reverse=True)

    def modes(self) -> dict[str, list[tuple[int, int, list[float]]]]:
        """{fourcc: [(width, height, [fps, ...]), ...]}: everything the node can stream"""
        return {f.fourcc: [(w, h, self.frame_rates(f.fourcc, w, h)) for w, h in self.frame_sizes(f.fourcc)]
                for f in self.formats()}

    # ---- format and frame rate --------------------------------------------------------
    def get_format(self) -> PixFormat:
        f = self.ioctl(VIDIOC_G_FMT, v4l2_format(type=BUF_TYPE_VIDEO_CAPTURE), "VIDIOC_G_FMT")
        p = f.fmt.pix
        return PixFormat(p.width, p.height, fourcc_str(p.pixelformat), p.bytesperline, p.sizeimage)

    def set_format(self, width: int, height: int, code: str) -> PixFormat:
        """Ask for a format; V4L2Error when the driver answers with another one"""
        code = (code + "    ")[:4]
        f = v4l2_format(type=BUF_TYPE_VIDEO_CAPTURE)
        f.fmt.pix.width, f.fmt.pix.height = width, height
        f.fmt.pix.pixelformat = fourcc(code)
        f.fmt.pix.field = FIELD_NONE
        self.ioctl(VIDIOC_S_FMT, f, f"VIDIOC_S_FMT {width}x{height} {code.strip()}")
        p = f.fmt.pix
        got = PixFormat(p.width, p.height, fourcc_str(p.pixelformat), p.bytesperline, p.sizeimage)
        if (got.width, got.height, got.fourcc) != (width, height, code):
            have = ", ".join(f"{k.strip()} " + " ".join(f"{w}x{h}" for w, h, _ in v) for k, v in self.modes().items())
            raise V4L2Error(f"{self.path}: asked for {width}x{height} {code.strip()}, the driver chose "
                            f"{got.width}x{got.height} {got.fourcc.strip()}; this node offers: {have or 'nothing'}")
        if got.bytesperline == 0 and code not in COMPRESSED_FORMATS:
            got = dataclasses.replace(got, bytesperline=width * (bytes_per_pixel(code) or 1))
        self.format = got
        return got

    def get_fps(self) -> float:
        p = self.ioctl(VIDIOC_G_PARM, v4l2_streamparm(type=BUF_TYPE_VIDEO_CAPTURE), "VIDIOC_G_PARM")
        t = p.parm.capture.timeperframe
        return t.denominator / t.numerator if t.numerator else 0.0

    def set_fps(self, fps: float) -> float:
        """Ask for a frame rate; returns the one the driver chose"""
        p = v4l2_streamparm(type=BUF_TYPE_VIDEO_CAPTURE)
        p.parm.capture.timeperframe.numerator = 1000
        p.parm.capture.timeperframe.denominator = int(round(fps * 1000))
        self.ioctl(VIDIOC_S_PARM, p, f"VIDIOC_S_PARM {fps} fps")
        t = p.parm.capture.timeperframe
        return t.denominator / t.numerator if t.numerator else 0.0

    # ---- controls ---------------------------------------------------------------------
    def controls(self) -> list[Control]:
        """Every control the node reports (VIDIOC_QUERYCTRL with NEXT_CTRL), class headings skipped"""
        out, cid = [], 0
        while True:
            q = v4l2_queryctrl(id=cid | CTRL_FLAG_NEXT_CTRL)
            if not self._listed(VIDIOC_QUERYCTRL, q, "VIDIOC_QUERYCTRL") or q.id <= cid:
                return out
            cid = q.id
            if q.type == CTRL_TYPE_CTRL_CLASS:
                continue
            menu = {}
            if q.type in (CTRL_TYPE_MENU, CTRL_TYPE_INTEGER_MENU):
                for i in range(q.minimum, q.maximum + 1):
                    m = v4l2_querymenu(id=q.id, index=i)
                    try:
                        self.sys.ioctl(self.fd, VIDIOC_QUERYMENU, m)
                    except OSError:
                        continue
                    menu[i] = m.u.name.decode(errors="replace") if q.type == CTRL_TYPE_MENU else str(m.u.value)
            out.append(Control(q.id, q.name.decode(errors="replace"), q.type, q.minimum, q.maximum, q.step,
                               q.default_value, q.flags, menu))

    def get_control(self, cid: int) -> int:
        return self.ioctl(VIDIOC_G_CTRL, v4l2_control(id=cid), f"VIDIOC_G_CTRL 0x{cid:08x}").value

    def set_control(self, cid: int, value: int) -> int:
        """Set a control and read it back"""
        self.ioctl(VIDIOC_S_CTRL, v4l2_control(id=cid, value=int(value)), f"VIDIOC_S_CTRL 0x{cid:08x} = {value}")
        return self.get_control(cid)

    # ---- streaming ----------------------------------------------------------------------
    def start(self, nbuffers: int = 4) -> None:
        """Allocate and queue mmap buffers, then VIDIOC_STREAMON"""
        if self.format is None:
            self.format = self.get_format()
        req = v4l2_requestbuffers(count=nbuffers, type=BUF_TYPE_VIDEO_CAPTURE, memory=MEMORY_MMAP)
        self.ioctl(VIDIOC_REQBUFS, req, "VIDIOC_REQBUFS")
        self._requested = True
        if req.count < 2:
            raise V4L2Error(f"{self.path}: the driver gave {req.count} buffer(s); need at least 2")
        for i in range(req.count):
            b = v4l2_buffer(index=i, type=BUF_TYPE_VIDEO_CAPTURE, memory=MEMORY_MMAP)
            self.ioctl(VIDIOC_QUERYBUF, b, "VIDIOC_QUERYBUF")
            try:
                self._buffers.append(self.sys.mmap(self.fd, b.length, b.m.offset))
            except OSError as e:
                raise V4L2Error(f"{self.path}: mmap of buffer {i}: {e.strerror or e}") from e
        for i in range(len(self._buffers)):
            self._queue(i)
        self.ioctl(VIDIOC_STREAMON, C.c_int(BUF_TYPE_VIDEO_CAPTURE), "VIDIOC_STREAMON")
        self._streaming = True

    def _queue(self, i: int) -> None:
        self.ioctl(VIDIOC_QBUF, v4l2_buffer(index=i, type=BUF_TYPE_VIDEO_CAPTURE, memory=MEMORY_MMAP), "VIDIOC_QBUF")

    def read(self, timeout: float = 2.0) -> RawFrame:
        """The next frame (copied out of the buffer, which is queued again)

        Frames the driver marks as corrupt (V4L2_BUF_FLAG_ERROR) are skipped;
        dropped frames show as gaps in .sequence.
        """
        if not self._streaming:
            raise V4L2Error(f"{self.path}: read before start")
        while True:
            if not self.sys.select(self.fd, timeout):
                raise V4L2Error(f"{self.path}: no frame within {timeout:g} s (is another program using the camera?)")
            b = v4l2_buffer(type=BUF_TYPE_VIDEO_CAPTURE, memory=MEMORY_MMAP)
            try:
                self.sys.ioctl(self.fd, VIDIOC_DQBUF, b)
            except OSError as e:
                if e.errno in (errno.EAGAIN, errno.EINTR):
                    continue
                raise V4L2Error(f"{self.path}: VIDIOC_DQBUF: {e.strerror or e}") from e
            try:
                if b.flags & BUF_FLAG_ERROR:
                    continue
                as_array = self.format.fourcc in PIXEL_FORMATS and not self.raw_bytes
                img = (frame_array if as_array else frame_bytes)(self._buffers[b.index], self.format, b.bytesused)
            finally:
                self._queue(b.index)
            t = b.timestamp.tv_sec * 1_000_000_000 + b.timestamp.tv_usec * 1000
            return RawFrame(img, int(b.sequence), int(t), int(b.flags))

    def ready(self) -> bool:
        """A frame is waiting (select without waiting): read() would not block"""
        return self._streaming and self.sys.select(self.fd, 0.0)

    def stop(self) -> None:
        if self._streaming:
            self._streaming = False
            self.ioctl(VIDIOC_STREAMOFF, C.c_int(BUF_TYPE_VIDEO_CAPTURE), "VIDIOC_STREAMOFF")
        self._release_buffers()

    def _release_buffers(self) -> None:
        for m in self._buffers:
            try:
                m.close()
            except (BufferError, AttributeError, ValueError):
                pass
        self._buffers = []
        if self._requested and self.fd is not None and not self._streaming:
            self._requested = False
            try:  # free the driver's buffers (count 0)
                self.sys.ioctl(self.fd, VIDIOC_REQBUFS,
                               v4l2_requestbuffers(count=0, type=BUF_TYPE_VIDEO_CAPTURE, memory=MEMORY_MMAP))
            except OSError:
                pass

"""The V4L2 path without hardware: a fake RealSense D435 at the system-call boundary

FakeD435 answers exactly what the kernel would through Syscalls (open,
close, ioctl on ctypes structures, mmap, select): five video nodes (depth,
its metadata, left IR, its metadata, RGB), format negotiation that snaps to
what the node offers (as uvcvideo does), frame-rate negotiation, the gain
control, the D4xx extension unit 3 behind UVCIOC_CTRL_QUERY (sizes via
GET_LEN, ranges, read-back), mmap buffers, a dropped frame (a gap in the
sequence numbers) and a corrupt one (V4L2_BUF_FLAG_ERROR). Every ioctl checks
that the structure's size matches the size encoded in the request number.
A fake sysfs tree gives the USB ids the node finder reads.

Every node streams on its own (buffers, queue, frame counter) on one
clock: a node's frame k exists at t0 + k / fps; dequeuing a frame that does
not exist yet waits for it (the clock advances), and select without a
timeout says whether one is waiting, so several nodes streamed together
behave like cameras running side by side (the rig tests). The IR node also
serves Y12I (both imagers), the RGB node YUYV and MJPG.
"""

from __future__ import annotations

import ctypes as C
import errno
import mmap
import os

import numpy as np
import pytest

from rotstar_mrcal.capture import d435, uvc_xu, v4l2
from rotstar_mrcal.capture.backend_v4l2 import V4L2Source
from rotstar_mrcal.capture.backends import describe_nodes, open_source
from rotstar_mrcal.capture.source import CaptureError, ControlError, record


def _err(code):
    return OSError(code, os.strerror(code))


class FakeNode:
    def __init__(self, name, caps, modes, usb=(0x8086, 0x0B07), interface=0, controls=True, xu=True,
                 padding=0):
        self.name, self.caps, self.modes = name, caps, modes  # modes: {fourcc: {(w, h): [fps, ...]}}
        self.usb, self.interface = usb, interface
        self.controls = {v4l2.CID_GAIN: dict(name=b"Gain", type=1, min=16, max=248, step=1, default=16, value=16)} \
            if controls else {}
        self.xu = {  # selector: [size, min, max, value]
            uvc_xu.D4XX.EMITTER: [1, 0, 3, 1],
            uvc_xu.D4XX.EXPOSURE: [4, 1, 165000, 8500],
            uvc_xu.D4XX.LASER_POWER: [2, 0, 360, 150],
            uvc_xu.D4XX.AUTO_EXPOSURE: [1, 0, 1, 1],
        } if xu else {}
        self.padding = padding
        self.frames = None  # callable(k, w, h, code) -> image bytes; None: the device's
        self.t0 = 0.0  # time of frame 0, s
        self.buffers: list = []
        self.queued: list[int] = []
        self.streaming = False
        self.made = 0  # frames the camera produced (including dropped ones)
        first = next(iter(modes))
        w, h = next(iter(modes[first]))
        self.fmt = [first, w, h]
        self.fps = modes[first][(w, h)][0]


class FakeD435(v4l2.Syscalls):
    """A D435 as uvcvideo presents it; see the module docstring"""

    def __init__(self, frames=None, drop=(), corrupt=(), emitter_broken=False, padding=0):
        ir_modes = {
            "GREY": {(1280, 800): [30, 15], (640, 400): [30, 15]},
            "Y8I ": {(1280, 800): [30, 15]},
            "Y16 ": {(1280, 800): [25, 15], (640, 400): [25, 15]},
            "Y12I": {(1280, 800): [25, 15], (640, 400): [25, 15]},
        }
        self.nodes = {
            "/dev/video0": FakeNode(b"Intel(R) RealSense(TM) Depth Ca", 0x84200001, {"Z16 ": {(1280, 720): [30]}}),
            "/dev/video1": FakeNode(b"Intel(R) RealSense(TM) Depth Ca", 0x84A00000, {"Z16 ": {(1, 1): [30]}},
                                    controls=False),
            "/dev/video2": FakeNode(b"Intel(R) RealSense(TM) Depth Ca", 0x84200001, ir_modes, padding=padding),
            "/dev/video3": FakeNode(b"Intel(R) RealSense(TM) Depth Ca", 0x84A00000, {"Z16 ": {(1, 1): [30]}},
                                    controls=False),
            "/dev/video4": FakeNode(b"Intel(R) RealSense(TM) Depth Ca", 0x84200001,
                                    {"YUYV": {(1920, 1080): [30], (424, 240): [30, 15]}, "MJPG": {(424, 240): [30]}},
                                    interface=3, xu=False),
            "/dev/video5": FakeNode(b"HD Webcam", 0x84200001, {"YUYV": {(640, 480): [30]}}, usb=(0x046D, 0x0825)),
        }
        if emitter_broken:
            del self.nodes["/dev/video2"].xu[uvc_xu.D4XX.EMITTER]
        self.frames = frames  # callable(k) -> (h, w) image, k counting frames the camera made
        self.drop, self.corrupt = set(drop), set(corrupt)
        self.fds: dict[int, str] = {}
        self.next_fd = 100
        self.calls: list[str] = []
        self.now = 0.0  # the clock, s: the time of the latest frame dequeued on any node

    @property
    def streaming(self) -> bool:
        return any(n.streaming for n in self.nodes.values())

    def frame_time(self, n: FakeNode, k: int) -> float:
        return n.t0 + k / n.fps

    # ---- syscalls ----------------------------------------------------------------
    def open(self, path):
        if path not in self.nodes:
            raise _err(errno.ENOENT)
        self.next_fd += 1
        self.fds[self.next_fd] = path
        return self.next_fd

    def close(self, fd):
        self.fds.pop(fd)

    def mmap(self, fd, length, offset):
        i = offset // 0x100000
        n = self.node(fd)
        assert n.buffers[i] is None and length == self.sizeimage(n)
        n.buffers[i] = mmap.mmap(-1, length)
        return n.buffers[i]

    def select(self, fd, timeout):
        n = self.node(fd)
        if not (n.streaming and n.queued):
            return False
        if timeout > 0:
            return True  # (waits for the next frame)
        k = n.made
        while k in self.drop:
            k += 1
        return self.frame_time(n, k) <= self.now + 1e-9

    def node(self, fd) -> FakeNode:
        return self.nodes[self.fds[fd]]

    def bytesperline(self, n: FakeNode) -> int:
        if n.fmt[0] == "MJPG":
            return 0
        return n.fmt[1] * (v4l2.bytes_per_pixel(n.fmt[0]) or 2) + n.padding

    def sizeimage(self, n: FakeNode) -> int:
        if n.fmt[0] == "MJPG":
            return n.fmt[1] * n.fmt[2] * 2  # room for any JPEG of that size
        return self.bytesperline(n) * n.fmt[2]

    def ioctl(self, fd, request, arg):
        size = (request >> 16) & 0x3FFF
        assert C.sizeof(arg) == size, f"ioctl 0x{request:08x}: {type(arg).__name__} is {C.sizeof(arg)} bytes, the request says {size}"
        n = self.node(fd)
        name = {v: k for k, v in vars(v4l2).items() if k.startswith("VIDIOC_")}.get(request, "UVCIOC_CTRL_QUERY"
                                                                                     if request == uvc_xu.UVCIOC_CTRL_QUERY else hex(request))
        self.calls.append(name)
        getattr(self, "_" + name)(n, arg)

    # ---- ioctls ------------------------------------------------------------------------
    def _VIDIOC_QUERYCAP(self, n, c):
        c.driver, c.card, c.bus_info = b"uvcvideo", n.name, b"usb-0000:00:14.0-2"
        c.capabilities = n.caps | v4l2.CAP_DEVICE_CAPS
        c.device_caps = n.caps & ~v4l2.CAP_DEVICE_CAPS

    def _VIDIOC_ENUM_FMT(self, n, f):
        if n.caps & v4l2.CAP_META_CAPTURE or f.type != v4l2.BUF_TYPE_VIDEO_CAPTURE or f.index >= len(n.modes):
            raise _err(errno.EINVAL)
        code = list(n.modes)[f.index]
        f.pixelformat, f.description = v4l2.fourcc(code), code.strip().encode()

    def _VIDIOC_ENUM_FRAMESIZES(self, n, s):
        sizes = list(n.modes.get(v4l2.fourcc_str(s.pixel_format), {}))
        if s.index >= len(sizes):
            raise _err(errno.EINVAL)
        s.type = v4l2.FRMSIZE_TYPE_DISCRETE
        s.u.discrete.width, s.u.discrete.height = sizes[s.index]

    def _VIDIOC_ENUM_FRAMEINTERVALS(self, n, f):
        rates = n.modes.get(v4l2.fourcc_str(f.pixel_format), {}).get((f.width, f.height), [])
        if f.index >= len(rates):
            raise _err(errno.EINVAL)
        f.type = v4l2.FRMIVAL_TYPE_DISCRETE
        f.u.discrete.numerator, f.u.discrete.denominator = 1, rates[f.index]

    def _fill_fmt(self, n, f):
        f.fmt.pix.width, f.fmt.pix.height = n.fmt[1], n.fmt[2]
        f.fmt.pix.pixelformat = v4l2.fourcc(n.fmt[0])
        f.fmt.pix.bytesperline, f.fmt.pix.sizeimage = self.bytesperline(n), self.sizeimage(n)

    def _VIDIOC_G_FMT(self, n, f):
        self._fill_fmt(n, f)

    def _VIDIOC_S_FMT(self, n, f):
        if n.streaming:
            raise _err(errno.EBUSY)
        code = v4l2.fourcc_str(f.fmt.pix.pixelformat)
        if code not in n.modes:  # uvcvideo falls back to the first format
            code = next(iter(n.modes))
        want = (f.fmt.pix.width, f.fmt.pix.height)
        sizes = list(n.modes[code])
        w, h = min(sizes, key=lambda s: abs(s[0] - want[0]) + abs(s[1] - want[1]))
        n.fmt = [code, w, h]
        n.fps = n.modes[code][(w, h)][0]
        self._fill_fmt(n, f)

    def _VIDIOC_G_PARM(self, n, p):
        p.parm.capture.capability = v4l2.CAP_TIMEPERFRAME
        p.parm.capture.timeperframe.numerator, p.parm.capture.timeperframe.denominator = 1, n.fps

    def _VIDIOC_S_PARM(self, n, p):
        t = p.parm.capture.timeperframe
        want = t.denominator / t.numerator
        rates = n.modes[n.fmt[0]][(n.fmt[1], n.fmt[2])]
        n.fps = min(rates, key=lambda r: abs(r - want))
        self._VIDIOC_G_PARM(n, p)

    def _VIDIOC_QUERYCTRL(self, n, q):
        ids = sorted(n.controls)
        if q.id & v4l2.CTRL_FLAG_NEXT_CTRL:
            base = q.id & ~v4l2.CTRL_FLAG_NEXT_CTRL
            nxt = [i for i in ids if i > base]
            if not nxt:
                raise _err(errno.EINVAL)
            q.id = nxt[0]
        elif q.id not in n.controls:
            raise _err(errno.EINVAL)
        c = n.controls[q.id]
        q.type, q.name, q.minimum, q.maximum = c["type"], c["name"], c["min"], c["max"]
        q.step, q.default_value, q.flags = c["step"], c["default"], 0

    def _VIDIOC_G_CTRL(self, n, c):
        if c.id not in n.controls:
            raise _err(errno.EINVAL)
        c.value = n.controls[c.id]["value"]

    def _VIDIOC_S_CTRL(self, n, c):
        if c.id not in n.controls:
            raise _err(errno.EINVAL)
        ctl = n.controls[c.id]
        if not ctl["min"] <= c.value <= ctl["max"]:
            raise _err(errno.ERANGE)
        ctl["value"] = c.value

    def _UVCIOC_CTRL_QUERY(self, n, q):
        if q.unit != uvc_xu.D4XX.unit:
            raise _err(errno.ENOENT)
        if q.selector not in n.xu:
            raise _err(errno.EIO)  # the firmware stalls the request
        size, lo, hi, val = n.xu[q.selector]
        if q.query == uvc_xu.UVC_GET_LEN:
            assert q.size == 2
            C.memmove(q.data, size.to_bytes(2, "little"), 2)
            return
        if q.size != size:
            raise _err(errno.EINVAL)
        if q.query == uvc_xu.UVC_SET_CUR:
            v = int.from_bytes(C.string_at(q.data, size), "little")
            if not lo <= v <= hi:
                raise _err(errno.ERANGE)
            n.xu[q.selector][3] = v
            return
        v = {uvc_xu.UVC_GET_CUR: val, uvc_xu.UVC_GET_MIN: lo, uvc_xu.UVC_GET_MAX: hi}[q.query]
        C.memmove(q.data, int(v).to_bytes(size, "little"), size)

    def _VIDIOC_REQBUFS(self, n, r):
        if n.streaming:
            raise _err(errno.EBUSY)
        assert r.memory == v4l2.MEMORY_MMAP and r.type == v4l2.BUF_TYPE_VIDEO_CAPTURE
        r.count = min(r.count, 8)
        n.buffers, n.queued = [None] * r.count, []

    def _VIDIOC_QUERYBUF(self, n, b):
        if b.index >= len(n.buffers):
            raise _err(errno.EINVAL)
        b.length, b.m.offset = self.sizeimage(n), b.index * 0x100000

    def _VIDIOC_QBUF(self, n, b):
        if b.index >= len(n.buffers) or b.index in n.queued or n.buffers[b.index] is None:
            raise _err(errno.EINVAL)
        n.queued.append(b.index)

    def _VIDIOC_STREAMON(self, n, t):
        assert t.value == v4l2.BUF_TYPE_VIDEO_CAPTURE and n.queued
        n.streaming = True

    def _VIDIOC_STREAMOFF(self, n, t):
        n.streaming = False
        n.queued = []

    def _VIDIOC_DQBUF(self, n, b):
        if not n.streaming or not n.queued:
            raise _err(errno.EAGAIN)
        while n.made in self.drop:  # the driver had no buffer in time: the frame is lost
            n.made += 1
        k = n.made
        n.made += 1
        t = self.frame_time(n, k)
        self.now = max(self.now, t)  # (waited for it)
        i = n.queued.pop(0)
        code, w, h = n.fmt
        img = (n.frames or self.frames)(k, w, h, code)
        bpl = self.bytesperline(n)
        if code == "MJPG":
            raw = np.asarray(img, np.uint8).reshape(-1)
        else:
            raw = np.zeros((h, bpl), np.uint8)
            row = img.view(np.uint8).reshape(h, -1)
            raw[:, : row.shape[1]] = row
        n.buffers[i][: raw.nbytes] = raw.tobytes()
        b.index, b.bytesused, b.sequence = i, raw.nbytes, k
        b.flags = v4l2.BUF_FLAG_ERROR if k in self.corrupt else 0
        us = int(round(t * 1e6))
        b.timestamp.tv_sec, b.timestamp.tv_usec = 1000 + us // 1000000, us % 1000000


def ramp(k, w, h, code):
    """Frame k: a distinct, checkable image in the node's format"""
    y, x = np.mgrid[0:h, 0:w]
    if code == "Y16 ":
        return ((x + 7 * y + 1000 * k) % 65536).astype("<u2")
    if code == "Y8I ":
        return np.stack([(x + k) % 256, np.full_like(x, 77)], -1).astype(np.uint8)
    return ((x + y + k) % 256).astype(np.uint8)


@pytest.fixture
def sysfs(tmp_path):
    """/sys/class/video4linux for the fake nodes: USB ids on the device, interface numbers"""
    fake = FakeD435()
    root = tmp_path / "sys"
    cls = root / "class" / "video4linux"
    cls.mkdir(parents=True)
    for path, node in fake.nodes.items():
        name = os.path.basename(path)
        usbdev = root / "devices" / f"usb-{node.usb[1]:04x}"
        iface = usbdev / f"1-2:1.{node.interface}"
        iface.mkdir(parents=True, exist_ok=True)
        (usbdev / "idVendor").write_text(f"{node.usb[0]:04x}\n")
        (usbdev / "idProduct").write_text(f"{node.usb[1]:04x}\n")
        (usbdev / "serial").write_text("841512070000\n")
        (iface / "bInterfaceNumber").write_text(f"{node.interface:02x}\n")
        (cls / name).mkdir()
        (cls / name / "name").write_text(node.name.decode() + "\n")
        os.symlink(iface, cls / name / "device")
    return str(cls)


# ---- ioctl numbers and structure layouts -------------------------------------------------
def test_ioctl_numbers_match_the_kernel():
    """The values of <linux/videodev2.h> and <linux/uvcvideo.h> on 64-bit Linux"""
    assert C.sizeof(C.c_void_p) == 8
    assert v4l2.VIDIOC_QUERYCAP == 0x80685600
    assert v4l2.VIDIOC_ENUM_FMT == 0xC0405602
    assert v4l2.VIDIOC_S_FMT == 0xC0D05605
    assert v4l2.VIDIOC_REQBUFS == 0xC0145608
    assert v4l2.VIDIOC_QUERYBUF == 0xC0585609
    assert v4l2.VIDIOC_QBUF == 0xC058560F
    assert v4l2.VIDIOC_DQBUF == 0xC0585611
    assert v4l2.VIDIOC_STREAMON == 0x40045612
    assert v4l2.VIDIOC_S_PARM == 0xC0CC5616
    assert v4l2.VIDIOC_S_CTRL == 0xC008561C
    assert v4l2.VIDIOC_QUERYCTRL == 0xC0445624
    assert v4l2.VIDIOC_ENUM_FRAMESIZES == 0xC02C564A
    assert v4l2.VIDIOC_ENUM_FRAMEINTERVALS == 0xC034564B
    assert uvc_xu.UVCIOC_CTRL_QUERY == 0xC0107521
    assert v4l2.fourcc("Y16") == 0x20363159 and v4l2.fourcc_str(0x59455247) == "GREY"


# ---- format negotiation --------------------------------------------------------------------
def test_format_negotiation():
    fake = FakeD435(ramp)
    with v4l2.Device("/dev/video2", fake) as dev:
        cap = dev.querycap()
        assert cap.driver == "uvcvideo" and cap.is_video_capture and cap.can_stream
        assert [f.fourcc for f in dev.formats()] == ["GREY", "Y8I ", "Y16 ", "Y12I"]
        assert dev.frame_sizes("Y16") == [(1280, 800), (640, 400)]
        assert dev.frame_rates("Y16", 1280, 800) == [25.0, 15.0]
        fmt = dev.set_format(1280, 800, "Y16")
        assert (fmt.width, fmt.height, fmt.fourcc, fmt.bytesperline) == (1280, 800, "Y16 ", 2560)
        assert dev.get_format() == fmt
        assert dev.set_fps(25) == 25.0 and dev.get_fps() == 25.0
        # the driver snaps an unsupported size and says so
        with pytest.raises(v4l2.V4L2Error, match=r"asked for 1920x1080 Y16, the driver chose 1280x800 Y16"):
            dev.set_format(1920, 1080, "Y16")
        # and an unknown format to its first one
        with pytest.raises(v4l2.V4L2Error, match=r"driver chose .* GREY.*offers: GREY"):
            dev.set_format(1280, 800, "YUYV")
    assert fake.fds == {}


def test_v4l2_source_rejects_impossible_modes():
    with pytest.raises(CaptureError, match="has no Z16 format; it offers GREY, Y8I, Y16"):
        V4L2Source("/dev/video2", fourcc="Z16", sys=FakeD435(ramp))
    with pytest.raises(CaptureError, match=r"asked for 30 fps, the driver chose 25; Y16 1280x800 runs at 25, 15 fps"):
        V4L2Source("/dev/video2", fourcc="Y16", fps=30, sys=FakeD435(ramp))
    with pytest.raises(CaptureError, match="not a streaming video-capture node"):
        V4L2Source("/dev/video1", sys=FakeD435(ramp))
    with pytest.raises(CaptureError, match="cannot open"):
        V4L2Source("/dev/video9", sys=FakeD435(ramp))


# ---- controls ---------------------------------------------------------------------------------
def test_controls_and_extension_unit():
    fake = FakeD435(ramp)
    with v4l2.Device("/dev/video2", fake) as dev:
        ctrls = dev.controls()
        assert [(c.name, c.minimum, c.maximum) for c in ctrls] == [("Gain", 16, 248)]
        assert dev.set_control(v4l2.CID_GAIN, 32) == 32
        with pytest.raises(v4l2.V4L2Error, match="VIDIOC_S_CTRL"):
            dev.set_control(v4l2.CID_GAIN, 1000)
        with pytest.raises(v4l2.V4L2Error):  # the IR pin has no standard exposure control
            dev.get_control(v4l2.CID_EXPOSURE_ABSOLUTE)
        # the D4xx extension unit: sizes from GET_LEN, little-endian values, read back
        assert uvc_xu.xu_len(dev, 3, uvc_xu.D4XX.EXPOSURE) == 4
        assert uvc_xu.xu_get(dev, 3, uvc_xu.D4XX.EXPOSURE) == 8500
        assert uvc_xu.xu_range(dev, 3, uvc_xu.D4XX.EXPOSURE) == (1, 165000)
        assert d435.set_exposure_us(dev, 70000) == 70000  # > 16 bits: the u32 payload matters
        assert fake.nodes["/dev/video2"].xu[uvc_xu.D4XX.AUTO_EXPOSURE][3] == 0
        assert fake.nodes["/dev/video2"].xu[uvc_xu.D4XX.EXPOSURE][3] == 70000
        assert d435.set_emitter(dev, False) == 0
        assert d435.xu_state(dev) == {"emitter": 0, "exposure_us": 70000, "laser_power": 150, "auto_exposure": 0}
        with pytest.raises(ControlError, match=r"exposure 200000 us is outside the camera's range 1-165000 us"):
            d435.set_exposure_us(dev, 200000)
        with pytest.raises(v4l2.V4L2Error, match="unit 7"):
            uvc_xu.xu_get(dev, 7, 1)
    assert "UVCIOC_CTRL_QUERY" in fake.calls


def test_emitter_falls_back_to_laser_power():
    fake = FakeD435(ramp, emitter_broken=True)
    with v4l2.Device("/dev/video2", fake) as dev:
        assert d435.set_emitter(dev, False) == 0
        assert fake.nodes["/dev/video2"].xu[uvc_xu.D4XX.LASER_POWER][3] == 0
        with pytest.raises(ControlError, match="emitter on"):
            d435.set_emitter(dev, True)


def test_source_controls_stop_with_a_reason():
    fake = FakeD435(ramp)
    with pytest.raises(CaptureError, match="'NV12' is not a format this tool reads"):
        V4L2Source("/dev/video4", fourcc="NV12", size=(1920, 1080), fps=30, camera="generic", sys=fake)
    assert fake.fds == {}
    gen = V4L2Source("/dev/video2", camera="generic", sys=fake)
    with pytest.raises(ControlError, match="exposure_auto / exposure_time_absolute"):
        gen.set_exposure_us(4000)
    with pytest.raises(ControlError, match="no emitter control"):
        gen.set_emitter(False)
    assert gen.set_gain(20) == 20.0
    gen.close()
    src = V4L2Source("/dev/video2", camera="d435", sys=fake)
    assert src.set_exposure_us(4000) == 4000.0
    src.set_emitter(False)
    info = src.info()
    assert info["format"] == {"fourcc": "Y16", "width": 1280, "height": 800, "bytesperline": 2560}
    assert info["xu"]["exposure_us"] == 4000 and info["xu"]["emitter"] == 0
    assert info["controls"]["Gain"]["value"] == 20
    assert info["modes"]["Y16"] == ["1280x800@25/15", "640x400@25/15"]
    src.close()


# ---- streaming ------------------------------------------------------------------------------
@pytest.mark.parametrize("padding", [0, 64])
def test_streaming_with_a_dropped_and_a_corrupt_frame(padding):
    fake = FakeD435(ramp, drop={3}, corrupt={5}, padding=padding)
    src = V4L2Source("/dev/video2", fourcc="Y16", size=(640, 400), fps=25, sys=fake)
    assert src.full_scale == 65535.0 and src.fps == 25.0
    src.start()
    rec = record(src, 6)
    src.stop()
    assert rec.sequence.tolist() == [0, 1, 2, 4, 6, 7]  # 3 lost by the driver, 5 marked corrupt
    assert rec.dropped == 2
    for img, k in zip(rec.frames, rec.sequence):
        assert img.dtype == np.uint16 and img.shape == (400, 640)
        np.testing.assert_array_equal(img, ramp(k, 640, 400, "Y16 "))
    # every dequeued buffer went back to the driver: 4 queued, then one QBUF per DQBUF
    assert fake.calls.count("VIDIOC_QBUF") == 4 + fake.calls.count("VIDIOC_DQBUF")
    assert fake.calls.count("VIDIOC_DQBUF") == 7  # six frames and the corrupt one
    assert not fake.streaming
    src.close()
    assert fake.fds == {}


def test_streaming_8bit_and_interleaved():
    fake = FakeD435(ramp)
    with v4l2.Device("/dev/video2", fake) as dev:
        dev.set_format(640, 400, "GREY")
        dev.start(nbuffers=3)
        f = dev.read()
        assert f.image.dtype == np.uint8 and f.sequence == 0 and f.timestamp_ns == 1000 * 10**9
        np.testing.assert_array_equal(f.image, ramp(0, 640, 400, "GREY"))
        dev.stop()
        dev.set_format(1280, 800, "Y8I")  # left + right interleaved: the left is kept
        dev.start()
        f = dev.read()
        np.testing.assert_array_equal(f.image, ramp(1, 1280, 800, "Y8I ")[..., 0])
        dev.stop()
    with v4l2.Device("/dev/video2", FakeD435(ramp)) as dev:
        with pytest.raises(v4l2.V4L2Error, match="read before start"):
            dev.read()


def test_read_times_out_with_a_reason():
    fake = FakeD435(ramp)
    with v4l2.Device("/dev/video2", fake) as dev:
        dev.set_format(640, 400, "Y16")
        dev.start()
        fake.nodes["/dev/video2"].queued.clear()  # the camera stopped delivering
        with pytest.raises(v4l2.V4L2Error, match="no frame within 0.1 s"):
            dev.read(timeout=0.1)


def test_frame_array_checks_the_size():
    fmt = v4l2.PixFormat(4, 2, "Y16 ", 8, 16)
    with pytest.raises(v4l2.V4L2Error, match="short frame: 10 bytes"):
        v4l2.frame_array(bytes(10), fmt)
    with pytest.raises(v4l2.V4L2Error, match="not supported"):
        v4l2.frame_array(bytes(16), v4l2.PixFormat(4, 2, "MJPG", 8, 16))


# ---- finding the D435 -----------------------------------------------------------------------
def test_find_ir_node_by_usb_id_and_formats(sysfs):
    fake = FakeD435(ramp)
    nodes = d435.list_nodes(sysfs, "/dev")
    assert [(n.path, n.model, n.interface) for n in nodes][:3] == [
        ("/dev/video0", "D435", 0), ("/dev/video1", "D435", 0), ("/dev/video2", "D435", 0)]
    assert nodes[5].model == "046d:0825" and not nodes[5].is_d4xx
    node = d435.find_ir_node(sysfs, "/dev", fake)
    assert node.path == "/dev/video2" and node.product == 0x0B07
    src = open_source("v4l2", camera="d435", sys=fake, sysfs=sysfs, dev_root="/dev")
    assert src.path == "/dev/video2"
    src.close()
    assert fake.fds == {}
    with pytest.raises(CaptureError, match="serial 841512070000, not 123"):
        d435.find_ir_node(sysfs, "/dev", fake, serial="123")
    del fake.nodes["/dev/video2"]  # the IR node gone (e.g. an old kernel without the formats)
    with pytest.raises(CaptureError, match=r"/dev/video0 \(D435\): formats Z16 .*/dev/video1: no video capture"
                                           r".*/dev/video4 \(D435\): formats YUYV.*not an Intel D4xx"):
        d435.find_ir_node(sysfs, "/dev", fake)
    with pytest.raises(CaptureError, match="no video nodes"):
        d435.find_ir_node(sysfs + "-missing", "/dev", fake)


def test_format_warning():
    assert "rectified" in d435.format_warning("GREY") and "Y16" in d435.format_warning("Y8I")
    assert d435.format_warning("Y16") is None


def test_describe_nodes_for_the_first_contact(sysfs, capsys):
    from rotstar_mrcal.cli.capture import print_nodes

    nodes = describe_nodes(FakeD435(ramp), sysfs, "/dev")
    ir = nodes[2]
    assert ir["usb"] == "D435" and ir["capture"] and ir["modes"]["Y16"] == ["1280x800@25/15", "640x400@25/15"]
    assert ir["controls"] == {"Gain": 16} and ir["xu"]["exposure_us"] == 8500
    assert not nodes[1]["capture"] and "modes" not in nodes[1]
    assert nodes[0]["modes"] == {"Z16": ["1280x720@30"]} and "xu" not in nodes[0]  # the depth pin
    print_nodes(nodes)
    out = capsys.readouterr().out
    assert "/dev/video2" in out and "Y16   1280x800@25/15" in out and "GREY" in out and "(rectified)" in out
    assert "extension unit exposure_us = 8500" in out and "not a video-capture node" in out
    assert "Y12I  1280x800@25/15 640x400@25/15  (left + right, unrectified: --stereo)" in out
    assert "YUYV  1920x1080@30 424x240@30/15" in out and "MJPG  424x240@30" in out  # the RGB node


# ---- rotstar-capture through the fake device -------------------------------------------------
@pytest.fixture(scope="module")
def player_loop_frames():
    """One loop of the player (the default sequence, identity frames included: 20 entries of 18 refreshes at 60 Hz)
    as a 640x400 camera sees it (150 frames at 25 fps; repeats seamlessly)"""
    from rotstar_mrcal import simulate
    from rotstar_mrcal.capture.simulated import camera_stream, loop_irradiance, player_schedule
    from rotstar_mrcal.pattern.loop import player_loop
    from rotstar_mrcal.pattern.layout import make_layout

    layout = make_layout(screen=(800, 600), pitch=100, band=24)
    model = simulate.preset_model("pinhole-small")
    rt = simulate.random_poses(model, layout, 1, np.random.default_rng(3))[0]
    E = loop_irradiance(layout, model, rt, supersample=2)
    n = len(player_loop(layout.frames()))
    frames, _ = camera_stream(E, player_schedule(n, hold=18, duration=12.5), n * 18 * 25 // 60, fps=25, exposure_s=0.012,
                              noise=0.005, gain=0.6, t0=0.013, rng=8)
    return layout, frames


def test_capture_cli_through_the_fake_d435(player_loop_frames, tmp_path, capsys, monkeypatch):
    """Two exposures, one dataset each; the exposure really goes to the camera (the fake's brightness follows it)"""
    import io
    import json
    import sys

    from rotstar_mrcal.cli.capture import main as rotstar_capture

    layout, loop = player_loop_frames
    (tmp_path / "pattern.json").write_text(layout.to_json())
    fake = FakeD435()
    ir = fake.nodes["/dev/video2"]

    def frames(k, w, h, code):  # the player, exposed for the exposure currently set in the extension unit
        f = loop[k % len(loop)].astype(float) * ir.xu[uvc_xu.D4XX.EXPOSURE][3] / 4000
        return np.clip(f, 0, 65535).astype("<u2")

    fake.frames = frames
    src = V4L2Source("/dev/video2", size=(640, 400), fps=25, sys=fake)
    monkeypatch.setattr(sys, "stdin", io.StringIO("\nq\n"))
    code = rotstar_capture(["--pattern", str(tmp_path), "--out", str(tmp_path / "seq"), "--size", "640x400",
                            "--exposure", "2000,4000", "--frames", "360"], source=src)
    out, err = capsys.readouterr()
    assert code == 0, err
    assert out.split() == [str(tmp_path / "seq" / "exp2000us" / "pose000"), str(tmp_path / "seq" / "exp4000us" / "pose000")]
    assert "emitter off" in err and "gain 16" in err
    assert "pose000 at 2000 us: board complete (24/24)" in err and "pose000 at 4000 us: board complete" in err
    assert ir.xu[uvc_xu.D4XX.EMITTER][3] == 0 and ir.xu[uvc_xu.D4XX.AUTO_EXPOSURE][3] == 0
    assert ir.controls[v4l2.CID_GAIN]["value"] == 16
    a = cv2_read(tmp_path / "seq" / "exp2000us" / "pose000" / "checkerboard.png")
    b = cv2_read(tmp_path / "seq" / "exp4000us" / "pose000" / "checkerboard.png")
    assert 0.45 < a.mean() / b.mean() < 0.55
    ids = [f["file"] for f in layout.frames() if f["kind"] == "identity"]
    assert len(ids) == 10 and all((tmp_path / "seq" / e / "pose000" / f).exists()
                                  for e in ("exp2000us", "exp4000us") for f in ids)
    assert (tmp_path / "seq" / "exp2000us" / "pattern.json").exists()
    log = json.loads((tmp_path / "seq" / "capture.json").read_text())
    assert log["source"]["device"] == "/dev/video2" and log["source"]["format"]["fourcc"] == "Y16"
    assert set(log["poses"]) == {"exp2000us", "exp4000us"}
    assert not fake.streaming and fake.fds == {}


def test_capture_cli_auto_exposure_through_the_fake_d435(player_loop_frames, tmp_path, capsys, monkeypatch):
    """No --exposure: the look sets the extension unit's exposure, the fake's brightness follows it (clipped at
    8000 us, its start), and the pose is recorded at the exposure picked, into OUT/exp<us>us"""
    import io
    import json
    import re
    import sys

    from rotstar_mrcal.capture.exposure import measure_look
    from rotstar_mrcal.cli.capture import main as rotstar_capture

    layout, loop = player_loop_frames
    (tmp_path / "pattern.json").write_text(layout.to_json())
    fake = FakeD435()
    ir = fake.nodes["/dev/video2"]
    set_to = []

    def frames(k, w, h, code):
        set_to.append(ir.xu[uvc_xu.D4XX.EXPOSURE][3])
        return np.clip(loop[k % len(loop)].astype(float) * set_to[-1] / 4000, 0, 65535).astype("<u2")

    fake.frames = frames
    monkeypatch.setattr(sys, "stdin", io.StringIO("\n\nq\n"))  # Enter: the look; Enter: pose000; q
    code = rotstar_capture(["--pattern", str(tmp_path), "--out", str(tmp_path / "seq"), "--size", "640x400",
                            "--hold", "18", "--frames", "360"], source=V4L2Source("/dev/video2", size=(640, 400),
                                                                                 fps=25, sys=fake))
    out, err = capsys.readouterr()
    assert code == 0, err
    us = int(re.search(r"exposure: (\d+) us \(white at (\d+) % of full scale after 3 looks", err)[1])
    white_4000 = measure_look(loop.astype(float), 65535).white  # the fake's white at 4000 us
    assert abs(white_4000 * us / 4000 / 0.75 - 1) < 0.1
    assert set_to[0] == 8500 and set_to.index(8000) < set_to.index(2000) and set_to[-1] == us  # the camera's
    # default until the look sets 8000 us (clipped), then 4 times shorter, then the exposure picked
    assert out.split() == [str(tmp_path / "seq" / f"exp{us}us" / "pose000")]
    assert f"pose000 at {us} us: board complete (24/24)" in err
    assert json.loads((tmp_path / "seq" / "capture.json").read_text())["auto_exposure"]["looks"] == 3
    assert err.index("press Enter to look") < err.index(f"exposure: {us} us (") < err.index("pose000: place the camera")


def test_capture_cli_stops_when_a_control_fails(player_loop_frames, tmp_path, capsys, monkeypatch):
    import io
    import sys

    from rotstar_mrcal.cli.capture import main as rotstar_capture

    layout, loop = player_loop_frames
    (tmp_path / "pattern.json").write_text(layout.to_json())
    fake = FakeD435(lambda k, w, h, code: loop[k % len(loop)])
    del fake.nodes["/dev/video2"].xu[uvc_xu.D4XX.EXPOSURE]  # a firmware that stalls the exposure selector
    argv = ["--pattern", str(tmp_path), "--out", str(tmp_path / "seq"), "--size", "640x400", "--exposure", "3000",
            "--frames", "360"]
    monkeypatch.setattr(sys, "stdin", io.StringIO("\n"))
    code = rotstar_capture(argv, source=V4L2Source("/dev/video2", size=(640, 400), sys=fake))
    err = capsys.readouterr().err
    assert code == 1 and "exposure 3000 us: exposure 3000 us (XU unit 3 selector 3)" in err and "--force" in err
    assert fake.fds == {}
    monkeypatch.setattr(sys, "stdin", io.StringIO("\nq\n"))
    code = rotstar_capture(argv + ["--force"], source=V4L2Source("/dev/video2", size=(640, 400), sys=fake))
    out, err = capsys.readouterr()
    assert code == 0 and "warning: exposure 3000 us" in err and "going on (--force)" in err
    assert out.split() == [str(tmp_path / "seq" / "exp3000us" / "pose000")]


def cv2_read(fn):
    import cv2

    return cv2.imread(str(fn), cv2.IMREAD_UNCHANGED).astype(float)

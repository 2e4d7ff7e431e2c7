"""The v4l2 backend: a V4L2 video node as a FrameSource (the default)

SYNOPSIS

    from rotstar_mrcal.capture.backend_v4l2 import V4L2Source
    src = V4L2Source("/dev/video2", fourcc="Y16 ", size=(1280, 800), fps=25, camera="d435")
    src.set_exposure_us(4000)      # D4xx: extension unit; generic: exposure_time_absolute
    src.set_emitter(False)
    src.start()
    frame = src.read()             # Frame(image (800, 1280) uint16, sequence, t_ns)
    src.close()

camera "d435" (any D4xx) sets exposure, auto exposure and the emitter
through the vendor extension unit (d435.py); camera "generic" uses the
standard UVC controls (exposure_auto = manual, exposure_time_absolute in 100
us units) and has no emitter. Gain is V4L2's gain control for both. Every
control is read back; a mismatch raises ControlError.

Formats: the grey ones of v4l2.PIXEL_FORMATS give one view, as recorded.
stereo=True (the D4xx's Y12I, or Y8I) gives two views per buffer, the left
and the right imager (interleaved.py), read_views() -> [left, right]; read()
is the left one. A colour format (YUYV, UYVY, MJPG: the D435's RGB node)
gives its luma as a uint8 grey view (colour.py).

    ir = V4L2Source("/dev/video2", fourcc="Y12I", stereo=True)   # 1280x800 25 fps
    left, right = ir.read_views()                                # Frames, uint16 12-bit values
    rgb = V4L2Source("/dev/video4", fourcc="YUYV", size=(1280, 720), fps=30, camera="generic")
"""

from __future__ import annotations

from rotstar_mrcal.capture import d435
from rotstar_mrcal.capture.colour import COLOUR_FORMATS, ColourError, to_grey
from rotstar_mrcal.capture.interleaved import InterleavedError, unpack
from rotstar_mrcal.capture.source import CaptureError, ControlError, Frame, FrameSource
from rotstar_mrcal.capture.v4l2 import (
    CID_EXPOSURE_ABSOLUTE, CID_EXPOSURE_AUTO, CID_GAIN, EXPOSURE_MANUAL, PIXEL_FORMATS, Device, Syscalls,
    V4L2Error,
)

STEREO_FORMATS = ("Y12I", "Y8I ")

CAMERAS = ("d435", "generic")


class V4L2Source(FrameSource):
    name = "v4l2"

    def __init__(self, path: str, fourcc: str = d435.DEFAULT_FOURCC, size=d435.DEFAULT_SIZE,
                 fps: float | None = d435.DEFAULT_FPS, camera: str = "d435", nbuffers: int = 4,
                 sys: Syscalls | None = None, stereo: bool = False):
        if camera not in CAMERAS:
            raise CaptureError(f"unknown camera {camera!r}; known: {', '.join(CAMERAS)}")
        self.camera = camera
        self.nbuffers = nbuffers
        try:
            self.dev = Device(path, sys)
        except V4L2Error as e:
            raise CaptureError(str(e)) from None
        try:
            cap = self.dev.querycap()
            if not cap.is_video_capture or not cap.can_stream:
                raise CaptureError(f"{path} ({cap.card}): not a streaming video-capture node")
            self.card = cap.card
            fmts = [f.fourcc for f in self.dev.formats()]
            code = (fourcc + "    ")[:4]
            if stereo and code not in STEREO_FORMATS:
                raise CaptureError(f"{code.strip()} is not a stereo format (Y12I, Y8I)")
            if code not in PIXEL_FORMATS and code not in STEREO_FORMATS + COLOUR_FORMATS:
                known = [k.strip() for k in PIXEL_FORMATS] + [k.strip() for k in STEREO_FORMATS + COLOUR_FORMATS
                                                               if k not in PIXEL_FORMATS]
                raise CaptureError(f"pixel format {code.strip()!r} is not a format this tool reads ({', '.join(known)})")
            if code not in fmts:
                raise CaptureError(f"{path} ({cap.card}) has no {code.strip()} format; it offers "
                                   f"{', '.join(f.strip() for f in fmts) or 'none'}")
            self.format = self.dev.set_format(int(size[0]), int(size[1]), code)
            self.fps = self.dev.set_fps(fps) if fps else self.dev.get_fps()
            if fps and abs(self.fps - fps) > 0.01 * fps:
                rates = self.dev.frame_rates(code, *size)
                raise CaptureError(f"{path}: asked for {fps:g} fps, the driver chose {self.fps:g}; "
                                   f"{code.strip()} {size[0]}x{size[1]} runs at {', '.join(f'{r:g}' for r in rates)} fps")
        except V4L2Error as e:
            self.dev.close()
            raise CaptureError(str(e)) from None
        except CaptureError:
            self.dev.close()
            raise
        self.code = self.format.fourcc
        self.views = 2 if stereo or self.code == "Y12I" else 1
        self.dev.raw_bytes = self.views == 2  # (Y8I as both halves, not the left one)
        dtype = PIXEL_FORMATS[self.code][0] if self.code in PIXEL_FORMATS else "u2" if self.code == "Y12I" else "u1"
        self.full_scale = 255.0 if dtype == "u1" else 65535.0
        self.path = path
        self._last: list[Frame] | None = None

    # ---- streaming -----------------------------------------------------------------
    def start(self) -> None:
        try:
            self.dev.start(self.nbuffers)
        except V4L2Error as e:
            raise CaptureError(str(e)) from None

    def stop(self) -> None:
        try:
            self.dev.stop()
        except V4L2Error as e:
            raise CaptureError(str(e)) from None

    def close(self) -> None:
        self.dev.close()

    def read_views(self, timeout: float = 2.0) -> list[Frame]:
        """The next buffer as its views: [image] or, stereo, [left, right]"""
        try:
            f = self.dev.read(timeout)
        except V4L2Error as e:
            raise CaptureError(str(e)) from None
        w, h = self.format.width, self.format.height
        try:
            if self.views == 2:
                images = unpack(self.code, f.image, w, h)
            elif self.code in COLOUR_FORMATS:
                images = [to_grey(self.code, f.image, w, h)]
            else:
                images = [f.image]
        except (InterleavedError, ColourError) as e:
            raise CaptureError(f"{self.path}: frame {f.sequence}: {e}") from None
        self._last = [Frame(im, f.sequence, f.timestamp_ns) for im in images]
        return self._last

    def read(self, timeout: float = 2.0) -> Frame:
        return self.read_views(timeout)[0]

    def read_latest(self, timeout: float = 2.0) -> list[Frame]:
        """The newest buffer waiting, the ones before it dropped; none waiting: the last one read again
        (a slower camera held at its latest frame), or the next one if nothing was read yet"""
        got = None
        while self.dev.ready():
            got = self.read_views(timeout)
        return got or self._last or self.read_views(timeout)

    # ---- controls ------------------------------------------------------------------
    def set_exposure_us(self, us: float) -> float:
        if self.camera == "d435":
            return float(d435.set_exposure_us(self.dev, us))
        try:
            self.dev.set_control(CID_EXPOSURE_AUTO, EXPOSURE_MANUAL)
            got = self.dev.set_control(CID_EXPOSURE_ABSOLUTE, max(1, round(us / 100)))
        except V4L2Error as e:
            raise ControlError(f"exposure {us:g} us (exposure_auto / exposure_time_absolute): {e}") from None
        if abs(got * 100 - us) > 100:
            raise ControlError(f"exposure reads back {got * 100} us after setting {us:g} us")
        return float(got * 100)

    def set_gain(self, gain: float) -> float:
        try:
            got = self.dev.set_control(CID_GAIN, int(round(gain)))
        except V4L2Error as e:
            raise ControlError(f"gain {gain:g}: {e}") from None
        if got != int(round(gain)):
            raise ControlError(f"gain reads back {got} after setting {gain:g}")
        return float(got)

    def set_emitter(self, on: bool) -> None:
        if self.camera != "d435":
            raise ControlError(f"{self.path}: a generic camera has no emitter control")
        d435.set_emitter(self.dev, on)

    def info(self) -> dict:
        out = {
            "backend": self.name, "device": self.path, "card": self.card, "camera": self.camera,
            "format": {"fourcc": self.format.fourcc.strip(), "width": self.format.width,
                       "height": self.format.height, "bytesperline": self.format.bytesperline},
            "fps": self.fps,
        }
        try:
            out["modes"] = {k.strip(): [f"{w}x{h}@" + "/".join(f"{r:g}" for r in rates) for w, h, rates in v]
                            for k, v in self.dev.modes().items()}
            out["controls"] = {}
            for c in self.dev.controls():
                try:
                    val = self.dev.get_control(c.id)
                except V4L2Error as e:
                    val = f"unreadable: {e}"
                out["controls"][c.name] = {"id": f"0x{c.id:08x}", "value": val, "min": c.minimum,
                                           "max": c.maximum, "default": c.default, **({"menu": c.menu} if c.menu else {})}
        except V4L2Error as e:
            out["error"] = str(e)
        if self.camera == "d435":
            out["xu"] = d435.xu_state(self.dev)
        return out

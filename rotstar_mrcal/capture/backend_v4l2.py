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
"""

from __future__ import annotations

from . import d435
from .source import CaptureError, ControlError, Frame, FrameSource
from .v4l2 import (CID_EXPOSURE_ABSOLUTE, CID_EXPOSURE_AUTO, CID_GAIN, EXPOSURE_MANUAL, PIXEL_FORMATS, Device,
                   Syscalls, V4L2Error)

CAMERAS = ("d435", "generic")


class V4L2Source(FrameSource):
    name = "v4l2"

    def __init__(self, path: str, fourcc: str = d435.DEFAULT_FOURCC, size=d435.DEFAULT_SIZE,
                 fps: float | None = d435.DEFAULT_FPS, camera: str = "d435", nbuffers: int = 4,
                 sys: Syscalls | None = None):
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
            if code not in PIXEL_FORMATS:
                raise CaptureError(f"pixel format {code.strip()!r} is not a grey format this tool reads "
                                   f"({', '.join(k.strip() for k in PIXEL_FORMATS)})")
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
        dtype = PIXEL_FORMATS[self.format.fourcc][0]
        self.full_scale = 255.0 if dtype == "u1" else 65535.0
        self.path = path

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

    def read(self, timeout: float = 2.0) -> Frame:
        try:
            f = self.dev.read(timeout)
        except V4L2Error as e:
            raise CaptureError(str(e)) from None
        return Frame(f.image, f.sequence, f.timestamp_ns)

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

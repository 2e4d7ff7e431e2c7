"""The realsense backend: librealsense's Python wrapper as a FrameSource (optional)

SYNOPSIS

    from rotstar_mrcal.capture.backend_realsense import RealSenseSource
    src = RealSenseSource(size=(1280, 800), fourcc="Y16", fps=25)   # needs pyrealsense2
    src.set_exposure_us(4000); src.set_emitter(False)
    src.start(); frame = src.read(); src.close()

Streams infrared 1 (the left imager) through pyrealsense2 (pip install
pyrealsense2; not a dependency of this project), with auto exposure off, the
exposure in microseconds, the gain and the emitter set through the depth
sensor's options and read back. librealsense talks to the same uvcvideo
nodes as the v4l2 backend; use it where librealsense is installed anyway.
"""

from __future__ import annotations

import numpy as np

from rotstar_mrcal.capture.source import CaptureError, ControlError, Frame, FrameSource


def _rs():
    try:
        import pyrealsense2 as rs
    except ImportError:
        raise CaptureError("the realsense backend needs pyrealsense2 (pip install pyrealsense2), which is not "
                           "installed; the default v4l2 backend needs nothing") from None
    return rs


class RealSenseSource(FrameSource):
    name = "realsense"

    def __init__(self, size=(1280, 800), fourcc: str = "Y16", fps: float = 25, serial: str | None = None):
        rs = self.rs = _rs()
        fmt = {"Y16": rs.format.y16, "GREY": rs.format.y8, "Y8": rs.format.y8}.get(fourcc.strip())
        if fmt is None:
            raise CaptureError(f"realsense: format {fourcc!r}; use Y16 or GREY")
        self.full_scale = 65535.0 if fourcc.strip() == "Y16" else 255.0
        self.fps = float(fps)
        self.config = rs.config()
        if serial:
            self.config.enable_device(serial)
        self.config.enable_stream(rs.stream.infrared, 1, int(size[0]), int(size[1]), fmt, int(fps))
        self.pipeline = rs.pipeline()
        try:
            self.profile = self.config.resolve(rs.pipeline_wrapper(self.pipeline))
        except RuntimeError as e:
            raise CaptureError(f"realsense: {e}") from None
        self.sensor = self.profile.get_device().first_depth_sensor()
        self.started = False

    def _option(self, name: str, value: float) -> float:
        opt = getattr(self.rs.option, name)
        if not self.sensor.supports(opt):
            raise ControlError(f"realsense: the depth sensor has no option {name}")
        try:
            self.sensor.set_option(opt, float(value))
        except RuntimeError as e:
            raise ControlError(f"realsense: {name} = {value}: {e}") from None
        got = self.sensor.get_option(opt)
        if abs(got - value) > max(1.0, 0.01 * abs(value)):
            raise ControlError(f"realsense: {name} reads back {got} after setting {value}")
        return float(got)

    def set_exposure_us(self, us: float) -> float:
        self._option("enable_auto_exposure", 0)
        return self._option("exposure", us)

    def set_gain(self, gain: float) -> float:
        return self._option("gain", gain)

    def set_emitter(self, on: bool) -> None:
        self._option("emitter_enabled", 1 if on else 0)

    def start(self) -> None:
        if not self.started:
            self.pipeline.start(self.config)
            self.started = True

    def stop(self) -> None:
        if self.started:
            self.pipeline.stop()
            self.started = False

    def read(self, timeout: float = 2.0) -> Frame:
        try:
            frames = self.pipeline.wait_for_frames(int(timeout * 1000))
        except RuntimeError as e:
            raise CaptureError(f"realsense: {e}") from None
        f = frames.get_infrared_frame(1)
        return Frame(np.asanyarray(f.get_data()).copy(), int(f.get_frame_number()),
                     int(f.get_timestamp() * 1e6))

    def info(self) -> dict:
        dev = self.profile.get_device()
        return {"backend": self.name, "name": dev.get_info(self.rs.camera_info.name),
                "serial": dev.get_info(self.rs.camera_info.serial_number),
                "firmware": dev.get_info(self.rs.camera_info.firmware_version)}

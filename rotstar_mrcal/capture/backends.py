"""Open a capture backend by name; describe the video nodes for a first look at the hardware

SYNOPSIS

    >>> from rotstar_mrcal.capture.backends import BACKENDS, open_source
    >>> BACKENDS
    ('v4l2', 'libcamera', 'realsense', 'replay')

    src = open_source("v4l2", camera="d435")            # finds the D435's IR node
    src = open_source("replay", device="rec.npy")       # a recording

open_source returns a FrameSource (source.py) or raises CaptureError with
the reason. describe_nodes() is what `rotstar-capture --list` prints: every
video node with its USB id, capabilities, formats with sizes and frame
rates, controls with their values and, on a D4xx, the extension-unit values.
"""

from __future__ import annotations

from rotstar_mrcal.capture import d435
from rotstar_mrcal.capture.source import CaptureError, FrameSource
from rotstar_mrcal.capture.v4l2 import Device, Syscalls, V4L2Error

BACKENDS = ("v4l2", "libcamera", "realsense", "replay")


def open_source(backend: str = "v4l2", device: str | None = None, camera: str = "d435",
                fourcc: str = d435.DEFAULT_FOURCC, size=d435.DEFAULT_SIZE, fps: float | None = d435.DEFAULT_FPS,
                serial: str | None = None, sys: Syscalls | None = None, sysfs: str = "/sys/class/video4linux",
                dev_root: str = "/dev", stereo: bool = False) -> FrameSource:
    """A FrameSource for the backend; see the module docstring"""
    if backend == "v4l2":
        from rotstar_mrcal.capture.backend_v4l2 import V4L2Source

        if device is None:
            if camera != "d435":
                raise CaptureError("a generic V4L2 camera needs --device /dev/videoN")
            device = d435.find_ir_node(sysfs, dev_root, sys, serial).path
        return V4L2Source(device, fourcc, size, fps, camera, sys=sys, stereo=stereo)
    if stereo:
        raise CaptureError(f"both infrared imagers are recorded over V4L2, not the {backend} backend")
    if backend == "libcamera":
        from rotstar_mrcal.capture.backend_libcamera import LibcameraSource

        return LibcameraSource(camera=device or "1", size=size, pixelformat=fourcc.strip(), fps=fps)
    if backend == "realsense":
        from rotstar_mrcal.capture.backend_realsense import RealSenseSource

        return RealSenseSource(size=size, fourcc=fourcc.strip(), fps=fps or 25, serial=serial)
    if backend == "replay":
        from rotstar_mrcal.capture.backend_replay import ReplaySource

        if device is None:
            raise CaptureError("the replay backend needs --device RECORDING (a folder of frames, .npy, .raw or video)")
        return ReplaySource(device, size=size, fourcc=fourcc, fps=fps)
    raise CaptureError(f"unknown backend {backend!r}; known: {', '.join(BACKENDS)}")


def describe_nodes(sys: Syscalls | None = None, sysfs: str = "/sys/class/video4linux",
                   dev_root: str = "/dev") -> list[dict]:
    """Everything worth logging about every video node (errors included, never raised)"""
    out = []
    for node in d435.list_nodes(sysfs, dev_root):
        item = {"path": node.path, "name": node.name, "usb": node.model if node.vendor is not None else None,
                "interface": node.interface, "serial": node.serial}
        try:
            with Device(node.path, sys) as dev:
                cap = dev.querycap()
                item.update(card=cap.card, driver=cap.driver, bus=cap.bus_info,
                            capture=cap.is_video_capture, streaming=cap.can_stream)
                if cap.is_video_capture:
                    item["modes"] = {k.strip(): [f"{w}x{h}@" + "/".join(f"{r:g}" for r in rates)
                                                 for w, h, rates in v] for k, v in dev.modes().items()}
                    ctrls = {}
                    for c in dev.controls():
                        try:
                            ctrls[c.name] = dev.get_control(c.id)
                        except V4L2Error as e:
                            ctrls[c.name] = f"unreadable ({e})"
                    item["controls"] = ctrls
                    if node.is_d4xx and any(f in item["modes"] for f in ("Y16", "GREY", "Y8I")):
                        item["xu"] = d435.xu_state(dev)
        except V4L2Error as e:
            item["error"] = str(e)
        out.append(item)
    return out

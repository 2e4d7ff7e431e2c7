"""The RealSense D435 preset: find the IR node, pick the unrectified format, set the XU controls

SYNOPSIS

    from rotstar_mrcal.capture import d435
    node = d435.find_ir_node()            # by USB id and format list, never a fixed /dev/video2
    print(node.path, node.product)        # e.g. /dev/video2 D435
    with Device(node.path) as dev:
        dev.set_format(*d435.DEFAULT_SIZE, d435.DEFAULT_FOURCC)
        d435.set_exposure_us(dev, 4000)   # auto exposure off, then 4000 us (extension unit 3)
        d435.set_emitter(dev, False)      # IR projector off
        d435.xu_state(dev)                # {'exposure_us': 4000, 'auto_exposure': 0, ...}

The D4xx depth USB function (interface 0) carries two streaming pins, depth
(Z16) and left IR (GREY, Y8I, Y16), each with a metadata node on recent
kernels; /dev/video numbers depend on what else is plugged in. The IR node is
the video-capture node of an Intel (8086) D4xx product whose format list
holds Y16 or GREY.

Formats: GREY / Y8I (both imagers, 8-bit) are rectified and undistorted by the camera's ASIC with
its factory calibration, so calibrating on them estimates a virtual, nearly
distortion-free camera, not the lens. Y16 (1280x800 or 640x400, 15 or 25 fps)
is the unrectified calibration stream: the default; Y12I is the same for
both imagers, 12 bits each (interleaved.py). Its real bit depth (10
bits, low- or high-aligned?) is not documented; rotstar-capture logs the
value range it sees.

Exposure of the IR imagers is not the V4L2 exposure control (that one is the
RGB camera's, in 100 us units): it is selector 3 of extension unit 3, in
microseconds, effective only with selector 0x0B (auto exposure) at 0. Gain is
the standard V4L2 gain control (16-248). Sources: doc/capture.md, section 9.
"""

from __future__ import annotations

import dataclasses
import os
import re

from rotstar_mrcal.capture.source import CaptureError, ControlError
from rotstar_mrcal.capture.uvc_xu import D4XX, xu_get, xu_range, xu_set
from rotstar_mrcal.capture.v4l2 import Device, Syscalls, V4L2Error

INTEL_VENDOR = 0x8086
D4XX_PRODUCTS = {  # librealsense src/ds/d400/d400-private.h
    0x0AD1: "D400", 0x0AD2: "D410", 0x0AD3: "D415", 0x0AD4: "D430", 0x0AD5: "D430 (MM)",
    0x0AF6: "D420", 0x0AFE: "D420 (MM)", 0x0AFF: "D410 (MM)", 0x0B00: "D400 (MM)", 0x0B01: "D430 (RGB)",
    0x0B03: "D460", 0x0B07: "D435", 0x0B0C: "D405U", 0x0B3A: "D435i", 0x0B49: "D416", 0x0B4B: "D430i",
    0x0B4D: "D465", 0x0B5B: "D405", 0x0B5C: "D455",
}
DEFAULT_FOURCC = "Y16 "
DEFAULT_SIZE = (1280, 800)
DEFAULT_FPS = 25.0
IR_FORMATS = ("Y16 ", "GREY", "Y8I ", "Y12I")
EXPOSURE_RANGE_US = (1, 165000)


@dataclasses.dataclass(frozen=True)
class Node:
    """One /dev/videoN as sysfs describes it"""

    path: str
    name: str
    vendor: int | None
    product: int | None
    interface: int | None
    usb_path: str  # the USB device's sysfs folder ('' if not USB)
    serial: str = ""

    @property
    def is_d4xx(self) -> bool:
        return self.vendor == INTEL_VENDOR and self.product in D4XX_PRODUCTS

    @property
    def model(self) -> str:
        return D4XX_PRODUCTS.get(self.product, f"{self.vendor or 0:04x}:{self.product or 0:04x}")


def _read(path: str) -> str:
    try:
        with open(path) as f:
            return f.read().strip()
    except OSError:
        return ""


def _hex(s: str) -> int | None:
    try:
        return int(s, 16)
    except ValueError:
        return None


def list_nodes(sysfs: str = "/sys/class/video4linux", dev: str = "/dev") -> list[Node]:
    """Every video node, with its USB vendor/product/interface where it has one"""
    if not os.path.isdir(sysfs):
        return []
    out = []
    names = [n for n in os.listdir(sysfs) if re.fullmatch(r"video\d+", n)]
    for n in sorted(names, key=lambda s: int(s[5:])):
        base = os.path.join(sysfs, n)
        iface = os.path.realpath(os.path.join(base, "device"))
        usb = os.path.dirname(iface)
        vendor = _hex(_read(os.path.join(usb, "idVendor")))
        out.append(Node(
            path=os.path.join(dev, n),
            name=_read(os.path.join(base, "name")),
            vendor=vendor,
            product=_hex(_read(os.path.join(usb, "idProduct"))),
            interface=_hex(_read(os.path.join(iface, "bInterfaceNumber"))),
            usb_path=usb if vendor is not None else "",
            serial=_read(os.path.join(usb, "serial")),
        ))
    return out


def find_ir_node(sysfs: str = "/sys/class/video4linux", dev: str = "/dev", sys: Syscalls | None = None,
                 serial: str | None = None) -> Node:
    """The left-IR capture node of the (first, or the given serial's) D4xx camera

    Raises CaptureError naming every node looked at and why it was not it.
    """
    nodes = list_nodes(sysfs, dev)
    seen = []
    for node in nodes:
        if not node.is_d4xx:
            seen.append(f"{node.path} ({node.name or '?'}, {node.model}): not an Intel D4xx")
            continue
        if serial and node.serial != serial:
            seen.append(f"{node.path}: serial {node.serial}, not {serial}")
            continue
        try:
            with Device(node.path, sys) as d:
                cap = d.querycap()
                if not cap.is_video_capture:
                    seen.append(f"{node.path}: no video capture (metadata node)")
                    continue
                fmts = [f.fourcc for f in d.formats()]
        except V4L2Error as e:
            seen.append(str(e))
            continue
        if any(f in fmts for f in IR_FORMATS):
            return node
        seen.append(f"{node.path} ({node.model}): formats {', '.join(f.strip() for f in fmts) or 'none'} "
                    f"(no GREY/Y16: the depth or RGB pin)")
    detail = "; ".join(seen) if seen else f"no video nodes in {sysfs}"
    raise CaptureError(f"no RealSense D4xx infrared node found ({detail}). Is the camera on a USB 3 port? "
                       f"Does `v4l2-ctl --list-devices` show it? Otherwise pass --device /dev/videoN")


def format_warning(code: str) -> str | None:
    """Why a D4xx IR format is unsuitable for calibrating the lens, or None"""
    code = (code + "    ")[:4]
    if code in ("GREY", "Y8I "):
        return (f"{code.strip()} frames are rectified and undistorted by the camera with its factory "
                f"calibration: a calibration on them describes that virtual camera, not the lens; a quick "
                f"look only. Use Y16 (1280x800 or 640x400) to calibrate the imager, Y12I for both imagers")
    return None


# ---- extension-unit controls ---------------------------------------------------------
def _xu(what: str, f, *args):
    try:
        return f(*args)
    except V4L2Error as e:
        raise ControlError(f"{what}: {e}") from None


def set_exposure_us(dev: Device, us: float) -> int:
    """Auto exposure off, then manual exposure in microseconds; returns the value read back"""
    us = int(round(us))
    lo, hi = EXPOSURE_RANGE_US
    try:
        lo, hi = xu_range(dev, D4XX.unit, D4XX.EXPOSURE)
    except V4L2Error:
        pass
    if not lo <= us <= hi:
        raise ControlError(f"exposure {us} us is outside the camera's range {lo}-{hi} us")
    ae = _xu("auto exposure off (XU unit 3 selector 0x0B)", xu_set, dev, D4XX.unit, D4XX.AUTO_EXPOSURE, 0)
    if ae != 0:
        raise ControlError(f"auto exposure reads back {ae} after switching it off")
    got = _xu(f"exposure {us} us (XU unit 3 selector 3)", xu_set, dev, D4XX.unit, D4XX.EXPOSURE, us)
    if abs(got - us) > max(1, 0.01 * us):
        raise ControlError(f"exposure reads back {got} us after setting {us} us")
    return got


def set_emitter(dev: Device, on: bool) -> int:
    """IR projector on (laser) or off; falls back to laser power 0 where the emitter selector fails"""
    want = 1 if on else 0
    try:
        got = xu_set(dev, D4XX.unit, D4XX.EMITTER, want)
        if got != want:
            raise ControlError(f"emitter reads back {got} after setting {want}")
        return got
    except V4L2Error as e:
        if on:
            raise ControlError(f"emitter on (XU unit 3 selector 2): {e}") from None
        got = _xu(f"emitter off failed ({e}); laser power 0 (XU unit 3 selector 4)", xu_set,
                  dev, D4XX.unit, D4XX.LASER_POWER, 0)
        if got != 0:
            raise ControlError(f"laser power reads back {got} after setting 0") from None
        return 0


def xu_state(dev: Device) -> dict[str, int | str]:
    """Every D4xx XU value we use, or the error reading it (for the log)"""
    out = {}
    for sel, name in D4XX.names().items():
        try:
            out[name] = xu_get(dev, D4XX.unit, sel)
        except V4L2Error as e:
            out[name] = f"unreadable: {e}"
    return out

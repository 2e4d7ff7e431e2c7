"""UVC extension-unit controls (UVCIOC_CTRL_QUERY) and the Intel D4xx depth unit

SYNOPSIS

    from rotstar_mrcal.capture.v4l2 import Device
    from rotstar_mrcal.capture.uvc_xu import D4XX, xu_get, xu_set
    with Device("/dev/video2") as dev:
        xu_set(dev, D4XX.unit, D4XX.AUTO_EXPOSURE, 0)          # manual exposure
        xu_set(dev, D4XX.unit, D4XX.EXPOSURE, 4000)            # microseconds
        xu_set(dev, D4XX.unit, D4XX.EMITTER, 0)                # IR projector off
        xu_get(dev, D4XX.unit, D4XX.EXPOSURE)                  # -> 4000

The RealSense D4xx cameras keep depth/IR exposure, auto-exposure, the
emitter and the laser power in a vendor extension unit, which V4L2 does not
map to controls (v4l2-ctl cannot set them). uvcvideo passes raw queries
through: ioctl(fd, UVCIOC_CTRL_QUERY, struct uvc_xu_control_query {u8 unit;
u8 selector; u8 query; u16 size; u8 *data}). Any video node of the camera's
depth interface reaches the unit (they share one VideoControl interface).
Values are little-endian; each selector's size is asked for with
UVC_GET_LEN first, so a firmware with another size fails loudly instead of
writing garbage. Unit, GUID and selectors: librealsense src/ds/ds-private.h
(doc/capture.md, section 9).
"""

from __future__ import annotations

import ctypes as C
import dataclasses

from rotstar_mrcal.capture.v4l2 import Device, V4L2Error, _IOWR

UVC_SET_CUR = 0x01
UVC_GET_CUR = 0x81
UVC_GET_MIN = 0x82
UVC_GET_MAX = 0x83
UVC_GET_RES = 0x84
UVC_GET_LEN = 0x85
UVC_GET_INFO = 0x86
UVC_GET_DEF = 0x87


class uvc_xu_control_query(C.Structure):
    _fields_ = [("unit", C.c_uint8), ("selector", C.c_uint8), ("query", C.c_uint8), ("size", C.c_uint16),
                ("data", C.POINTER(C.c_uint8))]


UVCIOC_CTRL_QUERY = _IOWR("u", 0x21, uvc_xu_control_query)  # 0xc0107521 on 64-bit


@dataclasses.dataclass(frozen=True)
class _D4xx:
    """The D4xx depth extension unit (librealsense ds::depth_xu)"""

    unit: int = 3
    guid: str = "C9606CCB-594C-4D25-AF47-CCC496435995"
    EMITTER: int = 2  # u8: 0 off, 1 laser, 2 laser auto, 3 LED
    EXPOSURE: int = 3  # u32, microseconds
    LASER_POWER: int = 4  # u16, mW; 0 = off
    AUTO_EXPOSURE: int = 0x0B  # u8: 0 manual, 1 auto

    def names(self) -> dict[int, str]:
        return {self.EMITTER: "emitter", self.EXPOSURE: "exposure_us", self.LASER_POWER: "laser_power",
                self.AUTO_EXPOSURE: "auto_exposure"}


D4XX = _D4xx()


def xu_query(dev: Device, unit: int, selector: int, query: int, data: bytearray) -> bytearray:
    """One raw query; data is read (SET_CUR) or filled (GET_*) in place"""
    buf = (C.c_uint8 * max(len(data), 1)).from_buffer(data) if len(data) else (C.c_uint8 * 1)()
    q = uvc_xu_control_query(unit=unit, selector=selector, query=query, size=len(data),
                             data=C.cast(buf, C.POINTER(C.c_uint8)))
    names = {UVC_SET_CUR: "SET_CUR", UVC_GET_CUR: "GET_CUR", UVC_GET_LEN: "GET_LEN", UVC_GET_MIN: "GET_MIN",
             UVC_GET_MAX: "GET_MAX", UVC_GET_DEF: "GET_DEF", UVC_GET_INFO: "GET_INFO", UVC_GET_RES: "GET_RES"}
    dev.ioctl(UVCIOC_CTRL_QUERY, q, f"UVCIOC_CTRL_QUERY unit {unit} selector {selector} {names.get(query, hex(query))}")
    del buf
    return data


def xu_len(dev: Device, unit: int, selector: int) -> int:
    """The size in bytes of a selector's value (UVC_GET_LEN)"""
    return int.from_bytes(xu_query(dev, unit, selector, UVC_GET_LEN, bytearray(2)), "little")


def xu_get(dev: Device, unit: int, selector: int, query: int = UVC_GET_CUR) -> int:
    """A selector's current (or min/max/default) value as an unsigned integer"""
    n = xu_len(dev, unit, selector)
    return int.from_bytes(xu_query(dev, unit, selector, query, bytearray(n)), "little")


def xu_set(dev: Device, unit: int, selector: int, value: int) -> int:
    """Set a selector and read it back"""
    n = xu_len(dev, unit, selector)
    if not 0 <= value < 1 << (8 * n):
        raise V4L2Error(f"{dev.path}: unit {unit} selector {selector}: {value} does not fit in {n} byte(s)")
    xu_query(dev, unit, selector, UVC_SET_CUR, bytearray(int(value).to_bytes(n, "little")))
    return xu_get(dev, unit, selector)


def xu_range(dev: Device, unit: int, selector: int) -> tuple[int, int]:
    return xu_get(dev, unit, selector, UVC_GET_MIN), xu_get(dev, unit, selector, UVC_GET_MAX)

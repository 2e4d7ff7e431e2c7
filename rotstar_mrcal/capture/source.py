"""What every capture backend is: a source of grey frames with a few controls

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.capture.source import ArraySource, record
    >>> src = ArraySource(np.zeros((5, 4, 6), np.uint16))
    >>> rec = record(src, 3)
    >>> rec.frames.shape, rec.sequence.tolist(), rec.dropped
    ((3, 4, 6), [0, 1, 2], 0)

A backend (v4l2, libcamera, realsense, replay) is a FrameSource:

    start(), stop(), close()        streaming on / off
    read(timeout) -> Frame | None   the next frame; None at the end of a replay
    set_exposure_us(us) -> float    manual exposure, microseconds; the value read back
    set_gain(g) -> float            sensor gain in the camera's units; read back
    set_emitter(on) -> None         a structured-light projector on / off
    info() -> dict                  what to log: device, format, controls
    full_scale, fps                 255 / 65535, frames per second (0: unknown)

A control the backend cannot set raises ControlError with the reason, so the
CLI can stop (or go on with --force). Frames are numpy arrays in the camera's
own units (uint8 or uint16), never colour-converted or scaled.
"""

from __future__ import annotations

import dataclasses

import numpy as np


class CaptureError(Exception):
    """The camera cannot be opened or streamed; the message says why"""


class ControlError(CaptureError):
    """A control cannot be set (or does not read back what was set)"""


@dataclasses.dataclass
class Frame:
    image: np.ndarray  # (H, W) uint8 or uint16
    sequence: int  # frame counter; gaps are dropped frames
    t_ns: int = 0  # time stamp, ns (0: unknown)


class FrameSource:
    """Base class of the backends; see the module docstring"""

    name = "source"
    full_scale = 65535.0
    fps = 0.0

    def start(self) -> None:
        pass

    def stop(self) -> None:
        pass

    def close(self) -> None:
        self.stop()

    def read(self, timeout: float = 2.0) -> Frame | None:
        raise NotImplementedError

    def set_exposure_us(self, us: float) -> float:
        raise ControlError(f"{self.name}: exposure cannot be set")

    def set_gain(self, gain: float) -> float:
        raise ControlError(f"{self.name}: gain cannot be set")

    def set_emitter(self, on: bool) -> None:
        raise ControlError(f"{self.name}: no emitter control")

    def info(self) -> dict:
        return {"backend": self.name}

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class ArraySource(FrameSource):
    """Frames from an array (T, H, W) held in memory (or a np.memmap)"""

    name = "array"

    def __init__(self, frames: np.ndarray, sequence=None, fps: float = 0.0):
        self.frames = frames
        self.sequence = np.arange(len(frames)) if sequence is None else np.asarray(sequence)
        self.fps = fps
        self.full_scale = 255.0 if frames.dtype == np.uint8 else 65535.0
        self.pos = 0

    def read(self, timeout: float = 2.0) -> Frame | None:
        if self.pos >= len(self.frames):
            return None
        i = self.pos
        self.pos += 1
        t = int(self.sequence[i] / self.fps * 1e9) if self.fps else 0
        return Frame(np.asarray(self.frames[i]), int(self.sequence[i]), t)

    def info(self) -> dict:
        return {"backend": self.name, "frames": len(self.frames), "shape": list(self.frames.shape[1:]),
                "dtype": str(self.frames.dtype)}


@dataclasses.dataclass
class Recording:
    """Consecutive frames of one source"""

    frames: np.ndarray  # (T, H, W) uint8 / uint16
    sequence: np.ndarray  # (T,) frame counters
    t_ns: np.ndarray  # (T,) time stamps
    full_scale: float
    fps: float = 0.0

    @property
    def dropped(self) -> int:
        """Frames the driver lost: gaps in the sequence numbers"""
        if len(self.sequence) < 2:
            return 0
        return int(np.sum(np.maximum(np.diff(self.sequence) - 1, 0)))


def record(source: FrameSource, n: int, timeout: float = 2.0, out: np.ndarray | None = None) -> Recording:
    """Read up to n frames (fewer if a replay ends) into one array

    out: a preallocated (n, H, W) array (e.g. a np.memmap on disk for long
    recordings); by default the frames are stacked in memory.
    """
    frames, seq, ts = [], [], []
    for i in range(n):
        f = source.read(timeout)
        if f is None:
            break
        if out is not None:
            out[i] = f.image
        else:
            frames.append(f.image)
        seq.append(f.sequence)
        ts.append(f.t_ns)
    if not seq:
        raise CaptureError(f"{source.name}: no frames")
    arr = out[: len(seq)] if out is not None else np.stack(frames)
    return Recording(arr, np.array(seq, np.int64), np.array(ts, np.int64), source.full_scale, source.fps)


def skip(source: FrameSource, n: int, timeout: float = 2.0) -> int:
    """Read and drop n frames (a new exposure takes a few frames to settle); returns how many were read"""
    k = 0
    for _ in range(n):
        if source.read(timeout) is None:
            break
        k += 1
    return k

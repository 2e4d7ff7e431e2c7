"""Several cameras recorded together: the D435's two infrared imagers and, optionally, its colour camera

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.capture.source import ArraySource
    >>> from rotstar_mrcal.capture.rig import RigSource, record_rig
    >>> rig = RigSource([ArraySource(np.zeros((5, 4, 6), np.uint16)), ArraySource(np.ones((5, 3, 3), np.uint8))])
    >>> rig.cameras, rig.full_scales
    (2, [65535.0, 255.0])
    >>> recs = record_rig(rig, 3)
    >>> [r.frames.shape for r in recs], recs[1].sequence.tolist()
    ([(3, 4, 6), (3, 3, 3)], [0, 1, 2])

A RigSource reads its sources in lockstep, one step per frame of the first
source (the clock: the D435's infrared node, whose one Y12I buffer holds
the left and the right imager of the same instant, so those two are
synchronised by construction). Each other source (the colour camera: its
own USB interface and clock, not hardware-synchronised with the infrared
pair by default) gives, at every step, its newest frame: the ones queued
before it are dropped, and a camera slower than the clock repeats its last
frame (read_latest). Every camera's recording thus has one frame per step,
frame t of each camera taken within about one frame period of the others.

That is enough because the player holds every pattern frame still for many
camera frames: segmentation (segment.segment_rig) finds the displayed
frames on one camera and takes the same frames of every camera, after
checking that each camera saw one still pattern frame there (the frames a
late camera shows in transition at the edges of a stretch are left out).
Each camera's sequence numbers and time stamps are kept, so the offset
between the cameras can be read from the log.

Exposure, gain and the emitter go to the first source (the infrared node:
the same settings as a one-camera capture); a colour camera keeps its own
(rotstar-capture --rgb-exposure sets it through the standard controls).
read() returns the first camera's frame (for skipping and waiting for
stillness) but reads every source, so that none falls behind.
"""

from __future__ import annotations

import numpy as np

from rotstar_mrcal.capture.source import CaptureError, Frame, FrameSource, Recording


def _views(src: FrameSource, timeout: float) -> list[Frame] | None:
    if hasattr(src, "read_views"):
        return src.read_views(timeout)
    f = src.read(timeout)
    return None if f is None else [f]


def _latest(src: FrameSource, timeout: float) -> list[Frame] | None:
    if hasattr(src, "read_latest"):
        return src.read_latest(timeout)
    return _views(src, timeout)


def source_views(src: FrameSource) -> int:
    """How many cameras one source gives (2 for a stereo buffer)"""
    return int(getattr(src, "views", 1))


class RigSource(FrameSource):
    """Several FrameSources read in lockstep; see the module docstring"""

    name = "rig"

    def __init__(self, sources: list[FrameSource]):
        if not sources:
            raise CaptureError("a rig needs at least one source")
        self.sources = sources
        self.cameras = sum(source_views(s) for s in sources)
        self.full_scales = [float(s.full_scale) for s in sources for _ in range(source_views(s))]
        self.full_scale = self.full_scales[0]
        self.fps = sources[0].fps

    def read_views(self, timeout: float = 2.0) -> list[Frame] | None:
        """One frame per camera, or None when a source (a replay) has ended"""
        out = _views(self.sources[0], timeout)
        if out is None:
            return None
        for s in self.sources[1:]:
            v = _latest(s, timeout)
            if v is None:
                return None
            out = out + v
        return out

    def read(self, timeout: float = 2.0) -> Frame | None:
        v = self.read_views(timeout)
        return None if v is None else v[0]

    def start(self) -> None:
        for s in self.sources:
            s.start()

    def stop(self) -> None:
        for s in self.sources:
            s.stop()

    def close(self) -> None:
        for s in self.sources:
            s.close()

    def set_exposure_us(self, us: float) -> float:
        return self.sources[0].set_exposure_us(us)

    def set_gain(self, gain: float) -> float:
        return self.sources[0].set_gain(gain)

    def set_emitter(self, on: bool) -> None:
        self.sources[0].set_emitter(on)

    def info(self) -> dict:
        first = self.sources[0].info()
        return {**first, "cameras": self.cameras, "sources": [first] + [s.info() for s in self.sources[1:]]}


def record_rig(rig: RigSource, n: int, timeout: float = 2.0, outs: list[np.ndarray] | None = None,
               first: list[Frame] | None = None) -> list[Recording]:
    """Up to n lockstep steps (fewer if a replay ends) -> one Recording per camera, all of one length

    outs: preallocated (n, H, W) arrays per camera (np.memmap for long
    recordings); first: the views of a step already read (it becomes step 0).
    """
    seq, ts, stacks = [], [], [[] for _ in range(rig.cameras)]
    for i in range(n):
        v = first if (i == 0 and first is not None) else rig.read_views(timeout)
        if v is None:
            break
        if len(v) != rig.cameras:
            raise CaptureError(f"a rig step gave {len(v)} frames for {rig.cameras} cameras")
        for k, f in enumerate(v):
            if outs is not None:
                if f.image.shape != outs[k].shape[1:]:
                    raise CaptureError(f"camera {k}: a {f.image.shape[1]}x{f.image.shape[0]} frame in a "
                                       f"{outs[k].shape[2]}x{outs[k].shape[1]} recording")
                outs[k][i] = f.image
            else:
                stacks[k].append(f.image)
        seq.append([f.sequence for f in v])
        ts.append([f.t_ns for f in v])
    if not seq:
        raise CaptureError(f"{rig.name}: no frames")
    seq, ts = np.array(seq, np.int64), np.array(ts, np.int64)
    recs = []
    for k in range(rig.cameras):
        arr = outs[k][: len(seq)] if outs is not None else np.stack(stacks[k])
        recs.append(Recording(arr, seq[:, k], ts[:, k], rig.full_scales[k], rig.fps))
    return recs

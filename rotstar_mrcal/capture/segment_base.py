"""What segmentation returns and takes: the options, the stretches, the verdicts, the error (no method here)

capture.segment (between start markers) and capture.content (by content, any
window of the loop) both fill a Segmentation; capture.segment re-exports
everything here.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np


class SegmentError(Exception):
    """The recording cannot be split into the pattern's frames; the message says why"""


@dataclasses.dataclass(frozen=True)
class Options:
    step: int = 4  # area downsampling of the difference signal
    k: float = 6.0  # threshold: median + k robust sigmas ...
    ratio: float = 3.0  # ... and at least ratio x the median
    min_len: int = 4  # camera frames in the shortest stable stretch
    guard: int = 1  # frames dropped at each end of a stretch
    average: int = 8  # middle frames averaged per stretch
    min_average: int = 2  # fewer frames left after the guards: the stretch is too short
    max_motion: float = 0.5  # px, drift over one loop
    min_correlation: float = 0.9  # recorded vs expected levels of a loop
    min_still: float = 0.3  # fraction of frames in stable stretches
    max_jitter: float = 5.0  # frames of a stretch may differ by this many times the sensor noise
    method: str = "auto"  # 'loop' (two start markers), 'content' (capture.content), 'auto' (loop, else content)
    content_step: int = 2  # content: area downsampling of the frames compared (a thin blended band survives 2x)
    content_k: float = 5.0  # content: a pixel differs beyond this many sigmas of the noise ...
    content_fraction: float = 0.003  # ... and two frames differ when more than this fraction of pixels do
    content_class_fraction: float = 0.02  # content: two runs show different displayed frames when more differ
    hold: int = 0  # content: the player's hold for every kind, refreshes (0: pattern.loop.SHORT_HOLDS per kind)
    marker_hold: int = 0  # content: the start marker's hold (0: as hold says)
    refresh_hz: float = 60.0  # content: the screen's refresh rate (with times in seconds: each entry's time)
    content_timing: float = 1.0  # content: a visit's time may be off by this many (mean of two) entry durations
    content_spare: bool = True  # content: a pose may lack the frames pattern.layout.SPARE_KINDS allows (one identity
    #                             frame, the checkerboard); False: every frame of pattern.json or SegmentError
    content_blend_z: float = 6.0  # content: a camera frame blending in the entry before or after by this many sigmas
    #                               in some rows is not averaged (content.blend_free; 0: every clean frame averaged)


@dataclasses.dataclass
class Stretch:
    start: int  # first frame
    stop: int  # one past the last frame
    core: tuple[int, int]  # the frames averaged
    level: float  # mean level of the core, fraction of full scale
    truncated: bool  # touches the start or the end of the recording

    @property
    def length(self) -> int:
        return self.stop - self.start


@dataclasses.dataclass
class LoopVerdict:
    marker: int  # index of its start marker in the stretch list
    stretches: list[int]  # stretch index of every loop entry (marker first), if complete
    ok: bool
    reason: str  # why rejected, or ''
    correlation: float = math.nan
    motion_px: float = math.nan
    min_average: int = 0


@dataclasses.dataclass
class Segmentation:
    images: dict[str, np.ndarray]  # pattern.json file -> (H, W) float64 average, recorded units
    ranges: dict[str, tuple[int, int]]  # pattern.json file -> frames averaged [a, b)
    stretches: list[Stretch]
    markers: np.ndarray  # (nstretch,) bool
    loops: list[LoopVerdict]
    chosen: int  # index into loops
    d: np.ndarray  # the difference signal
    level: np.ndarray  # per-frame mean level
    tau: float
    mask: np.ndarray | None = None  # the downsampled pixels d and level average over (None: all)
    method: str = "loop"  # how it was split: 'loop' (between start markers) or 'content' (capture.content)
    used: dict[str, list[int]] | None = None  # content: pattern.json file -> every camera frame averaged
    missing: list[str] = dataclasses.field(default_factory=list)  # content: files not seen clean, which the pose
    #                                                               can do without (pattern.layout.unspared)

    @property
    def loop(self) -> LoopVerdict:
        return self.loops[self.chosen]

    def summary(self) -> str:
        lv = self.loop
        if self.method == "content":
            n = sum(len(u) for u in (self.used or {}).values())
            return (f"{len(self.stretches)} clean visits of displayed frames found by their content; {n} camera "
                    f"frames averaged, >= {lv.min_average} per pattern frame, drift {lv.motion_px:.2f} px, level "
                    f"correlation {lv.correlation:.3f}" + (f"; not seen: {', '.join(self.missing)}" if self.missing
                                                           else ""))
        n_ok = sum(v.ok for v in self.loops)
        return (f"{len(self.stretches)} stretches, {len(self.loops)} loop(s) seen, {n_ok} usable; using the one "
                f"starting at frame {self.stretches[lv.marker].start}: >= {lv.min_average} frames averaged per "
                f"pattern frame, drift {lv.motion_px:.2f} px, level correlation {lv.correlation:.3f}")


def check_order(rec: np.ndarray, want: np.ndarray, min_correlation: float) -> tuple[float, str]:
    """(correlation, '' or why the recorded levels do not follow the expected ones)"""
    if np.std(rec) == 0 or np.std(want) == 0:
        return 0.0, "flat levels"
    r = float(np.corrcoef(rec, want)[0, 1])
    dw, dr = np.diff(want), np.diff(rec)
    big = np.abs(dw) > 0.25 * np.ptp(want)
    wrong = np.flatnonzero(big & (np.sign(dw) != np.sign(dr)))
    if r < min_correlation:
        return r, f"levels do not follow pattern.json (correlation {r:.2f} < {min_correlation})"
    if len(wrong):
        return r, f"level steps disagree with pattern.json between loop entries {wrong[0]} and {wrong[0] + 1}"
    return r, ""


def _mean(frames, a: int, b: int) -> np.ndarray:
    acc = np.zeros(np.shape(frames[a]), np.float64)
    for t in range(a, b):
        acc += frames[t]
    return acc / (b - a)


def threshold(d: np.ndarray, k: float = 6.0, ratio: float = 3.0) -> float:
    """Robust threshold separating the noise floor of d from the changes

    SYNOPSIS

        >>> d = np.r_[np.nan, np.full(50, 0.01), 0.2, np.full(50, 0.01)]
        >>> round(threshold(d), 3)
        0.03
    """
    v = d[np.isfinite(d)]
    if len(v) == 0:
        raise SegmentError("the recording has fewer than two frames")
    med = float(np.median(v))
    mad = float(np.median(np.abs(v - med))) * 1.4826
    return med + max(k * mad, (ratio - 1) * med, 1e-9)

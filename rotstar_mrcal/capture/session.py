"""A capture session: record a pose, split it into the displayed frames, check it, write it

SYNOPSIS

    from rotstar_mrcal.capture.session import OutputDataset, SessionOptions, capture_one
    ds = OutputDataset("seq/exp4000us", 4000)
    out = capture_one(src, ds, "pose000", pattern, layout, nframes, "seq/raw", SessionOptions())
    out.ok, out.messages, out.folder      # a board was found; lines for the user; the pose folder
    ds.display.summary()                  # the screen's per-frame offsets over the poses so far

rotstar-capture drives these for every pose and exposure; nothing here
prints. A recording goes to a memory map (2.2 loops of the default sequence
with its identity frames, 633 Y16 frames of a D435, are 1.3 GB), is segmented as rotstar-segment does (capture.segment), detected at
once (capture.pose.quick_check), written as a pose folder of the dataset, and
counted into the coverage of the imager and the display offsets of the
session (detect.display: a pose whose frames moved against the others'
offsets is a camera that moved).
"""

from __future__ import annotations

import collections
import dataclasses
import json
import os

import cv2
import numpy as np

from rotstar_mrcal.atomic import allocated_npy, atomic_path, atomic_write
from rotstar_mrcal.detect.display_offsets import DisplayCheck, dataset_offsets
from rotstar_mrcal.vnl import mrcal_keeps, mrcal_min_corners
from rotstar_mrcal.capture import coverage
from rotstar_mrcal.capture.motion import difference_signal, downsample, noise_floor, screen_pixels, still_fraction
from rotstar_mrcal.capture.pose import quick_check, value_scale, write_segmented
from rotstar_mrcal.capture.content import agreeing_fraction
from rotstar_mrcal.capture.segment import Options, SegmentError, segment, threshold
from rotstar_mrcal.capture.source import CaptureError, FrameSource, record


@dataclasses.dataclass
class SessionOptions:
    segment: Options = dataclasses.field(default_factory=Options)
    keep_raw: bool = False  # keep OUT/raw/<pose>.npy (+ .json) after segmentation
    until_enough: int = 0  # > 0: record this many frames, then more (a third as many at a time) until every frame
    #                        of pattern.json has opts.segment.min_average clean camera frames, at most nframes


@dataclasses.dataclass
class PoseOutcome:
    """What one recording gave: a board or not, the lines to show, the pose folder written"""

    ok: bool
    messages: list[str]
    folder: str | None = None


class OutputDataset:
    """One output dataset (one exposure): its folder, corners so far, value scale, display offsets"""

    def __init__(self, folder: str, exposure: int | None, camera: str | None = None):
        self.folder, self.exposure = folder, exposure
        self.camera = camera  # a rig's camera-<k>: poses go to <pose>/<camera>, coverage to coverage-<camera>.png
        self.boards: list[np.ndarray] = []
        self.names: list[str] = []  # the pose of each board
        self.shifts: dict = {}  # pose -> FrameShifts
        self.imagersize = None
        self.scale: float | None = None
        self.tau: float | None = None  # stability threshold of the latest recording (for --auto)
        self.log: list[dict] = []

    @property
    def label(self) -> str:
        return f"{self.exposure} us" if self.exposure else ""

    def what(self, pose: str) -> str:
        """'pose003' or 'pose003 at 4000 us', for messages (with the camera of a rig)"""
        return (f"{pose} at {self.label}" if self.exposure else pose) + (f" {self.camera}" if self.camera else "")

    def pose_folder(self, pose: str) -> str:
        """The pose folder's name inside the dataset: <pose>, or <pose>/camera-<k> for a rig's camera"""
        return f"{pose}/{self.camera}" if self.camera else pose

    @property
    def coverage_file(self) -> str:
        return os.path.join(self.folder, f"coverage-{self.camera}.png" if self.camera else "coverage.png")

    @property
    def display(self) -> DisplayCheck:
        return dataset_offsets(self.shifts)

    @property
    def good(self) -> int:
        return sum(1 for e in self.log if e.get("ok"))


def wait_for_new_view(src: FrameSource, tau: float, fps: float, still_s: float, need_motion: bool,
                      step: int = 4, by_content: bool = False) -> bool:
    """Read frames until the view has moved (if need_motion) and then stayed still; False at the end

    Still and moving are motion.is_still over the last still_s seconds: still
    when 75 % of consecutive frames agree up to noise, moving below 30 %.
    by_content (the player's short holds, where a still view changes every
    two or three camera frames): consecutive frames compared as the split by
    content does (content.agreeing_fraction): still when 30 % agree, moving
    below 10 %.
    """
    n = max(10, int(round(still_s * (fps or 25))))
    window = collections.deque(maxlen=n + 1)
    moving_below, still_at = (0.1, 0.3) if by_content else (0.3, 0.75)
    moved = not need_motion
    while True:
        f = src.read()
        if f is None:
            return False
        small = downsample(f.image, step)
        window.append(small.ravel() / np.float32(src.full_scale) if by_content else small)
        if len(window) < window.maxlen:
            continue
        agree = _agreeing(window, f.image, src.full_scale, step) if by_content else \
            still_fraction(difference_signal(list(window), src.full_scale, step=1)[0], tau)
        if not moved and agree < moving_below:
            moved = True
        elif moved and agree >= still_at:
            return True


def _agreeing(window, image: np.ndarray, full_scale: float, step: int) -> float:
    """The fraction of the window's consecutive frames that agree, as the split by content compares them"""
    # the noise of two block means' difference, from within the frame (motion.noise_floor's mean |difference|)
    sigma = noise_floor(image, full_scale, step) / 1.128 * np.sqrt(2)
    return agreeing_fraction(np.stack(window), sigma)


def board_state(corners: np.ndarray) -> str:
    """'complete', or how many corners are missing and whether mrcal will use the board

    >>> board_state(np.zeros((9, 14, 2)))
    'complete'
    >>> c = np.zeros((9, 14, 2)); c[3:] = np.nan
    >>> board_state(c)
    '84 corner(s) missing'
    >>> c[1:] = np.nan; c[1, :4] = 0                       # 18 corners
    >>> board_state(c)
    '108 corner(s) missing: too few for mrcal, which ignores boards with <= 18'
    """
    ny, nx = corners.shape[:2]
    n = int(np.isfinite(corners).all(axis=-1).sum())
    if n == nx * ny:
        return "complete"
    return (f"{nx * ny - n} corner(s) missing" + ("" if mrcal_keeps(corners) else
            f": too few for mrcal, which ignores boards with <= {mrcal_min_corners(nx, ny)}"))


def next_free_pose(folders: list[str]) -> int:
    """The first k such that no folder holds pose<k>"""
    k = 0
    while any(os.path.isdir(os.path.join(f, f"pose{k:03d}")) for f in folders):
        k += 1
    return k


def capture_one(src: FrameSource, ds: OutputDataset, pose: str, pattern: dict, layout, nframes: int, raw_dir: str,
                opts: SessionOptions) -> PoseOutcome:
    """Record nframes, then process_recording; raises EOFError when the source has nothing left

    The recording goes to raw_dir/<pose>[_exp<us>us].npy (its disk space
    allocated first: CaptureError "...: no space left on device" if there is
    none), removed afterwards unless opts.keep_raw.
    """
    os.makedirs(raw_dir, exist_ok=True)
    tag = f"{pose}_exp{ds.exposure}us" if ds.exposure else pose
    raw = os.path.join(raw_dir, tag + ".npy")
    first = src.read()
    if first is None:
        raise EOFError
    try:
        buf = allocated_npy(raw, first.image.dtype, (nframes,) + first.image.shape)
    except OSError as e:  # a full disk: said before recording, not a SIGBUS half-way
        raise CaptureError(str(e)) from None
    try:
        buf[0] = first.image
        if opts.until_enough:
            seqnums, ended = record_until_enough(src, buf, first.sequence, pattern, layout, opts)
        else:
            rec = record(src, nframes - 1, out=buf[1:]) if nframes > 1 else None
            seqnums = np.r_[first.sequence, rec.sequence] if rec else np.array([first.sequence])
            ended = len(seqnums) < nframes
        n = len(seqnums)
        if opts.keep_raw:
            buf.flush()
            with atomic_write(os.path.join(raw_dir, tag + ".json")) as f:
                json.dump({"sequence": [int(v) for v in seqnums], "fps": src.fps, "exposure_us": ds.exposure,
                           "frames": n}, f)
        short = [f"{ds.what(pose)}: the source ended after {n} of {nframes} frames"] if ended else []
        out = process_recording(ds, pose, pattern, layout, buf[:n], seqnums, src.full_scale, opts, src.fps)
        out.messages[:0] = short
        if src.fps:  # the time the camera and the screen stood still for this recording
            secs = (int(seqnums[-1]) - int(seqnums[0]) + 1) / src.fps
            ds.log[-1]["seconds"] = secs
            out.messages.append(f"{ds.what(pose)}: {secs:.1f} s at the screen ({n} camera frames)")
        return out
    finally:
        del buf
        if not opts.keep_raw:
            os.remove(raw)


def enough(frames, seqnums: np.ndarray, pattern: dict, layout, full_scale: float, opts: SessionOptions,
           fps: float) -> bool:
    """Every frame of pattern.json split off with at least opts.segment.min_average clean camera frames"""
    try:
        seg = segment(frames, pattern["frames"], layout, full_scale, opts.segment,
                      times=np.asarray(seqnums) / fps if fps else None)
    except SegmentError:
        return False
    counts = [len(u) for u in seg.used.values()] if seg.used else \
        [b - a for a, b in seg.ranges.values()]
    return min(counts) >= opts.segment.min_average


def record_until_enough(src: FrameSource, buf, first_seq: int, pattern: dict, layout,
                        opts: SessionOptions) -> tuple[np.ndarray, bool]:
    """Record into buf (buf[0] holds the first frame) until enough() or buf is full: (the sequence numbers,
    whether the source ended first)

    The first look is opts.until_enough frame periods, then a third of that
    at a time: periods by the sequence numbers, so that a frame the camera
    lost counts as the time it took (a look ends at the same moment whatever
    was lost). (While a look is split, a camera's driver may drop frames:
    they are gaps in the sequence numbers, which segmentation takes as time.)
    """
    seq = [first_seq]
    want = opts.until_enough  # frame periods since the first frame
    while True:
        ended = False
        while not ended and len(seq) < len(buf) and seq[-1] - seq[0] + 1 < want:
            n = len(seq)
            more = min(max(1, (want - (seq[-1] - seq[0] + 1)) // 2), len(buf) - n)  # halves: a frame lost in a
            #                                                            chunk does not carry the look past `want`
            try:
                got = record(src, more, out=buf[n:n + more]).sequence.tolist()
            except CaptureError:  # the source has nothing left
                got = []
            seq += got
            ended = len(got) < more
        if ended or len(seq) >= len(buf) or enough(buf[:len(seq)], np.array(seq), pattern, layout, src.full_scale,
                                                   opts, src.fps):
            break
        want = seq[-1] - seq[0] + 1 + max(1, opts.until_enough // 3)
    return np.array(seq), ended


def process_recording(ds: OutputDataset, pose: str, pattern: dict, layout, frames: np.ndarray, seqnums: np.ndarray,
                      full_scale: float, opts: SessionOptions, fps: float = 0.0) -> PoseOutcome:
    """Segment, check and write one recording into ds; see the module doc (fps: the camera's, 0 if unknown)"""
    so = opts.segment
    entry = {"pose": pose, "exposure_us": ds.exposure, "frames": len(frames),
             "dropped": int(np.sum(np.maximum(np.diff(seqnums) - 1, 0)))}
    ds.log.append(entry)
    try:
        seg = segment(frames, pattern["frames"], layout, full_scale, so,
                      times=np.asarray(seqnums) / fps if fps else None)
        ds.tau = seg.tau
    except SegmentError as e:
        d, _ = difference_signal(frames, full_scale, so.step, screen_pixels(frames, full_scale, so.step))
        ds.tau = threshold(d, so.k, so.ratio)  # as segment() would have set it
        entry.update(ok=False, error=str(e))
        return PoseOutcome(False, [f"{ds.what(pose)}: not usable: {e}"])
    return process_segmented(ds, pose, pattern, layout, seg, frames.shape, full_scale, entry)


def process_segmented(ds: OutputDataset, pose: str, pattern: dict, layout, seg, shape: tuple, full_scale: float,
                      entry: dict) -> PoseOutcome:
    """Check and write one segmented recording into ds (value scale, quick detection, coverage)"""
    messages = []
    if ds.scale is None:
        ds.scale, note = value_scale(max(float(np.max(im)) for im in seg.images.values()), full_scale)
        if note:
            messages.append(f"note{f' ({ds.label})' if ds.label else ''}: {note}")
    r = quick_check(seg, layout, pattern, full_scale / ds.scale)  # the averages are not scaled yet
    total = layout.nx * layout.ny
    entry.update(summary=seg.summary(), drift_px=seg.loop.motion_px, found=r.found, corners=r.n_valid,
                 error=r.error)
    extra = {"exposure_us": ds.exposure, "dropped_camera_frames": entry["dropped"],
             "quick_check": {"corners": r.n_valid, "motion_px": r.motion_px}}
    if not r.found:
        entry.update(ok=False, extra=extra)
        return PoseOutcome(False, messages + [f"{ds.what(pose)}: no board: {r.error}"])
    folder = write_segmented(ds.folder, ds.pose_folder(pose), seg, pattern, full_scale, ds.scale, extra)
    ds.boards.append(r.corners)
    ds.names.append(pose)
    ds.imagersize = (shape[2], shape[1])
    counts = coverage.coverage_counts(ds.boards, ds.imagersize)
    with atomic_path(ds.coverage_file) as tmp:
        cv2.imwrite(tmp, coverage.coverage_image(ds.boards, ds.imagersize, names=ds.names))
    if r.shifts is not None:
        ds.shifts[pose] = r.shifts
    display = ds.display
    motion = display.motion_px.get(pose, r.motion_px)
    entry.update(ok=True, folder=folder, motion_px=motion,
                 display_offsets=None if display.offsets is None else display.offsets.tolist(),
                 display_maps=display.as_dict())
    state = board_state(r.corners)
    if seg.missing:
        messages.append(f"{ds.what(pose)}: written without {', '.join(seg.missing)} (not seen clean; rotstar-detect "
                        f"does without it)")
    messages += [f"{ds.what(pose)}: board {state} ({r.n_valid}/{total}), frames agree to {motion:.3f} px beyond "
                 f"the display's maps; {coverage.describe(counts)}", display.summary()]
    return PoseOutcome(True, messages, folder)

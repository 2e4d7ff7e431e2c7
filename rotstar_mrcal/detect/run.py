"""A whole dataset: every pose detected, then the display offsets told from camera motion

SYNOPSIS

    from rotstar_mrcal.detect.run import detect_dataset
    det = detect_dataset("seq", jobs=2)
    det.display.summary()            # the screen's per-frame offsets, if any
    for r in det.results:            # sorted by pose
        r.pose, r.file, r.found, r.error
    det.boards()                     # [(file, (ny, nx, 2) or None)] for vnl.write_corners

Poses are detected independently (in worker processes with jobs > 1); the
display offsets are then estimated over all poses that gave a board
(detect.display.dataset_offsets) and a pose whose frames moved differently
from the others is rejected as a camera that moved during the sequence,
with how far it moved. Nothing here prints: `progress(result)` is called as
each pose finishes (parallel.process_map: no worker outlives an interrupt),
and the rejections after the dataset check are in
`det.rejected`.
"""

from __future__ import annotations

import dataclasses
import os

import numpy as np

from rotstar_mrcal import dataset
from rotstar_mrcal.parallel import process_map
from rotstar_mrcal.pattern.layout import Layout
from rotstar_mrcal.vnl import mrcal_can_read
from rotstar_mrcal.detect.display_offsets import MAX_MOTION, DisplayCheck, dataset_offsets
from rotstar_mrcal.detect.pipeline import PoseCorners, detect_pose


@dataclasses.dataclass
class PoseResult:
    """One pose of a dataset: its corners or why it gave none"""

    pose: str
    file: str  # the first rotating-star frame: mrcal's filename column
    corners: PoseCorners | None
    error: str = ""  # '' or the one-line reason the pose gave no board
    size: tuple[int, int] | None = None  # (width, height) of its frames

    @property
    def found(self) -> bool:
        return self.corners is not None and not self.error


@dataclasses.dataclass
class DatasetCorners:
    """Every pose of a dataset, in sorted order, and the display check over them"""

    seq: str
    layout: Layout
    pattern: dict
    results: list[PoseResult]
    display: DisplayCheck
    rejected: list[PoseResult]  # found by their pose, then rejected by the dataset's motion check

    @property
    def found(self) -> list[PoseResult]:
        return [r for r in self.results if r.found]

    def boards(self) -> list[tuple[str, np.ndarray | None]]:
        """(file, corners or None) per pose that mrcal can name, for vnl.write_corners"""
        return [(r.file, r.corners.corners if r.found else None) for r in self.results if mrcal_can_read(r.file)]

    def weights(self) -> list[np.ndarray | None]:
        return [r.corners.weights() if r.found else None for r in self.results if mrcal_can_read(r.file)]

    @property
    def sizes(self) -> list[tuple[int, int]]:
        return sorted({r.size for r in self.found})


def detect_one(seq: str, pose: str, pattern_frames: list[dict], layout: Layout, opts: dict) -> PoseResult:
    """Load and detect one pose (a worker: picklable arguments, no printing)"""
    first = next(f["file"] for f in pattern_frames if f["kind"] == "rotstar")
    fn = os.path.join(seq, pose, first)
    if not mrcal_can_read(os.path.join(seq, pose)):
        return PoseResult(pose, fn, None, f"{os.path.join(seq, pose)}: mrcal cannot read file names with "
                                          "whitespace or non-ASCII characters; rename the folder (left out of the output)")
    try:
        p = dataset.load_pose(seq, pose, pattern_frames)
    except dataset.DatasetError as e:
        return PoseResult(pose, fn, None, str(e))
    opts = dict(opts)
    name = opts.pop("method", "rotstar")
    r = detect_pose(p.rotstar, layout, full_scale=p.full_scale, checkerboard=p.checkerboard,
                    identity=p.identity, **opts)
    if name != "rotstar" and r.found:
        r = started_from_rotstar(name, r, p, layout)
    return PoseResult(pose, p.first_file, r, r.error, (p.rotstar.shape[2], p.rotstar.shape[1]))


def started_from_rotstar(name: str, r: PoseCorners, p: dataset.Pose, layout: Layout) -> PoseCorners:
    """rotstar's corners r of pose p moved by method `name` (methods.METHODS, start='rotstar'), rotstar's windows

    The result keeps rotstar's windows, display offsets and motion (the
    dataset's motion check), and has the method's per-corner reasons; no
    covariance (--weights are rotstar's).
    """
    from rotstar_mrcal.peers.registry import PoseImages, method

    f = method(name)(PoseImages(layout, p.full_scale, frames=p.rotstar, identity=p.identity,
                                checkerboard=p.checkerboard, phase=p.phase, star=p.star,
                                start=r.corners, start_window=r.window))
    if f.corners is None:
        return dataclasses.replace(r, error=f"{name}: {f.why}", sigma=None, cov=None)
    reasons = f.reasons if f.reasons is not None else np.where(np.isfinite(f.corners[..., 0]), "",
                                                               f"{name}: not refined").astype(object)
    return dataclasses.replace(r, corners=f.corners, reasons=reasons, sigma=None, cov=None)


def missing_frames(layout: Layout, name: str) -> str:
    """'' or the frames method `name` needs and the dataset's sequence lacks ('phase-shift frames', 'star frame')

    >>> from rotstar_mrcal.pattern.layout import make_layout
    >>> plain = make_layout(screen=(800, 600), pitch=100, band=24)
    >>> missing_frames(plain, "phase"), missing_frames(plain, "saddle")
    ('phase-shift frames', '')
    """
    from rotstar_mrcal.peers.registry import method

    needs = method(name).needs
    if needs == "phase" and not layout.phase:
        return "phase-shift frames"
    if needs == "star" and not layout.star_segments:
        return "star frame"
    return ""


def method_available(layout: Layout, name: str) -> str:
    """'' or why the dataset's sequence cannot give method `name`'s corners (one line)

    >>> from rotstar_mrcal.pattern.layout import make_layout
    >>> method_available(make_layout(screen=(800, 600), pitch=100, band=24), "star")[:48]
    'the sequence has no star frame (it was recorded '
    """
    from rotstar_mrcal.peers.registry import method

    m = method(name)
    what = missing_frames(layout, name)
    if what:
        return (f"the sequence has no {what} (it was recorded without rotstar-pattern --paper-sequence): "
                f"--method {name} cannot run; the rotating-star corners are still available with the default "
                f"--method rotstar")
    if m.start != "rotstar" and name != "rotstar":
        return f"--method {name} finds its own board; rotstar-detect runs the methods that start from rotstar's corners"
    return ""


def detect_dataset(seq: str, *, window: float = 10.0, refine: str = "symmetric", max_motion: float = MAX_MOTION,
                   jobs: int = 1, poses: list[str] | None = None, progress=None,
                   method: str = "rotstar") -> DatasetCorners:
    """Detect every pose of seq, then check the frames' motion over the dataset; see the module doc

    method: 'rotstar', or a method of the registry that starts from rotstar's
    corners (methods.METHODS: 'phase', 'star', 'cornersubpix', 'saddle'),
    run on every pose rotstar found. Raises dataset.DatasetError when the
    dataset cannot be read at all or its sequence lacks the method's frames.
    """
    pattern, layout = dataset.read_pattern(seq)
    why = method_available(layout, method)
    if why:
        raise dataset.DatasetError(f"{dataset.pattern_file(seq)}: {why}")
    frames = pattern["frames"]
    poses = dataset.list_poses(seq, frames) if poses is None else poses
    opts = dict(window=window, refine=refine, max_motion=max_motion, method=method)
    done: dict[str, PoseResult] = {}

    def finish(r: PoseResult):
        done[r.pose] = r
        if progress:
            progress(r)

    for r in process_map(detect_one, [(seq, p, frames, layout, opts) for p in poses], jobs):
        finish(r)

    results = [done[p] for p in poses]
    shifts = {r.pose: r.corners.shifts for r in results if r.found and r.corners.shifts is not None}
    display = dataset_offsets(shifts)
    for r in results:
        if r.pose in display.motion_px:
            r.corners.motion_px = display.motion_px[r.pose]
    rejected = [r for r in results if r.pose in display.moved(max_motion)]
    for r in rejected:
        r.error = (f"frames do not align: the camera moved during the sequence (its frames moved "
                   f"{r.corners.motion_px:.2f} px against each other beyond the screen's own offsets, "
                   f"limit {max_motion})")
    return DatasetCorners(seq, layout, pattern, results, display, rejected)

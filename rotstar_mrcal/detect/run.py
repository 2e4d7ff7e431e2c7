"""A whole dataset, one camera or several: every pose detected, the display maps, the mrcal command

SYNOPSIS

    >>> from rotstar_mrcal.dataset import open_dataset
    >>> from rotstar_mrcal.detect.run import detect_dataset

    ds = open_dataset("seq")                     # read once (DatasetError: one line)
    det = detect_dataset(ds, jobs=2)             # window=, refine=REFINERS[...], max_motion=, method=,
                                                 # progress=, corners_file=, weights= (below)
    det.boards()                     # [(file, (ny, nx, 2) or None)], every camera, for vnl.write_corners
    det.weights()                    # the same boards' weights (--weights)
    det.cameras[k]                   # camera k's DatasetCorners: .results (PoseResult per pose folder,
                                     # sorted: r.pose, r.file, r.found, r.error), .display (the screen's
                                     # offsets and motion verdicts: .summary()), .rejected (moved poses)
    det.disagree                     # {poseNNN: why}: boards labelled differently in two cameras (dropped)
    det.kept[k]                      # camera k's boards mrcal will use
    det.focal[k]                     # camera k's focal seed (px), for mrcal's --focal
    det.command                      # the mrcal-calibrate-cameras command ('' when no calibration can run:
                                     # no board, or a camera of a rig with < 2: det.thin)
    vnl.write_corners(f, det.boards(), det.weights() if weights else None)   # corners.vnl, as rotstar-detect

A pose that gives no board says why:

    >>> import tempfile
    >>> import numpy as np
    >>> from rotstar_mrcal.dataset import write_pattern, write_pose
    >>> from rotstar_mrcal.pattern.layout import make_layout
    >>> seq = tempfile.mkdtemp(); layout = make_layout(screen=(800, 600), pitch=100, band=24)
    >>> _ = write_pattern(seq, layout)
    >>> _ = write_pose(seq, "pose000", {f["file"]: np.zeros((40, 60), np.uint8) for f in layout.frames()})
    >>> det = detect_dataset(open_dataset(seq))
    >>> r = det.cameras[0].results[0]
    >>> r.pose, r.found, r.error[:8], det.kept, det.command
    ('pose000', False, 'all dark', {0: []}, '')

Every camera is detected alike (one camera is a rig of one, its pose folders
'poseNNN'; a rig's are 'poseNNN/camera-K'). Poses are detected independently
(in worker processes with jobs > 1); the display maps (one affine map per
frame in screen coordinates) are then estimated per camera over its poses
that gave a board (display_offsets.still_display: the median over the poses,
then again over those found still), a pose whose frames
moved differently from the others is rejected as a camera that moved during
the sequence, with how far it moved, and (rotstar's corners, four poses or
more) every other pose's joint refinement is run again with the dataset's
maps instead of its own noisier ones (zero maps when they are not
significant: the plain joint refinement). With several
cameras, each pose's boards are checked to be labelled alike in every camera
(rig.check_labelling); a pose that is not is dropped from every camera. The
focal seed and the command come from the boards mrcal keeps
(calibrate.focal.estimate_focal; calibrate.command.hint_command for one camera,
calibrate.rig.rig_argv for several: the builders rotstar-calibrate uses).
corners_file names the corners in the command, weights adds mrcal's
--corners-cache-has-weights. Nothing here prints: `progress(result)` is
called as each pose finishes (parallel.process_map: no worker outlives an
interrupt).
"""

from __future__ import annotations

import dataclasses
import os

import numpy as np

from rotstar_mrcal.calibrate.focal import estimate_focal
from rotstar_mrcal.calibrate.command import LEAN_LENSMODEL, command_line, hint_command, rig_argv, rig_globs
from rotstar_mrcal.dataset import Dataset, DatasetError, Pose, load_pose, pattern_file, read_image
from rotstar_mrcal.parallel import process_map
from rotstar_mrcal.pattern.layout import Layout
from rotstar_mrcal.peers.registry import PoseImages, method
from rotstar_mrcal.vnl import mrcal_can_read, mrcal_keeps
from rotstar_mrcal.detect.display_offsets import (
    MAX_MOTION, DisplayCheck, FrameShifts, map_displacement, still_display,
)
from rotstar_mrcal.detect.pipeline import PoseCorners, correct_with_dataset, detect_pose, refine_with_maps
from rotstar_mrcal.detect.refine import SYMMETRIC, Refiner
from rotstar_mrcal.detect.rig import MAX_TURN_DEG, check_labelling


@dataclasses.dataclass
class PoseResult:
    """One pose of a dataset: its corners or why it gave none"""

    pose: str
    file: str  # the first rotating-star frame: mrcal's filename column
    corners: PoseCorners | None
    error: str = ""  # '' or the one-line reason the pose gave no board
    size: tuple[int, int] | None = None  # (width, height) of its frames
    note: str = ""  # '' or what was read differently (an identity frame missing: missing_note)

    @property
    def found(self) -> bool:
        return self.corners is not None and not self.error


@dataclasses.dataclass
class DatasetCorners:
    """Every pose of one camera of a dataset, in sorted order, and the display check over them"""

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
        p = load_pose(seq, pose, pattern_frames)
    except DatasetError as e:
        return PoseResult(pose, fn, None, str(e))
    opts = dict(opts)
    name = opts.pop("method", "rotstar")
    r = detect_pose(p.rotstar, layout, full_scale=p.full_scale, checkerboard=p.checkerboard,
                    identity=p.identity, **opts)
    if name != "rotstar" and r.found:
        r = started_from_rotstar(name, r, p, layout)
    return PoseResult(pose, p.first_file, r, r.error, (p.rotstar.shape[2], p.rotstar.shape[1]), missing_note(p))


def missing_note(p: Pose) -> str:
    """'' or what a pose lacking an identity frame (Pose.missing) was read from

    >>> import numpy as np
    >>> p = Pose("pose007", "seq/pose007", None, None, 65535.0, [], np.zeros((13, 1, 1)), missing=("identity_06.png",))
    >>> missing_note(p)
    'identity_06.png missing: read from the other 12 identity frames'
    """
    if not p.missing:
        return ""
    return f"{', '.join(p.missing)} missing: read from the other {len(p.identity) - len(p.missing)} identity frames"


def started_from_rotstar(name: str, r: PoseCorners, p: Pose, layout: Layout) -> PoseCorners:
    """rotstar's corners r of pose p moved by method `name` (methods.METHODS, start='rotstar'), rotstar's windows

    The result keeps rotstar's windows, display maps and motion (the
    dataset's motion check), and has the method's per-corner reasons; no
    covariance (--weights are rotstar's).
    """
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
    m = method(name)
    what = missing_frames(layout, name)
    if what:
        return (f"the sequence has no {what} (it was recorded without rotstar-pattern --paper-sequence): "
                f"--method {name} cannot run; the rotating-star corners are still available with the default "
                f"--method rotstar")
    if m.start != "rotstar" and name != "rotstar":
        return f"--method {name} finds its own board; rotstar-detect runs the methods that start from rotstar's corners"
    return ""


def detect_camera(ds: Dataset, k: int = 0, *, window: float = 10.0, refine: Refiner = SYMMETRIC,
                  max_motion: float = MAX_MOTION, jobs: int = 1, progress=None,
                  method: str = "rotstar", blur_map: bool = False) -> DatasetCorners:
    """Detect camera k's poses of ds, then check their frames' motion over the camera's poses (module doc)

    blur_map: also the local PSF at every corner (PoseCorners.blur, detect_pose(blur_map=True)).
    """
    poses = ds.poses[k]
    # a refiner whose correction pools the poses' measurements measures in the first pass and corrects after it
    first = dataclasses.replace(refine, correct=corners_as_they_are) if refine.pools else refine
    opts = dict(window=window, refine=first, max_motion=max_motion, method=method, blur_map=blur_map)
    done: dict[str, PoseResult] = {}
    for r in process_map(detect_one, [(ds.path, p, ds.frames, ds.layout, opts) for p in poses], jobs):
        done[r.pose] = r
        if progress:
            progress(r)

    results = [done[p] for p in poses]
    shifts = {r.pose: r.corners.shifts for r in results if r.found and r.corners.shifts is not None}
    display = still_display(shifts, max_motion)
    for r in results:
        if r.pose in display.motion_px:
            r.corners.motion_px = display.motion_px[r.pose]
    rejected = [r for r in results if r.pose in display.moved(max_motion)]
    moved = {r.pose for r in rejected}
    still = [r for r in results if r.found and r.pose not in moved]
    # the second pass is the symmetric joint refinement; a refiner that corrects its corners in the first pass
    # (psf) keeps each pose's own maps; one that pools (psf-sim) has corrected nothing yet, and corrects after it
    if method == "rotstar" and refine.needs == "rotstar" and (refine.correct is None or refine.pools) \
            and display.offsets is not None:
        refine_with_dataset_maps(ds, still, display, jobs)
    if refine.pools:
        correct_with_dataset(ds.layout, [r.corners for r in still], refine)
    for r in rejected:
        r.error = (f"frames do not align: the camera moved during the sequence (its frames moved "
                   f"{r.corners.motion_px:.2f} px against each other beyond the screen's own maps, "
                   f"limit {max_motion})")
    return DatasetCorners(ds.path, ds.layout, ds.pattern, results, display, rejected)


def corners_as_they_are(frames, corners, window, shifts, samples=None) -> np.ndarray:
    """A Refiner's correct that changes nothing (detect_camera's first pass of a pooling refiner)"""
    return corners


REFINE_AGAIN_PX = 0.002  # a pose is refined again when the dataset's maps move a frame's corner this much more


def refine_one(seq: str, pose: str, pattern_frames: list[dict], layout: Layout, corners: PoseCorners,
               maps: tuple) -> tuple[str, PoseCorners]:
    """(pose, its corners refined again with the dataset's display maps) (a worker)"""
    files = [os.path.join(seq, pose, f["file"]) for f in pattern_frames if f["kind"] == "rotstar"]
    frames = np.stack([read_image(fn)[0] for fn in files])
    return pose, refine_with_maps(frames, layout, corners, *maps)


def maps_change_px(shifts: FrameShifts, maps: tuple) -> float:
    """Camera px by which maps (offsets, linear, centre) move a frame's corner beyond what the pose's refinement used"""
    used = shifts.displacement(shifts.uv) if shifts.applied else 0.0
    return float(np.abs(map_displacement(*maps, shifts.uv) - used).max()) * shifts.px_per_display


def refine_with_dataset_maps(ds: Dataset, results: list[PoseResult], display: DisplayCheck, jobs: int) -> None:
    """The poses' joint refinement run again with the dataset's display maps (less noisy than a pose's own)

    Only the poses for which the maps differ by REFINE_AGAIN_PX or more from
    those their refinement used (on a clean display: none).
    """
    maps = display.refinement_maps()
    todo = {r.pose: r for r in results if r.corners.shifts is not None and np.isfinite(r.corners.shifts.px_per_display)
            and maps_change_px(r.corners.shifts, maps) >= REFINE_AGAIN_PX}
    args = [(ds.path, r.pose, ds.frames, ds.layout, r.corners, maps) for r in todo.values()]
    for pose, corners in process_map(refine_one, args, jobs):
        todo[pose].corners = corners


@dataclasses.dataclass
class Detection:
    """Everything a caller of detect_dataset needs: every camera's corners, the focal seeds, mrcal's command"""

    dataset: Dataset
    cameras: dict[int, DatasetCorners]
    disagree: dict[str, str]  # poseNNN -> why its boards were dropped from every camera
    kept: dict[int, list[PoseResult]]  # per camera, the boards mrcal will use
    focal: dict[int, float]  # per camera, the focal seed (px); empty when command is ''
    command: str  # the mrcal-calibrate-cameras command, or '' (no board; or thin)
    thin: list[int]  # the cameras of a rig with fewer than the 2 boards mrcal needs

    def results(self) -> list[PoseResult]:
        """Every camera's PoseResults, camera by camera"""
        return [r for d in self.cameras.values() for r in d.results]

    def found(self, k: int = 0) -> list[PoseResult]:
        """Camera k's poses that gave a board (after the cross-camera labelling check)"""
        return [r for r in self.cameras[k].found if self._kept(r)]

    def boards(self) -> list[tuple[str, np.ndarray | None]]:
        """(file, corners or None) of every camera's poses that mrcal can name, for vnl.write_corners"""
        return [(r.file, r.corners.corners if self._kept(r) else None)
                for r in self.results() if mrcal_can_read(r.file)]

    def weights(self) -> list[np.ndarray | None]:
        return [r.corners.weights() if self._kept(r) else None for r in self.results() if mrcal_can_read(r.file)]

    def _kept(self, r: PoseResult) -> bool:
        return r.found and r.pose.split("/")[0] not in self.disagree


def detect_dataset(ds: Dataset, *, window: float = 10.0, refine: Refiner = SYMMETRIC,
                   max_motion: float = MAX_MOTION, jobs: int = 1, progress=None, method: str = "rotstar",
                   corners_file: str = "corners.vnl", weights: bool = False,
                   max_turn_deg: float = MAX_TURN_DEG, blur_map: bool = False) -> Detection:
    """Detect every camera's poses of ds, check them, and say how to calibrate; see the module doc

    method: 'rotstar', or a method of the registry that starts from rotstar's
    corners (peers.registry.METHODS: 'phase', 'star', 'cornersubpix', 'saddle'),
    run on every pose rotstar found. Raises DatasetError when the dataset's
    sequence lacks the method's frames.
    """
    why = method_available(ds.layout, method)
    if why:
        raise DatasetError(f"{pattern_file(ds.path)}: {why}")
    cams = {k: detect_camera(ds, k, window=window, refine=refine, max_motion=max_motion, jobs=jobs,
                             progress=progress, method=method, blur_map=blur_map) for k in ds.cameras}
    disagree = check_labelling({k: d.found for k, d in cams.items()}, max_turn_deg) if len(cams) > 1 else {}
    det = Detection(ds, cams, disagree, {}, {}, "", [])
    det.kept = {k: [r for r in det.found(k) if mrcal_keeps(r.corners.corners, r.corners.weights() if weights else None)]
                for k in ds.cameras}
    det.thin = [k for k in ds.cameras if len(det.kept[k]) < 2] if ds.multi_camera else []
    if any(det.kept.values()) and not det.thin:
        det.focal, det.command = mrcal_command(ds, det, corners_file, weights)
    return det


def mrcal_command(ds: Dataset, det: Detection, corners_file: str, weights: bool) -> tuple[dict[int, float], str]:
    """({camera: focal seed}, the mrcal-calibrate-cameras command): rotstar-calibrate's lean model, its builders"""
    pts = ds.layout.board_points()[..., :2]
    if not ds.multi_camera:  # the image size the boards were found in (the first, should they differ)
        imagersize = det.cameras[0].sizes[0]
        focal = estimate_focal([r.corners.corners for r in det.kept[0]], pts, imagersize)
        return {0: focal}, hint_command(ds.layout, imagersize, focal, corners_file,
                                        os.path.join(ds.path, "*", ds.first_frame), weights)
    focals = {k: estimate_focal([r.corners.corners for r in det.kept[k]], pts, ds.sizes[k]) for k in ds.cameras}
    return focals, command_line(rig_argv(corners_file, ds.layout, ds.sizes, focals, LEAN_LENSMODEL, ".",
                                         rig_globs(ds.path, ds.cameras, ds.first_frame), weights))

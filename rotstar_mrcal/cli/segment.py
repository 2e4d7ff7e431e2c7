"""rotstar-segment: a recording of the looping player in, one dataset pose folder out"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import os
import re
import sys

import numpy as np

from rotstar_mrcal import dataset
from rotstar_mrcal.capture.backend_replay import ReplaySource, stereo_raw
from rotstar_mrcal.capture.pose import quick_check, value_scale, write_segmented
from rotstar_mrcal.capture.rig_segment import RigSegmentation, check_recordings, segment_rig
from rotstar_mrcal.capture.segment import SegmentError, segment
from rotstar_mrcal.capture.source import CaptureError
from rotstar_mrcal.cli.segment_args import add_segment_options, options_from
from rotstar_mrcal.cli.common import HOLD_HELP, hold_arg
from rotstar_mrcal.pattern.player import DEFAULT_HOLD, hold_text
from rotstar_mrcal.atomic import whole_or_none
from rotstar_mrcal.cli.common import (
    EXIT_FAILED, HelpFormatter, atomic_path, atomic_write, check_output_path, exit_status_help, fail,
    out_line, run, say, size_arg,
)

DESCRIPTION = """\
Split a continuous recording of player.html (the start marker, then every
frame of pattern.json, in a loop) into the displayed frames: stable
stretches between the transitions are found from the mean absolute
difference of consecutive camera frames, the middle frames of each stretch
are averaged, and the order is fixed by the start marker and checked against
pattern.json. Writes OUT/<file> for every frame of pattern.json (16-bit PNG)
and OUT/segment.json, and copies pattern.json into OUT's parent, so that
`rotstar-detect` reads the parent folder directly. A quick detection of the
board follows (skip it with --no-check).

RECORDING is a folder of frames (PNG/TIFF/PGM, 8 or 16 bit, in natural name
order), a .npy array (T, H, W) with an optional .json of sequence numbers
beside it (what rotstar-capture --keep-raw writes), a raw dump of
`v4l2-ctl --stream-to` (needs --size and --fourcc), or a video file (8-bit,
usually lossy: a last resort).

Several cameras recorded together (the D435's two infrared imagers and its
colour camera: rotstar-capture --stereo / --rgb-device, whose --keep-raw
writes raw/<pose>/camera-0.npy, camera-1.npy, ...): give every camera's
recording, in camera order, or the folder holding camera-<k>.npy (or
camera-<k>/ folders of frames). The displayed frames are found on camera 0
(or, when its recording cannot be split, on the first camera that can:
--reference K chooses), and every camera's recording is split with the
same frame boundaries, checked on each (each camera must be still there and
follow the sequence's levels). Writes OUT/camera-<k>/ for every camera: the
pose folder of a multi-camera dataset (doc/dataset.md). The recordings must
hold the same number of frames (one per lockstep step), and every frame of
one camera the same size; otherwise a one-line error (exit 2).

Progress and the verdict go to stderr; stdout gets the pose folder only.
"""

EPILOG = """\
examples:
  rotstar-segment rec/pose000.npy --pattern pattern/pattern.json --out seq/pose000
  rotstar-detect seq/ > corners.vnl
  rotstar-segment seq/raw/pose000_exp4000us/ --pattern pattern/ --out stereo/pose000     # camera-0, camera-1, ...
  rotstar-segment left.npy right.npy colour.npy --pattern pattern/ --out stereo/pose000

""" + exit_status_help("written", failed="the recording cannot be split (the reason is printed)") + "\n"


def parse_args(argv=None):
    p = argparse.ArgumentParser(prog="rotstar-segment", description=DESCRIPTION, epilog=EPILOG,
                                formatter_class=HelpFormatter)
    p.add_argument("recording", nargs="+",
                   help="folder of frames, .npy, .raw or video file; several (one per camera, in camera order), or a "
                        "folder of camera-<k>.npy recordings: the cameras of a rig")
    p.add_argument("--pattern", required=True, help="pattern.json (or the folder holding it) that the player showed")
    p.add_argument("--out", "-o", required=True, help="the pose folder to write, SEQ/<pose>")
    p.add_argument("--size", type=size_arg, help="WIDTHxHEIGHT of a .raw recording")
    p.add_argument("--fourcc", help="pixel format of a .raw recording: GREY, Y16 or Y8I (its left imager); Y12I or "
                                    "Y8I with --stereo: both imagers")
    p.add_argument("--plot", metavar="PNG", help="also plot the difference signal, the threshold and the stretches")
    p.add_argument("--no-check", action="store_true", help="do not run the quick board detection")
    p.add_argument("--stereo", action="store_true",
                   help="RECORDING is a raw dump of both infrared imagers (`v4l2-ctl --stream-to` in Y12I, or Y8I): "
                        "split into camera-0 (left) and camera-1 (right); --fourcc Y12I implies it")
    p.add_argument("--reference", type=int, metavar="K",
                   help="several cameras: the camera whose recording sets the frame boundaries (default: camera 0, "
                        "or the first that can be split)")
    p.add_argument("--force", action="store_true", help="overwrite a pose folder that already holds frames")
    add_segment_options(p)
    p.add_argument("--hold", type=hold_arg, default=DEFAULT_HOLD,
                   help=f"{HOLD_HELP} (default {hold_text(DEFAULT_HOLD)}); used to tell the frames apart by their "
                        f"content when no whole loop between two start markers was recorded")
    p.add_argument("--refresh", type=float, default=60.0, help="the screen's refresh rate, Hz (default 60)")
    return p.parse_args(argv)


def plot_signal(fn: str, seg, title: str) -> None:
    """The difference signal with the threshold, the stretches and the frames averaged"""
    import matplotlib  # matplotlib.pyplot costs 2.1 s to import (-X importtime): only with --plot

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(12, 4))
    ax.semilogy(seg.d, lw=0.8, color="k", label="mean |difference| (fraction of full scale)")
    ax.axhline(seg.tau, color="r", lw=0.8, label="threshold")
    # between markers: the stretches of the loop used; by content: every clean visit of a frame is averaged
    used = set(range(len(seg.stretches))) if seg.method == "content" else set(seg.loop.stretches)
    for k, s in enumerate(seg.stretches):
        colour = "tab:purple" if seg.markers[k] else "tab:green" if k in used else "tab:gray"
        ax.axvspan(s.start, s.stop - 0.5, color=colour, alpha=0.15, lw=0)
        ax.axvspan(s.core[0], s.core[1] - 0.5, color=colour, alpha=0.35, lw=0)
    ax.set_xlabel("camera frame")
    ax.set_title(title + "\n" + seg.summary(), fontsize=9)
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    with atomic_path(fn) as tmp:
        fig.savefig(tmp, dpi=100)
    plt.close(fig)


def main(argv=None) -> int:
    return run("rotstar-segment", _main, argv)


def camera_recordings(paths: list[str]) -> list[str]:
    """The recordings of each camera: the paths given, or a folder's camera-<k>.npy / camera-<k>/ in order of k"""
    if len(paths) != 1 or not os.path.isdir(paths[0]):
        return paths
    found = {}
    for name in os.listdir(paths[0]):
        m = re.fullmatch(r"camera-(\d+)(\.npy)?", name)
        full = os.path.join(paths[0], name)
        if m and (m.group(2) or os.path.isdir(full)):
            found[int(m.group(1))] = full
    if not found:
        return paths
    if sorted(found) != list(range(len(found))):
        fail(f"{paths[0]}: camera recordings {', '.join(os.path.basename(found[k]) for k in sorted(found))}: "
             f"cameras are numbered 0, 1, ... without gaps")
    return [found[k] for k in range(len(found))]


def _main(argv=None) -> int:
    """parse -> read the recordings -> split them -> write the pose folder (and check it) -> print its name

    One camera is a rig of one, written as OUT/<file> (its split: capture.segment.segment); several cameras
    (or --stereo) are written as OUT/camera-<k>/ (capture.rig_segment.segment_rig).
    """
    a = parse_args(argv)
    names = camera_names(a)
    pattern, layout = read_pattern_for(a)
    out = check_outputs(a, pattern, names)
    cams = load_cameras(a, names)
    rs = split(a, cams, pattern, layout, names)
    try:
        with whole_or_none(out) if names else contextlib.nullcontext():  # no new pose folder with some cameras
            for k, (c, seg) in enumerate(zip(cams, rs.cameras)):
                folder = write_camera(a, out, names[k] if names else "", c, seg, pattern, layout,
                                      names[rs.reference] if names else "")
    except (dataset.DatasetError, OSError, ValueError) as e:
        fail(str(e))
    out_line(out if names else folder)
    return 0


def camera_names(a) -> list[str]:
    """The camera folders to write, camera-0, camera-1, ...; [] for one camera (written as the pose folder)"""
    a.recording = camera_recordings(a.recording)
    a.stereo = a.stereo or (a.fourcc or "").strip().upper() == "Y12I"
    if a.stereo and len(a.recording) != 1:
        fail("--stereo splits one raw dump of both imagers; give one recording")
    if len(a.recording) == 1 and not a.stereo:
        return []
    return [f"camera-{k}" for k in range(2 if a.stereo else len(a.recording))]


def read_pattern_for(a) -> tuple[dict, object]:
    """(pattern.json, its Layout) of --pattern, read once; fail() on one that cannot be read"""
    try:
        return dataset.read_pattern(a.pattern)
    except dataset.DatasetError as e:
        fail(str(e))


def check_outputs(a, pattern: dict, names: list[str]) -> str:
    """The pose folder to write (normalised): never over an input, nor over frames without --force"""
    out = os.path.normpath(a.out)
    inputs = list(a.recording) + [dataset.pattern_file(a.pattern)]
    if not names and a.reference not in (None, 0):
        fail("--reference is for several cameras' recordings")
    check_output_path(out, inputs, folder=True)
    if names and a.reference is not None and not 0 <= a.reference < len(names):
        fail(f"--reference {a.reference}: there are cameras 0-{len(names) - 1}")
    if a.plot and not names:
        check_output_path(a.plot, inputs)
    files = {f["file"] for f in pattern["frames"]}
    busy = [n for n in names or [""] if os.path.isdir(os.path.join(out, n))
            and files & set(os.listdir(os.path.join(out, n)))]
    if busy and not a.force:
        fail(f"{os.path.join(out, busy[0]) if names else out} already holds frames (use --force to overwrite)")
    return out


def dropped_frames(sequence) -> int:
    """Camera frames missing from a recording: the gaps in its sequence numbers

    >>> dropped_frames([3, 4, 6, 9]), dropped_frames([5])
    (3, 0)
    """
    seq = np.asarray(sequence, np.int64)
    return int(np.sum(np.maximum(np.diff(seq) - 1, 0))) if len(seq) > 1 else 0


def split(a, cams: list, pattern: dict, layout, names: list[str]):
    """Every camera's recording split at the same frame boundaries (rig_segment.RigSegmentation), said on stderr"""
    try:
        if names:
            check_recordings([c.frames for c in cams], [f"{n} ({c.what})" for n, c in zip(names, cams)])
    except SegmentError as e:
        fail(str(e))
    try:
        if names:
            rs = segment_rig([c.frames for c in cams], pattern["frames"], layout, [c.full_scale for c in cams],
                             _options(a), a.reference, names)
        else:
            rs = RigSegmentation([segment(cams[0].frames, pattern["frames"], layout, cams[0].full_scale,
                                          _options(a), times=_times(cams[0]))], 0, [])
    except SegmentError as e:
        fail(str(e) if names else f"{a.recording[0]}: {e}", EXIT_FAILED)
    except CaptureError as e:
        fail(str(e))
    say(f"rotstar-segment: {rs.summary() if names else rs.cameras[0].summary()}")
    for v in [] if names else rs.cameras[0].loops:
        if not v.ok:
            say(f"rotstar-segment:   loop at frame {rs.cameras[0].stretches[v.marker].start} not used: {v.reason}")
    for n in rs.notes:
        say(f"rotstar-segment: note: {n}")
    return rs


def _options(a):
    """The segmentation options, with the player's hold and refresh rate"""
    return dataclasses.replace(options_from(a), hold=a.hold or 0, refresh_hz=a.refresh)


def _times(c) -> np.ndarray | None:
    """Seconds of every camera frame (sequence numbers / fps), None when the recording has no frame rate"""
    return np.asarray(c.sequence) / c.fps if c.fps else None


def write_camera(a, out: str, name: str, c, seg, pattern: dict, layout, reference: str) -> str:
    """One camera's frames into OUT/ (one camera) or OUT/camera-<k>/, with its --plot and quick check"""
    scale = _scale(a, seg, c.full_scale, name)
    extra = {"recording": c.what, "dropped_camera_frames": dropped_frames(c.sequence)}
    if name:
        extra.update(camera=name, boundaries_from=reference)
    pose = f"{os.path.basename(out)}/{name}" if name else os.path.basename(out)
    folder = write_segmented(os.path.dirname(out) or ".", pose, seg, pattern, c.full_scale, scale, extra)
    if a.plot and not name:
        plot_signal(a.plot, seg, a.recording[0])
        say(f"rotstar-segment: wrote {a.plot}")
    if not a.no_check:
        record_check(folder, name, quick_check(seg, layout, pattern, c.full_scale / scale), layout)
    return folder


def record_check(folder: str, name: str, r, layout) -> None:
    """The quick check's verdict on stderr and in the folder's segment.json"""
    n = layout.nx * layout.ny
    if name:
        say(f"rotstar-segment: {name}: board found: {r.n_valid} of {n} corners" if r.found
            else f"rotstar-segment: {name}: no board: {r.error}")
    elif r.found:
        say(f"rotstar-segment: board found: {r.n_valid} of {n} corners"
            + (" (complete)" if r.n_valid == n else "") + f", frames agree to {r.motion_px:.3f} px")
    else:
        say(f"rotstar-segment: no board: {r.error}")
    with open(os.path.join(folder, "segment.json")) as f:
        info = json.load(f)
    info["quick_check"] = {"found": r.found, "corners": r.n_valid, "error": r.error, "motion_px": r.motion_px}
    with atomic_write(os.path.join(folder, "segment.json")) as f:
        json.dump(info, f, indent=1, default=float)
        f.write("\n")


def _scale(a, seg, full_scale: float, what: str) -> float:
    """The factor 16-bit values are written with (--scale; auto: value_scale), with its note (naming the camera)"""
    if a.scale != "auto":
        return float(a.scale)
    scale, note = value_scale(max(float(np.max(img)) for img in seg.images.values()), full_scale)
    if note:
        say(f"rotstar-segment: note: {what + ': ' if what else ''}{note}")
    return scale


@dataclasses.dataclass
class CameraRecording:
    what: str  # the file, and which imager of a dump of both
    frames: object  # indexable (T, H, W)
    full_scale: float
    sequence: np.ndarray
    notes: list
    fps: float = 0.0  # the camera's frame rate, if the recording says (0: unknown)


def load_cameras(a, names: list[str]) -> list[CameraRecording]:
    """Every camera's recording (one file each, or the two imagers of one raw dump: --stereo), said on stderr"""
    try:
        if a.stereo:
            if not a.size or not a.fourcc:
                fail(f"{a.recording[0]}: a raw dump of both imagers needs --size WxH and --fourcc Y12I (or Y8I)")
            views = stereo_raw(a.recording[0], a.size, a.fourcc)
            fs = 65535.0 if views[0].dtype == np.uint16 else 255.0
            path = os.path.abspath(a.recording[0])
            cams = [CameraRecording(f"{path} ({side} imager)", v, fs, np.arange(len(v)), [])
                    for side, v in zip(("left", "right"), views)]
        else:
            cams = [load_recording(a, fn, rig=bool(names)) for fn in a.recording]
    except CaptureError as e:
        fail(str(e))
    for k, c in enumerate(cams):
        for note in c.notes:
            say(f"rotstar-segment: note: {note}")
        what = f"{names[k]}: {c.what}" if names else a.recording[0]
        say(f"rotstar-segment: {what}: {len(c.frames)} frames of {c.frames.shape[2]}x{c.frames.shape[1]}, "
            f"{'16' if c.full_scale == 65535 else '8'}-bit")
    gaps = dropped_frames(cams[0].sequence)
    if gaps and not names:
        say(f"rotstar-segment: note: {gaps} camera frame(s) were dropped (gaps in the sequence numbers)")
    return cams


def load_recording(a, fn: str, rig: bool) -> CameraRecording:
    """One camera's recording (capture.backend_replay.ReplaySource); a rig's frames checked for one size"""
    src = ReplaySource(fn, size=a.size, fourcc=a.fourcc)
    frames = src.frames()
    if rig and hasattr(frames, "check_sizes"):
        frames.check_sizes()
    return CameraRecording(os.path.abspath(fn), frames, src.full_scale, src.sequence_numbers(), src.notes,
                           src.fps or 0.0)


if __name__ == "__main__":
    sys.exit(main())

"""rotstar-segment: a recording of the looping player in, one dataset pose folder out"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import re
import sys

import numpy as np

from rotstar_mrcal import dataset
from rotstar_mrcal.capture.backend_replay import ReplaySource, stereo_raw
from rotstar_mrcal.capture.pose import quick_check, value_scale, write_segmented
from rotstar_mrcal.capture.rig_segment import check_recordings, segment_rig
from rotstar_mrcal.capture.segment import SegmentError, segment
from rotstar_mrcal.capture.source import CaptureError
from rotstar_mrcal.cli.segment_args import add_segment_options, options_from
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
    return p.parse_args(argv)


def plot_signal(fn: str, seg, title: str) -> None:
    """The difference signal with the threshold, the stretches and the frames averaged"""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(12, 4))
    ax.semilogy(seg.d, lw=0.8, color="k", label="mean |difference| (fraction of full scale)")
    ax.axhline(seg.tau, color="r", lw=0.8, label="threshold")
    used = set(seg.loop.stretches)
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
    a = parse_args(argv)
    a.recording = camera_recordings(a.recording)
    a.stereo = a.stereo or (a.fourcc or "").strip().upper() == "Y12I"
    if a.stereo and len(a.recording) != 1:
        fail("--stereo splits one raw dump of both imagers; give one recording")
    if len(a.recording) > 1 or a.stereo:
        return _main_rig(a)
    a.recording = a.recording[0]
    try:
        pattern, layout = dataset.read_pattern(a.pattern)
    except dataset.DatasetError as e:
        fail(str(e))
    out = os.path.normpath(a.out)
    seq, pose = os.path.dirname(out) or ".", os.path.basename(out)
    inputs = [a.recording, dataset.pattern_file(a.pattern)]
    if a.reference not in (None, 0):
        fail("--reference is for several cameras' recordings")
    check_output_path(out, inputs, folder=True)
    if a.plot:
        check_output_path(a.plot, inputs)
    names = {f["file"] for f in pattern["frames"]}
    if os.path.isdir(out) and names & set(os.listdir(out)) and not a.force:
        fail(f"{out} already holds frames (use --force to overwrite)")
    try:
        src = ReplaySource(a.recording, size=a.size, fourcc=a.fourcc)
        frames = src.frames()
    except CaptureError as e:
        fail(str(e))
    for note in src.notes:
        say(f"rotstar-segment: note: {note}")
    say(f"rotstar-segment: {a.recording}: {len(frames)} frames of {frames.shape[2]}x{frames.shape[1]}, "
        f"{'16' if src.full_scale == 65535 else '8'}-bit")
    seqnums = src.sequence_numbers()
    gaps = int(sum(max(int(b) - int(a_) - 1, 0) for a_, b in zip(seqnums[:-1], seqnums[1:])))
    if gaps:
        say(f"rotstar-segment: note: {gaps} camera frame(s) were dropped (gaps in the sequence numbers)")
    try:
        seg = segment(frames, pattern["frames"], layout, src.full_scale, options_from(a))
    except SegmentError as e:
        fail(f"{a.recording}: {e}", EXIT_FAILED)
    except CaptureError as e:
        fail(str(e))
    say(f"rotstar-segment: {seg.summary()}")
    for v in seg.loops:
        if not v.ok:
            say(f"rotstar-segment:   loop at frame {seg.stretches[v.marker].start} not used: {v.reason}")
    if a.scale == "auto":
        scale, note = value_scale(max(float(np.max(img)) for img in seg.images.values()), src.full_scale)
        if note:
            say(f"rotstar-segment: note: {note}")
    else:
        scale = float(a.scale)
    try:
        folder = write_segmented(seq, pose, seg, pattern, src.full_scale, scale,
                                 {"recording": os.path.abspath(a.recording), "dropped_camera_frames": gaps})
    except (dataset.DatasetError, OSError, ValueError) as e:
        fail(str(e))
    if a.plot:
        plot_signal(a.plot, seg, a.recording)
        say(f"rotstar-segment: wrote {a.plot}")
    if not a.no_check:
        r = quick_check(seg, layout, pattern, src.full_scale / scale)  # the averages are not scaled yet
        n = layout.nx * layout.ny
        if r.found:
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
    out_line(folder)
    return 0


def _scale(a, seg, full_scale: float, what: str) -> float:
    """The factor 16-bit values are written with (--scale; auto: value_scale), with its note"""
    if a.scale != "auto":
        return float(a.scale)
    scale, note = value_scale(max(float(np.max(img)) for img in seg.images.values()), full_scale)
    if note:
        say(f"rotstar-segment: note: {what}: {note}")
    return scale


@dataclasses.dataclass
class CameraRecording:
    what: str  # the file, and which imager of a dump of both
    frames: object  # indexable (T, H, W)
    full_scale: float
    sequence: np.ndarray
    notes: list


def load_cameras(a) -> list[CameraRecording]:
    """Every camera's recording: one file each, or the two imagers of one raw dump (--stereo)"""
    try:
        if a.stereo:
            if not a.size or not a.fourcc:
                fail(f"{a.recording[0]}: a raw dump of both imagers needs --size WxH and --fourcc Y12I (or Y8I)")
            views = stereo_raw(a.recording[0], a.size, a.fourcc)
            fs = 65535.0 if views[0].dtype == np.uint16 else 255.0
            path = os.path.abspath(a.recording[0])
            return [CameraRecording(f"{path} ({side} imager)", v, fs, np.arange(len(v)), [])
                    for side, v in zip(("left", "right"), views)]
        out = []
        for fn in a.recording:
            src = ReplaySource(fn, size=a.size, fourcc=a.fourcc)
            frames = src.frames()
            if hasattr(frames, "check_sizes"):
                frames.check_sizes()
            out.append(CameraRecording(os.path.abspath(fn), frames, src.full_scale, src.sequence_numbers(),
                                       src.notes))
        return out
    except CaptureError as e:
        fail(str(e))


def _main_rig(a) -> int:
    """Several cameras' recordings -> OUT/camera-<k>/ split with the same frame boundaries"""
    try:
        pattern, layout = dataset.read_pattern(a.pattern)
    except dataset.DatasetError as e:
        fail(str(e))
    out = os.path.normpath(a.out)
    seq, pose = os.path.dirname(out) or ".", os.path.basename(out)
    inputs = list(a.recording) + [dataset.pattern_file(a.pattern)]
    check_output_path(out, inputs, folder=True)
    n_cam = 2 if a.stereo else len(a.recording)
    if a.reference is not None and not 0 <= a.reference < n_cam:
        fail(f"--reference {a.reference}: there are cameras 0-{n_cam - 1}")
    names = [f"camera-{k}" for k in range(n_cam)]
    files = {f["file"] for f in pattern["frames"]}
    busy = [n for n in names if os.path.isdir(os.path.join(out, n)) and files & set(os.listdir(os.path.join(out, n)))]
    if busy and not a.force:
        fail(f"{os.path.join(out, busy[0])} already holds frames (use --force to overwrite)")
    cams = load_cameras(a)
    for name, c in zip(names, cams):
        for note in c.notes:
            say(f"rotstar-segment: note: {note}")
        say(f"rotstar-segment: {name}: {c.what}: {len(c.frames)} frames of {c.frames.shape[2]}x{c.frames.shape[1]}, "
            f"{'16' if c.full_scale == 65535 else '8'}-bit")
    frames = [c.frames for c in cams]
    try:
        check_recordings(frames, [f"{n} ({c.what})" for n, c in zip(names, cams)])
    except SegmentError as e:
        fail(str(e))
    try:
        rs = segment_rig(frames, pattern["frames"], layout, [c.full_scale for c in cams], options_from(a),
                         a.reference, names)
    except SegmentError as e:
        fail(str(e), EXIT_FAILED)
    except CaptureError as e:
        fail(str(e))
    say(f"rotstar-segment: {rs.summary()}")
    for n in rs.notes:
        say(f"rotstar-segment: note: {n}")
    try:
        with whole_or_none(out):  # an interrupt leaves no new pose folder with some of its cameras
            _write_rig(a, out, seq, pose, names, cams, rs, pattern, layout)
    except (dataset.DatasetError, OSError, ValueError) as e:
        fail(str(e))
    out_line(out)
    return 0


def _write_rig(a, out, seq, pose, names, cams, rs, pattern, layout) -> None:
    """Every camera's frames into OUT/camera-<k>/, with its quick check"""
    for name, c, seg in zip(names, cams, rs.cameras):
        scale = _scale(a, seg, c.full_scale, name)
        gaps = int(np.sum(np.maximum(np.diff(c.sequence) - 1, 0))) if len(c.sequence) > 1 else 0
        folder = write_segmented(seq, f"{pose}/{name}", seg, pattern, c.full_scale, scale,
                                 {"recording": c.what, "dropped_camera_frames": gaps,
                                  "camera": name, "boundaries_from": names[rs.reference]})
        if not a.no_check:
            r = quick_check(seg, layout, pattern, c.full_scale / scale)
            n = layout.nx * layout.ny
            say(f"rotstar-segment: {name}: board found: {r.n_valid} of {n} corners" if r.found
                else f"rotstar-segment: {name}: no board: {r.error}")
            with open(os.path.join(folder, "segment.json")) as f:
                info = json.load(f)
            info["quick_check"] = {"found": r.found, "corners": r.n_valid, "error": r.error,
                                   "motion_px": r.motion_px}
            with atomic_write(os.path.join(folder, "segment.json")) as f:
                json.dump(info, f, indent=1, default=float)
                f.write("\n")


if __name__ == "__main__":
    sys.exit(main())

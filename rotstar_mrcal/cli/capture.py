"""rotstar-capture: record the looping player pose by pose into calibration datasets"""

from __future__ import annotations

import argparse
import collections
import json
import os
import shutil
import sys
import time

import cv2
import numpy as np

from .. import dataset
from ..detect.display import dataset_offsets
from ..capture import coverage
from ..capture.backends import BACKENDS, describe_nodes, open_source
from ..capture.d435 import DEFAULT_FPS, DEFAULT_FOURCC, DEFAULT_SIZE, format_warning
from ..capture.motion import difference_signal, downsample, still_fraction
from ..capture.pose import quick_check, value_scale, write_segmented
from ..capture.segment import SegmentError, segment, threshold
from ..capture.source import CaptureError, ControlError, FrameSource, record, skip
from ..display.loop import player_loop
from ..display.player import DEFAULT_HOLD
from .common import EXIT_CODES_HELP, EXIT_FAILED, EXIT_INTERRUPTED, atomic_path, atomic_write, check_output_path, \
    fail, run, say, size_arg
from .segment import add_segment_options, options_from

DESCRIPTION = """\
Record the rotating-star sequence that player.html loops on the screen, one
camera pose at a time, and turn every recording into a dataset pose folder
that rotstar-detect reads: per pose and per exposure, record at least one
whole loop of the player, split it into the displayed frames (as
rotstar-segment does), detect the board at once and say whether it was
complete and which parts of the imager the corners cover so far (mrcal
needs corners near the edges and corners of the image; OUT/.../coverage.png
shows them). Then the next pose: on Enter, or with --auto as soon as the
view has moved and is still again.

Default camera: an Intel RealSense D435 (--camera d435) over plain V4L2:
the left-IR node is found by USB id and format list, the stream is Y16
1280x800 at 25 fps (unrectified; GREY/Y8 is rectified by the camera and
unsuitable for calibrating the lens), auto exposure off, the exposure in
microseconds and the IR projector off through the camera's extension unit,
gain 16. A control that cannot be set stops the capture (unless --force).

Several exposures (--exposure 2000,4000,8000) give one dataset each,
OUT/exp2000us, OUT/exp4000us, ..., to calibrate and compare separately.
Without --exposure the camera's exposure is left alone and OUT is the
dataset.

Messages go to stderr; stdout gets only the dataset folders written (and
the device listing of --list).
"""

EPILOG = """\
examples:
  rotstar-capture --list                                   # first contact: nodes, formats, controls
  rotstar-capture --pattern pattern/ --out seq --exposure 2000,4000,8000
  rotstar-capture --pattern pattern/ --out seq --auto --poses 30
  rotstar-capture --backend replay --device rec.npy --pattern pattern/ --out seq --frames 300
  rotstar-detect seq/exp4000us > corners.vnl

""" + EXIT_CODES_HELP + " (a camera that cannot be opened or set: 1)\n"


def _exposures(s: str) -> list[int]:
    try:
        v = [int(round(float(x))) for x in s.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{s!r}: expected microseconds, e.g. 2000,4000,8000") from None
    if not v or min(v) < 1:
        raise argparse.ArgumentTypeError(f"{s!r}: exposures must be positive microseconds")
    return v


def parse_args(argv=None):
    p = argparse.ArgumentParser(prog="rotstar-capture", description=DESCRIPTION, epilog=EPILOG,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--list", action="store_true",
                   help="list every video node (USB id, formats, sizes, frame rates, controls, D4xx "
                        "extension-unit values) on stdout and exit")
    p.add_argument("--pattern", help="the pattern folder (or its pattern.json) that player.html shows")
    p.add_argument("--out", "-o", help="dataset folder (one sub-folder per exposure with --exposure)")
    g = p.add_argument_group("camera")
    g.add_argument("--backend", choices=BACKENDS, default="v4l2", help="default v4l2")
    g.add_argument("--camera", choices=("d435", "generic"), default="d435",
                   help="v4l2 controls: d435 (any RealSense D4xx: extension unit) or generic (standard UVC)")
    g.add_argument("--device", help="v4l2: /dev/videoN (default: the D435's IR node, found by USB id); "
                                    "libcamera: the camera index or id; replay: the recording")
    g.add_argument("--serial", help="the camera's USB serial number, when several are plugged in")
    g.add_argument("--fourcc", default=DEFAULT_FOURCC.strip(), help="pixel format (default Y16)")
    g.add_argument("--size", type=size_arg, default=DEFAULT_SIZE, help="default 1280x800")
    g.add_argument("--fps", type=float, default=None, help=f"frame rate (default {DEFAULT_FPS:g}; replay: from the recording)")
    g.add_argument("--exposure", type=_exposures, help="microseconds, one dataset each, e.g. 2000,4000,8000 "
                                                       "(default: leave the camera's exposure alone)")
    g.add_argument("--gain", type=float, help="sensor gain (default 16 on a D435, the lowest; else unchanged)")
    g.add_argument("--emitter", choices=("off", "on", "keep"), default=None,
                   help="IR projector (default off on a D435, keep elsewhere)")
    g.add_argument("--settle", type=int, default=8,
                   help="frames dropped after a change of exposure or a pause (default 8)")
    g.add_argument("--force", action="store_true", help="go on when a control cannot be set")
    r = p.add_argument_group("recording")
    r.add_argument("--frames", type=int, help="camera frames per recording (default: --loops loops of the player)")
    r.add_argument("--loops", type=float, default=2.2, help="player loops per recording (default 2.2: at least one "
                                                            "whole loop wherever the recording starts)")
    r.add_argument("--hold", type=int, default=DEFAULT_HOLD, help=f"the player's hold, refreshes (default {DEFAULT_HOLD})")
    r.add_argument("--refresh", type=float, default=60.0, help="the screen's refresh rate, Hz (default 60)")
    r.add_argument("--poses", type=int, default=0, help="stop after this many poses (default: until q or the end of a replay)")
    r.add_argument("--auto", action="store_true",
                   help="start the next pose when the view has moved and then been still for --still seconds")
    r.add_argument("--still", type=float, default=1.0, help="seconds of stillness that start a pose with --auto (default 1)")
    r.add_argument("--keep-raw", action="store_true", help="keep every recording as OUT/raw/<pose>_<exposure>.npy (+ .json)")
    add_segment_options(p)
    a = p.parse_args(argv)
    if not a.list and (not a.pattern or not a.out):
        p.error("--pattern and --out are needed (or --list)")
    if a.backend == "replay" and a.exposure:
        p.error("a replay has the exposure it was recorded with: drop --exposure")
    return a


# ---- first contact -------------------------------------------------------------------
def print_nodes(nodes: list[dict]) -> None:
    if not nodes:
        print("no video nodes (/sys/class/video4linux is empty): is the camera plugged in, on USB 3?")
    for n in nodes:
        head = f"{n['path']}: {n.get('card') or n['name']}"
        if n.get("usb"):
            head += f"  [USB {n['usb']}, interface {n.get('interface')}, serial {n.get('serial') or '?'}]"
        print(head)
        if "error" in n:
            print(f"  error: {n['error']}")
            continue
        if not n.get("capture"):
            print("  not a video-capture node (metadata)")
            continue
        for fmt, modes in n.get("modes", {}).items():
            warn = format_warning(fmt) if n.get("xu") else None
            print(f"  {fmt:5s} {' '.join(modes)}" + ("  (rectified)" if warn else ""))
        for name, v in n.get("controls", {}).items():
            print(f"  control {name} = {v}")
        for name, v in n.get("xu", {}).items():
            print(f"  extension unit {name} = {v}")


# ---- the session ------------------------------------------------------------------------
def frames_per_recording(a, n_entries: int, fps: float) -> int:
    if a.frames:
        return a.frames
    if not fps:
        raise CaptureError("the frame rate is unknown (a replay without one): give --frames N or --fps")
    loop_s = n_entries * a.hold / a.refresh
    return int(np.ceil(a.loops * loop_s * fps))


def default_controls(a) -> tuple[float | None, str]:
    """(gain, emitter) to set: a D435 gets gain 16 and the emitter off unless told otherwise"""
    d435 = a.backend in ("v4l2", "realsense") and a.camera == "d435"
    gain = a.gain if a.gain is not None else (16.0 if d435 else None)
    return gain, a.emitter or ("off" if d435 else "keep")


def control(a, what: str, f, *args):
    """Run a control call; on ControlError say so and stop, or go on with --force"""
    try:
        return f(*args)
    except ControlError as e:
        if not a.force:
            raise CaptureError(f"{what}: {e} (run with --force to go on anyway)") from None
        say(f"rotstar-capture: warning: {what}: {e}; going on (--force)")
        return False


def wait_for_new_view(src: FrameSource, tau: float, fps: float, still_s: float, need_motion: bool,
                      step: int = 4) -> bool:
    """Read frames until the view has moved (if need_motion) and then stayed still; False at the end of a replay"""
    n = max(10, int(round(still_s * (fps or 25))))
    window = collections.deque(maxlen=n + 1)
    moved = not need_motion
    while True:
        f = src.read()
        if f is None:
            return False
        window.append(downsample(f.image, step))
        if len(window) < window.maxlen:
            continue
        d, _ = difference_signal(list(window), src.full_scale, step=1)
        frac = still_fraction(d, tau)
        if not moved and frac < 0.3:
            moved = True
        elif moved and frac >= 0.75:
            return True


def next_free_pose(folders: list[str]) -> int:
    k = 0
    while any(os.path.isdir(os.path.join(f, f"pose{k:03d}")) for f in folders):
        k += 1
    return k


class Dataset:
    """One output dataset (one exposure): its folder, corners so far, the value scale"""

    def __init__(self, folder: str, exposure: int | None):
        self.folder, self.exposure = folder, exposure
        self.boards: list[np.ndarray] = []
        self.shifts: dict = {}  # pose -> FrameShifts, for the display offsets over the session
        self.imagersize = None
        self.scale: float | None = None
        self.tau: float | None = None  # stability threshold of the latest recording (for --auto)
        self.log: list[dict] = []

    @property
    def label(self) -> str:
        return f"{self.exposure} us" if self.exposure else ""

    def what(self, pose: str) -> str:
        """'pose003' or 'pose003 at 4000 us', for messages"""
        return f"{pose} at {self.label}" if self.exposure else pose


def capture_one(src, ds: Dataset, pose: str, pattern, layout, nframes: int, a, raw_dir: str) -> bool:
    """Record, segment, write and check one pose into one dataset; True when a board was found

    The recording goes to OUT/raw/<pose>[_exp<us>us].npy (a memory map, not
    RAM: 275 Y16 frames of a D435 are 560 MB), removed after segmentation
    unless --keep-raw.
    """
    os.makedirs(raw_dir, exist_ok=True)
    tag = f"{pose}_exp{ds.exposure}us" if ds.exposure else pose
    raw = os.path.join(raw_dir, tag + ".npy")
    first = src.read()
    if first is None:
        raise EOFError
    buf = np.lib.format.open_memmap(raw, mode="w+", dtype=first.image.dtype, shape=(nframes,) + first.image.shape)
    try:
        buf[0] = first.image
        rec = record(src, nframes - 1, out=buf[1:]) if nframes > 1 else None
        seqnums = np.r_[first.sequence, rec.sequence] if rec else np.array([first.sequence])
        n = len(seqnums)
        if a.keep_raw:
            buf.flush()
            with open(os.path.join(raw_dir, tag + ".json"), "w") as f:
                json.dump({"sequence": [int(v) for v in seqnums], "fps": src.fps, "exposure_us": ds.exposure,
                           "frames": n}, f)
        if n < nframes:
            say(f"rotstar-capture: {ds.what(pose)}: the source ended after {n} of {nframes} frames")
        return process_recording(src, ds, pose, pattern, layout, buf[:n], seqnums, a)
    finally:
        del buf
        if not a.keep_raw:
            os.remove(raw)


def process_recording(src, ds: Dataset, pose: str, pattern, layout, frames, seqnums, a) -> bool:
    """Segment, check, write one recording; report on stderr; True when a board was found"""
    opts = options_from(a)
    entry = {"pose": pose, "exposure_us": ds.exposure, "frames": len(frames),
             "dropped": int(np.sum(np.maximum(np.diff(seqnums) - 1, 0)))}
    ds.log.append(entry)
    try:
        seg = segment(frames, pattern["frames"], layout, src.full_scale, opts)
        ds.tau = seg.tau
    except SegmentError as e:
        d, _ = difference_signal(frames, src.full_scale, opts.step)
        ds.tau = threshold(d, opts.k, opts.ratio)
        say(f"rotstar-capture: {ds.what(pose)}: not usable: {e}")
        entry.update(ok=False, error=str(e))
        return False
    if ds.scale is None:
        ds.scale, note = value_scale(max(float(np.max(im)) for im in seg.images.values()), src.full_scale)
        if note:
            say(f"rotstar-capture: note{f' ({ds.label})' if ds.label else ''}: {note}")
    r = quick_check(seg, layout, pattern, src.full_scale / ds.scale)  # the averages are not scaled yet
    total = layout.nx * layout.ny
    entry.update(summary=seg.summary(), drift_px=seg.loop.motion_px, found=r.found, corners=r.n_valid,
                 error=r.error)
    if not r.found:
        say(f"rotstar-capture: {ds.what(pose)}: no board: {r.error}")
        entry["ok"] = False
        return False
    folder = write_segmented(ds.folder, pose, seg, pattern, src.full_scale, ds.scale,
                             {"exposure_us": ds.exposure, "dropped_camera_frames": entry["dropped"],
                              "quick_check": {"corners": r.n_valid, "motion_px": r.motion_px}})
    ds.boards.append(r.corners)
    ds.imagersize = (frames.shape[2], frames.shape[1])
    counts = coverage.coverage_counts(ds.boards, ds.imagersize)
    with atomic_path(os.path.join(ds.folder, "coverage.png")) as tmp:
        cv2.imwrite(tmp, coverage.coverage_image(ds.boards, ds.imagersize))
    state = "complete" if r.n_valid == total else f"{total - r.n_valid} corner(s) missing"
    if r.shifts is not None:
        ds.shifts[pose] = r.shifts
    display = dataset_offsets(ds.shifts)
    motion = display.motion_px.get(pose, r.motion_px)
    entry.update(motion_px=motion, display_offsets=None if display.offsets is None else display.offsets.tolist())
    say(f"rotstar-capture: {ds.what(pose)}: board {state} ({r.n_valid}/{total}), frames agree to "
        f"{motion:.3f} px beyond the display's offsets; {coverage.describe(counts)}")
    say(f"rotstar-capture: {display.summary()}")
    entry.update(ok=True, folder=folder)
    print(folder, flush=True)
    return True


def main(argv=None, source: FrameSource | None = None) -> int:
    return run("rotstar-capture", lambda argv: _main(argv, source), argv)


def _main(argv=None, source: FrameSource | None = None) -> int:
    a = parse_args(argv)
    if a.list:
        print_nodes(describe_nodes())
        return 0
    try:
        pattern, layout = dataset.read_pattern(a.pattern)
    except dataset.DatasetError as e:
        fail(str(e))
    check_output_path(a.out, [dataset.pattern_file(a.pattern)], folder=True)
    n_entries = len(player_loop(pattern["frames"]))
    warn = format_warning(a.fourcc) if a.camera == "d435" and a.backend != "replay" else None
    if warn:
        say(f"rotstar-capture: warning: {warn}")
    fps = a.fps if a.fps else (None if a.backend == "replay" else DEFAULT_FPS)
    try:
        src = source or open_source(a.backend, a.device, a.camera, a.fourcc, a.size, fps, a.serial)
    except CaptureError as e:
        fail(str(e), EXIT_FAILED)
    datasets = [Dataset(os.path.join(a.out, f"exp{e}us"), e) for e in a.exposure] if a.exposure else [Dataset(a.out, None)]
    raw_dir = os.path.join(a.out, "raw")
    interrupted = False
    log = {"format": "rotstar-capture/1", "started": time.strftime("%Y-%m-%d %H:%M:%S"), "argv": sys.argv[1:] if argv is None else list(argv)}
    try:
        log["source"] = src.info()
        say(f"rotstar-capture: {src.name}: " + ", ".join(f"{k} {v}" for k, v in log["source"].items()
                                                        if k in ("device", "card", "format", "fps", "path", "frames")))
        gain, emitter = default_controls(a)
        if emitter != "keep" and control(a, f"emitter {emitter}", src.set_emitter, emitter == "on") is not False:
            say(f"rotstar-capture: emitter {emitter}")
        if gain is not None:
            got = control(a, f"gain {gain:g}", src.set_gain, gain)
            if got is not False:
                say(f"rotstar-capture: gain {got:g}")
        nframes = frames_per_recording(a, n_entries, src.fps)
        say(f"rotstar-capture: {nframes} frames per recording ({a.loops:g} loops of {n_entries} x {a.hold} "
            f"refreshes at {a.refresh:g} Hz)" if not a.frames else f"rotstar-capture: {nframes} frames per recording")
        os.makedirs(a.out, exist_ok=True)
        pose_no = next_free_pose([d.folder for d in datasets])
        src.start()
        taken, tau = 0, None
        interactive = not a.auto
        while not a.poses or taken < a.poses:
            pose = f"pose{pose_no:03d}"
            if interactive:
                say(f"rotstar-capture: {pose}: place the camera, hold still, press Enter (q: quit) ")
                line = sys.stdin.readline()
                if not line or line.strip().lower() == "q":
                    break
                skip(src, a.settle)
            elif tau is not None:  # (the first pose of --auto is recorded at once)
                say(f"rotstar-capture: {pose}: waiting for the view to move and then be still ...")
                if not wait_for_new_view(src, tau, src.fps, a.still, need_motion=True):
                    say("rotstar-capture: the recording ended")
                    break
            ok_any = False
            try:
                for ds in datasets:
                    if ds.exposure:
                        control(a, f"exposure {ds.exposure} us", src.set_exposure_us, ds.exposure)
                        skip(src, a.settle)
                    ok = capture_one(src, ds, pose, pattern, layout, nframes, a, raw_dir)
                    ok_any |= ok
            except EOFError:
                say("rotstar-capture: the recording ended")
                break
            finally:
                log["poses"] = {os.path.basename(os.path.normpath(d.folder)): d.log for d in datasets}
                with atomic_write(os.path.join(a.out, "capture.json")) as f:
                    json.dump(log, f, indent=1, default=str)
            tau = min((d.tau for d in datasets if d.tau is not None), default=tau)
            if ok_any:
                taken += 1
                pose_no += 1
    except CaptureError as e:
        say(f"rotstar-capture: {e}")
        return EXIT_FAILED
    except KeyboardInterrupt:  # Ctrl-C or SIGTERM: the poses so far are kept, the summary follows
        say("rotstar-capture: interrupted")
        interrupted = True
    finally:
        try:
            src.stop()
        finally:
            src.close()
        if not a.keep_raw and os.path.isdir(raw_dir):
            shutil.rmtree(raw_dir, ignore_errors=True)
    for ds in datasets:
        good = sum(1 for e in ds.log if e.get("ok"))
        say(f"rotstar-capture: {ds.folder}: {good} pose(s) with a board; next: rotstar-detect {ds.folder} > corners.vnl")
    if interrupted:
        return EXIT_INTERRUPTED
    return 0 if any(e.get("ok") for ds in datasets for e in ds.log) else EXIT_FAILED


if __name__ == "__main__":
    sys.exit(main())

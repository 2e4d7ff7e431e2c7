"""rotstar-capture: record the looping player pose by pose into calibration datasets"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import os
import shutil
import signal
import sys
import threading
import time

import cv2
import numpy as np

from rotstar_mrcal import dataset
from rotstar_mrcal.capture.backends import BACKENDS, describe_nodes, open_source
from rotstar_mrcal.capture.exposure import (
    SHORTEST_US, START_US, choose_exposure, longest_exposure_us, look_frames,
)
from rotstar_mrcal.capture.d435 import DEFAULT_FPS, DEFAULT_FOURCC, DEFAULT_SIZE, format_warning
from rotstar_mrcal.capture.rig import RigSource
from rotstar_mrcal.capture.rig_session import RigDataset, capture_rig_one
from rotstar_mrcal.capture.session import (
    OutputDataset, SessionOptions, capture_one, next_free_pose, wait_for_new_view,
)
from rotstar_mrcal.capture.source import CaptureError, ControlError, FrameSource, skip
from rotstar_mrcal.pattern.loop import entry_holds, player_loop
from rotstar_mrcal.pattern.player import DEFAULT_HOLD, hold_text
from rotstar_mrcal.cli.common import (
    EXIT_FAILED, EXIT_INTERRUPTED, HelpFormatter, atomic_write, check_output_path, exit_status_help, fail,
    out_line, run, say, size_arg,
)
from rotstar_mrcal.cli.segment_args import add_segment_options, options_from
from rotstar_mrcal.cli.common import HOLD_HELP, hold_arg

DESCRIPTION = """\
Record the display sequence that player.html loops on the screen (the
rotating-star frames, the identity frames, the checkerboard), one camera
pose at a time, and turn every recording into a dataset pose folder
that rotstar-detect reads: per pose and per exposure, record at least one
whole loop of the player, split it into the displayed frames (as
rotstar-segment does), detect the board at once and say whether it was
complete and which parts of the imager the corners cover so far (mrcal
needs corners near the edges and corners of the image; OUT/.../coverage.png
shows them). Then the next pose: on Enter, or with --auto as soon as the
view has moved and is still again. A replay (--backend replay) also waits
for Enter before each pose, then records its next frames; with --auto it
runs through without waiting (rotstar-simulate --recording makes one to try).

Default camera: an Intel RealSense D435 (--camera d435) over plain V4L2:
the left-IR node is found by USB id and format list, the stream is Y16
1280x800 at 25 fps (unrectified; GREY/Y8 is rectified by the camera and
unsuitable for calibrating the lens), auto exposure off, the exposure in
microseconds and the IR projector off through the camera's extension unit,
gain 16. A control that cannot be set stops the capture (unless --force).

Both infrared imagers (--stereo): the D435's interleaved calibration
stream Y12I (left and right, 12 bits each, unrectified, 1280x800 at 25 fps
by default), split into camera-0 (left) and camera-1 (right) with the same
exposure, gain and emitter settings; --stereo-format Y8I is the camera's
rectified 8-bit pair, for a quick look only (not for calibrating the
lenses). --rgb-device /dev/videoN adds the colour camera (its own node,
format and size; its luma is recorded as grey) as the next camera. The
cameras are read in lockstep (the colour camera is not hardware-
synchronised with the infrared pair: at each infrared frame its newest
frame is taken), every camera's recording is split with the same frame
boundaries, and each pose becomes OUT/poseNNN/camera-<k>/ folders (the
multi-camera layout of doc/dataset.md), with a coverage picture per camera.

Several exposures (--exposure 2000,4000,8000) give one dataset each,
OUT/exp2000us, OUT/exp4000us, ..., to calibrate and compare separately.
Without --exposure (or with --exposure auto) the capture first takes a
short look at the playing screen (on Enter, or at once with --auto; a few
camera frames at a time, about a second or two) and picks the exposure that puts the pattern's white at 75 %
of full scale, unclipped, then records as if that exposure had been given
(OUT/exp<us>us); a screen it cannot see or that is too dark even at the
longest exposure stops it with the reason. --exposure keep leaves the
camera's exposure alone and OUT is the dataset; a replay keeps the exposure
it was recorded with.

Messages go to stderr; stdout gets only the dataset folders written (and
the device listing of --list).
"""

EPILOG = """\
examples:
  rotstar-capture --list                                   # first contact: nodes, formats, controls
  rotstar-capture --pattern pattern/ --out seq --exposure 2000,4000,8000
  rotstar-capture --pattern pattern/ --out seq --auto --poses 30       # exposure picked by a look
  rotstar-capture --pattern pattern/ --out seq --exposure keep          # the camera's exposure as it is
  rotstar-capture --backend replay --device rec.npy --pattern pattern/ --out seq --frames 640   # Enter per pose
  rotstar-capture --backend replay --device rec.npy --pattern pattern/ --out seq --hold 18 --auto
  rotstar-capture --pattern pattern/ --out stereo --stereo --exposure 4000          # both IR imagers
  rotstar-capture --pattern pattern/ --out rig --stereo --rgb-device /dev/video4 --rgb-exposure 300
  rotstar-detect seq/exp4000us > corners.vnl

""" + exit_status_help("done", failed="a camera that cannot be opened or set, a screen the exposure look "
                                        "cannot see or expose (--exposure auto), or no pose written") + "\n"


def _exposures(s: str) -> list[int] | str:
    """--exposure: 'auto', 'keep', or microseconds, one dataset each

    >>> _exposures("auto"), _exposures("2000,4000")
    ('auto', [2000, 4000])
    """
    if s in ("auto", "keep"):
        return s
    try:
        v = [int(round(float(x))) for x in s.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{s!r}: expected auto, keep or microseconds, e.g. 2000,4000,8000") from None
    if not v or min(v) < 1:
        raise argparse.ArgumentTypeError(f"{s!r}: exposures must be positive microseconds")
    return v


def parse_args(argv=None):
    p = argparse.ArgumentParser(prog="rotstar-capture", description=DESCRIPTION, epilog=EPILOG,
                                formatter_class=HelpFormatter)
    for add in (_what_arguments, _camera_arguments, _several_camera_arguments, _recording_arguments,
                add_segment_options):
        add(p)
    a = p.parse_args(argv)
    if a.until_enough is None:  # the short holds record until enough, unless a length was asked for
        a.until_enough = a.hold is None and not a.frames
    if not a.list and not a.snapshot and (not a.pattern or not a.out):
        p.error("--pattern and --out are needed (or --list, --snapshot)")
    if a.backend == "replay" and a.exposure not in (None, "keep"):
        p.error("a replay has the exposure it was recorded with: drop --exposure")
    if a.exposure is None:
        a.exposure = "keep" if a.backend == "replay" else "auto"
    if (a.stereo or a.rgb_device) and a.backend != "v4l2":
        p.error("--stereo and --rgb-device record over V4L2 (--backend v4l2); split recordings of several cameras "
                "with rotstar-segment")
    return a


def _what_arguments(p) -> None:
    """What to do: list the nodes, a snapshot, or record the pattern into --out"""
    p.add_argument("--list", action="store_true",
                   help="list every video node (USB id, formats, sizes, frame rates, controls, D4xx "
                        "extension-unit values) on stdout and exit")
    p.add_argument("--snapshot", metavar="DIR",
                   help="first contact: set the controls, drop --settle frames, write one frame of every camera as "
                        "DIR/camera-<k>.png (as recorded) and print each one's mean and maximum, then exit (with "
                        "--stereo: cover one lens to see which camera goes dark)")
    p.add_argument("--pattern", help="the pattern folder (or its pattern.json) that player.html shows")
    p.add_argument("--out", "-o", help="dataset folder (one sub-folder per exposure with --exposure)")


def _camera_arguments(p) -> None:
    """The camera: backend, node, format, controls"""
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
    g.add_argument("--exposure", type=_exposures, metavar="auto|keep|US[,US...]",
                   help="auto (the default): a short look at the playing screen picks one exposure (the pattern's "
                        "white at 75 %% of full scale, unclipped) and OUT/exp<us>us gets the dataset; keep: leave the "
                        "camera's exposure alone (OUT is the dataset; a replay's default); microseconds, one dataset "
                        "each, e.g. 2000,4000,8000. --snapshot sets only given microseconds")
    g.add_argument("--gain", type=float, help="sensor gain (default 16 on a D435, the lowest; else unchanged)")
    g.add_argument("--emitter", choices=("off", "on", "keep"), default=None,
                   help="IR projector (default off on a D435, keep elsewhere)")
    g.add_argument("--settle", type=int, default=8,
                   help="frames dropped after a change of exposure or a pause (default 8)")
    g.add_argument("--force", action="store_true", help="go on when a control cannot be set")


def _several_camera_arguments(p) -> None:
    """A D435's two infrared imagers and its colour camera"""
    s = p.add_argument_group("several cameras (D435: both infrared imagers, the colour camera)")
    s.add_argument("--stereo", action="store_true",
                   help="record the left and the right infrared imager (cameras 0 and 1) from the interleaved "
                        "stream of the IR node (default Y12I 1280x800 at 25 fps, unrectified)")
    s.add_argument("--stereo-format", choices=("Y12I", "Y8I"), default="Y12I",
                   help="Y12I: unrectified 12-bit, for calibration (default); Y8I: rectified by the camera, a quick "
                        "look only")
    s.add_argument("--rgb-device", help="also record this colour node (e.g. the D435's RGB camera, /dev/videoN of "
                                        "its USB interface 3; see --list) as the next camera, converted to grey")
    s.add_argument("--rgb-format", choices=("YUYV", "UYVY", "MJPG"), default="YUYV",
                   help="the colour node's format (default YUYV: its luma is the grey image; MJPG is lossy)")
    s.add_argument("--rgb-size", type=size_arg, default=(1280, 720), help="the colour node's size (default 1280x720)")
    s.add_argument("--rgb-fps", type=float, default=30.0, help="the colour node's frame rate (default 30)")
    s.add_argument("--rgb-exposure", type=float,
                   help="the colour camera's manual exposure, microseconds (standard UVC controls, 100 us steps); "
                        "default: left alone (its auto exposure will follow the sequence's black marker: set it)")


def _recording_arguments(p) -> None:
    """How long each recording is and when the next pose starts"""
    r = p.add_argument_group("recording")
    r.add_argument("--frames", type=int, help="camera frames per recording (default: --loops loops of the player)")
    r.add_argument("--loops", type=float, default=2.2, help="player loops per recording (default 2.2: at least one "
                                                            "whole loop wherever the recording starts); with "
                                                            "--until-enough the most a pose records")
    r.add_argument("--hold", type=hold_arg, default=DEFAULT_HOLD,
                   help=f"{HOLD_HELP} (default {hold_text(DEFAULT_HOLD)})")
    r.add_argument("--refresh", type=float, default=60.0, help="the screen's refresh rate, Hz (default 60)")
    r.add_argument("--until-enough", action=argparse.BooleanOptionalAction,
                   help="record one loop of the player and two frames, then more, until every frame of pattern.json "
                        "the pose needs has two clean camera frames (split by their content; one identity frame and "
                        "the checkerboard may be missing); the recording's length (--loops, --frames) is the limit. "
                        "Says the seconds each pose took (default: on with the short holds, off with --hold N or "
                        "--frames N)")
    r.add_argument("--poses", type=int, default=0, help="stop after this many poses (default: until q or the end of a replay)")
    r.add_argument("--auto", action="store_true",
                   help="start the next pose when the view has moved and then been still for --still seconds")
    r.add_argument("--still", type=float, default=1.0, help="seconds of stillness that start a pose with --auto (default 1)")
    r.add_argument("--keep-raw", action="store_true", help="keep every recording as OUT/raw/<pose>_<exposure>.npy (+ .json)")

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
            label = "  (rectified)" if warn else "  (left + right, unrectified: --stereo)" \
                if fmt == "Y12I" and n.get("xu") else ""
            print(f"  {fmt:5s} {' '.join(modes)}{label}")
        for name, v in n.get("controls", {}).items():
            print(f"  control {name} = {v}")
        for name, v in n.get("xu", {}).items():
            print(f"  extension unit {name} = {v}")


def enter_prompt(backend: str, nframes: int) -> str:
    """What to do before a pose without --auto: a camera is placed; a replay just waits for Enter

    >>> enter_prompt("replay", 633)
    'press Enter to record the next 633 frames of the replay (q: quit; --auto goes on without waiting)'
    """
    if backend == "replay":
        return f"press Enter to record the next {nframes} frames of the replay (q: quit; --auto goes on without waiting)"
    return "place the camera, hold still, press Enter (q: quit)"


def os_error(e: OSError) -> str:
    """'path: reason' of an OSError, in one line

    >>> os_error(OSError(28, "No space left on device", "seq/pose003"))
    'seq/pose003: No space left on device'
    >>> os_error(OSError("seq/raw/pose003.npy: no space left on device (20 MB needed)"))
    'seq/raw/pose003.npy: no space left on device (20 MB needed)'
    """
    return f"{e.filename}: {e.strerror}" if e.filename and e.strerror else str(e)


# ---- the session ------------------------------------------------------------------------
def camera_names(rig: RigSource) -> list[str]:
    """What each camera of a rig is, for the log: 'left IR (Y12I 1280x800)', ..."""
    out = []
    for s in rig.sources:
        fmt = getattr(s, "format", None)
        what = f"{fmt.fourcc.strip()} {fmt.width}x{fmt.height}" if fmt else s.name
        where = getattr(s, "path", "")
        out += ([f"left IR ({where} {what})", f"right IR ({where} {what})"] if getattr(s, "views", 1) == 2
                else [f"{where} ({what})"])
    return out


def frames_per_recording(a, holds, fps: float) -> int:
    """--frames, or --loops loops of the player (holds: refreshes of every loop entry, pattern.loop.entry_holds)"""
    if a.frames:
        return a.frames
    if not fps:
        raise CaptureError("the frame rate is unknown (a replay without one): give --frames N or --fps")
    loop_s = int(np.sum(holds)) / a.refresh
    return int(np.ceil(a.loops * loop_s * fps))


def first_look(a, pattern: dict, fps: float) -> int:
    """--until-enough's first recording, in camera frames: one loop of the player and two camera frames

    The entry the recording starts in is seen at both ends, in two pieces
    that together hold its whole time but for one more change of the
    displayed frame (a camera frame or two lost to it): the two camera
    frames. Measured: one loop and 5 refreshes keep as many poses as one
    loop and two entries (tests/capture/test_timing_flaws.py).
    """
    holds = entry_holds(player_loop(pattern["frames"]), a.hold)
    fps = fps or 25.0
    return int(np.ceil(holds.sum() / a.refresh * fps)) + 2


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


def open_rig(a, fps) -> FrameSource:
    """The infrared node (both imagers with --stereo) and the colour node, as one RigSource"""
    fourcc = a.stereo_format if a.stereo else a.fourcc
    ir = open_source("v4l2", a.device, a.camera, fourcc, a.size, fps, a.serial, stereo=a.stereo)
    sources = [ir]
    try:
        if a.rgb_device:
            rgb = open_source("v4l2", a.rgb_device, "generic", a.rgb_format, a.rgb_size, a.rgb_fps)
            sources.append(rgb)
            if a.rgb_exposure:
                control(a, f"colour exposure {a.rgb_exposure:g} us", rgb.set_exposure_us, a.rgb_exposure)
    except CaptureError:
        for s in sources:
            s.close()
        raise
    return RigSource(sources)


def snapshot(a, src: FrameSource, names: list[str]) -> int:
    """--snapshot: one frame per camera to DIR, and their levels on stdout"""
    os.makedirs(a.snapshot, exist_ok=True)
    gain, emitter = default_controls(a)
    if emitter != "keep":
        control(a, f"emitter {emitter}", src.set_emitter, emitter == "on")
    if gain is not None:
        control(a, f"gain {gain:g}", src.set_gain, gain)
    if isinstance(a.exposure, list):
        control(a, f"exposure {a.exposure[0]} us", src.set_exposure_us, a.exposure[0])
    src.start()
    skip(src, a.settle)
    views = src.read_views() if isinstance(src, RigSource) else [src.read()]
    if views is None or views[0] is None:
        raise CaptureError("no frame")
    for k, (f, name) in enumerate(zip(views, names)):
        fn = os.path.join(a.snapshot, f"camera-{k}.png")
        cv2.imwrite(fn, f.image)
        print(f"camera-{k} {name}: {fn}, mean {float(f.image.mean()):.1f}, max {int(f.image.max())} "
              f"({f.image.dtype}), frame {f.sequence}")
    return 0


@contextlib.contextmanager
def ctrl_c_stops():
    """Ctrl-C (SIGINT) interrupts the capture even where it was started ignoring it

    A shell script that starts a command in the background (`cmd &`) starts it
    with SIGINT ignored; a capture session must stop on Ctrl-C (or kill -INT)
    at any point, its pose detection included, so the handler is put back.
    """
    main = threading.current_thread() is threading.main_thread()
    old = signal.getsignal(signal.SIGINT) if main else None
    if main and old == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        if main and old == signal.SIG_IGN:
            signal.signal(signal.SIGINT, old)


def main(argv=None, source: FrameSource | None = None) -> int:
    with ctrl_c_stops():
        return run("rotstar-capture", lambda argv: _main(argv, source), argv)


def _main(argv=None, source: FrameSource | None = None) -> int:
    a = parse_args(argv)
    if a.list:
        print_nodes(describe_nodes())
        return 0
    if a.snapshot:
        return _snapshot(a, source)
    try:
        pattern, layout = dataset.read_pattern(a.pattern)
    except dataset.DatasetError as e:
        fail(str(e))
    check_output_path(a.out, [dataset.pattern_file(a.pattern)], folder=True)
    holds = entry_holds(player_loop(pattern["frames"]), a.hold)  # refreshes of every loop entry
    _warn_formats(a)
    src = _open(a, source, a.fps if a.fps else (None if a.backend == "replay" else DEFAULT_FPS))
    return _session(a, argv, src, pattern, layout, holds)


def _open(a, source: FrameSource | None, fps):
    """The camera (or the rig) to record from; exits (EXIT_FAILED) when it cannot be opened"""
    try:
        return source or (open_rig(a, fps) if a.stereo or a.rgb_device else
                          open_source(a.backend, a.device, a.camera, a.fourcc, a.size, fps, a.serial))
    except CaptureError as e:
        fail(str(e), EXIT_FAILED)


def _snapshot(a, source: FrameSource | None) -> int:
    """--snapshot: open, one frame per camera, close"""
    src = _open(a, source, a.fps or DEFAULT_FPS)
    try:
        return snapshot(a, src, camera_names(src) if isinstance(src, RigSource) else [getattr(src, "path", "")])
    except CaptureError as e:
        say(f"rotstar-capture: {e}")
        return EXIT_FAILED
    finally:
        try:
            src.stop()
        finally:
            src.close()


def _warn_formats(a) -> None:
    """Warnings about the camera's settings: a D435 format that loses bits, the colour camera's auto exposure"""
    ir_format = a.stereo_format if a.stereo else a.fourcc
    warn = format_warning(ir_format) if a.camera == "d435" and a.backend != "replay" else None
    if warn:
        say(f"rotstar-capture: warning: {warn}")
    if not a.rgb_exposure and a.rgb_device:
        say("rotstar-capture: warning: the colour camera's exposure is left alone (--rgb-exposure sets it): "
            "auto exposure changes the brightness between the player's frames")


def _session(a, argv, src, pattern, layout, holds) -> int:
    """Pose after pose into one dataset per exposure, capture.json after each; the summary; the exit status"""
    rig = isinstance(src, RigSource)
    if rig:
        say(f"rotstar-capture: {src.cameras} cameras: " + ", ".join(
            f"camera-{k} {v}" for k, v in enumerate(camera_names(src))))
    raw_dir = os.path.join(a.out, "raw")
    interrupted = False
    datasets = []
    log = {"format": "rotstar-capture/1", "started": time.strftime("%Y-%m-%d %H:%M:%S"), "argv": sys.argv[1:] if argv is None else list(argv)}
    try:
        nframes = _start(a, src, log, holds)
        src.start()
        exposures = _exposures_to_record(a, src, holds, log)
        datasets += [RigDataset(f, e, src.cameras) if rig else OutputDataset(f, e) for f, e in zip(
            [os.path.join(a.out, f"exp{e}us") if e else a.out for e in exposures], exposures)]
        _record_poses(a, src, datasets, pattern, layout, nframes, raw_dir, log)
    except CaptureError as e:
        say(f"rotstar-capture: {e}")
        return EXIT_FAILED
    except OSError as e:  # a pose folder, capture.json, stdout that cannot be written (a full disk)
        say(f"rotstar-capture: {os_error(e)}")
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
        say(f"rotstar-capture: {ds.folder}: {ds.good} pose(s) with a board; next: rotstar-detect {ds.folder} > corners.vnl"
            + (" (the multi-camera layout: doc/dataset.md)" if rig else ""))
    if interrupted:
        return EXIT_INTERRUPTED
    return 0 if any(ds.good for ds in datasets) else EXIT_FAILED


def _start(a, src, log: dict, holds) -> int:
    """The source described, its emitter and gain set, OUT made; the number of frames per recording"""
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
    nframes = frames_per_recording(a, holds, src.fps)
    say(f"rotstar-capture: {nframes} frames per recording ({a.loops:g} loops of {int(np.sum(holds))} "
        f"refreshes at {a.refresh:g} Hz)" if not a.frames else f"rotstar-capture: {nframes} frames per recording")
    os.makedirs(a.out, exist_ok=True)
    return nframes


def _exposures_to_record(a, src, holds, log: dict) -> list[int | None]:
    """--exposure's microseconds; auto: the one a look at the screen picks (said, logged); keep: [None]

    Without --auto the look waits for Enter (the camera must face the playing screen); --auto looks at once,
    as it records its first pose at once.
    """
    if a.exposure != "auto":
        return [None] if a.exposure == "keep" else a.exposure
    if not a.auto:
        say("rotstar-capture: exposure: point the camera at the playing screen, press Enter to look (q: quit)")
        line = sys.stdin.readline()
        if not line or line.strip().lower() == "q":
            raise CaptureError("stopped before the exposure look: no pose written")
        skip(src, a.settle)
    got = control(a, "exposure auto", choose_exposure, src, START_US, look_frames(holds, a.refresh, src.fps),
                  a.settle, SHORTEST_US, longest_exposure_us(src.fps))
    if got is False:  # --force: a camera whose exposure cannot be set
        return [None]
    log["auto_exposure"] = dataclasses.asdict(got)
    if got.failure:
        raise CaptureError(f"exposure auto: {got.failure}")
    say(f"rotstar-capture: {got.summary()}")
    return [int(got.exposure_us)]


def _record_poses(a, src, datasets, pattern, layout, nframes: int, raw_dir: str, log: dict) -> None:
    """(src streaming) Until --poses poses with a board (or q, the recording's end): wait for a view, record it"""
    opts = SessionOptions(dataclasses.replace(options_from(a), hold=a.hold or 0, refresh_hz=a.refresh), a.keep_raw,
                          first_look(a, pattern, src.fps) if a.until_enough else 0)
    pose_no = next_free_pose([d.folder for d in datasets])
    taken, tau = 0, None
    while not a.poses or taken < a.poses:
        pose = f"pose{pose_no:03d}"
        if not _next_view(a, src, pose, nframes, tau):
            break
        try:
            ok_any = _record_pose(a, src, datasets, pose, pattern, layout, nframes, raw_dir, opts)
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


def _next_view(a, src, pose: str, nframes: int, tau) -> bool:
    """Wait for the next view: the user's Enter, or (--auto) the view moving and then still; False: stop"""
    if not a.auto:
        say(f"rotstar-capture: {pose}: " + enter_prompt(a.backend, nframes))
        line = sys.stdin.readline()
        if not line or line.strip().lower() == "q":
            return False
        skip(src, a.settle)
    elif tau is not None:  # (the first pose of --auto is recorded at once)
        say(f"rotstar-capture: {pose}: waiting for the view to move and then be still ...")
        if not wait_for_new_view(src, tau, src.fps, a.still, need_motion=True, by_content=a.hold is None):
            say("rotstar-capture: the recording ended")
            return False
    return True


def _record_pose(a, src, datasets, pose: str, pattern, layout, nframes: int, raw_dir: str, opts) -> bool:
    """One view at every exposure, each into its dataset; whether any found a board"""
    grab = capture_rig_one if isinstance(src, RigSource) else capture_one
    ok_any = False
    for ds in datasets:
        if ds.exposure:
            control(a, f"exposure {ds.exposure} us", src.set_exposure_us, ds.exposure)
            skip(src, a.settle)
        out = grab(src, ds, pose, pattern, layout, nframes, raw_dir, opts)
        for m in out.messages:
            say(f"rotstar-capture: {m}")
        if out.folder:
            out_line(out.folder)
        ok_any |= out.ok
    return ok_any


if __name__ == "__main__":
    sys.exit(main())

"""rotstar-simulate: write a synthetic rotating-star dataset with its ground truth

SYNOPSIS

    rotstar-simulate --out seq/ --camera d435 --poses 24 --seed 0 --jobs 2

Writes seq/pattern.json, seq/poseNNN/*.png (every frame of the pattern, the
identity frames included unless --no-identity, as a camera at a random pose
sees the screen), seq/truth.cameramodel and
seq/truth.json (the poses and the true corner projections). Progress goes to
stderr; stdout gets only the output folder, for piping.

    rotstar-simulate --rig d435 --rgb --out seq/ --poses 24

writes a multi-camera dataset instead (doc/dataset.md): seq/poseNNN/camera-K/
for every camera K that sees the board (0: left IR, 1: right IR 50 mm to its
right, 2: the colour camera with --rgb), seq/truth-camera-K.cameramodel (each
camera's true intrinsics and extrinsics, camera 0 at the origin) and
seq/truth.json (per pose rt_ref_board and each camera's true corners).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import sys

import mrcal
import numpy as np

from rotstar_mrcal.dataset import DatasetError, read_pattern
from rotstar_mrcal.pattern.layout import make_layout

PAPER_SEQUENCE = dict(phase_period=150, star_segments=16)  # rotstar-pattern --paper-sequence's defaults (pitch 150)
from rotstar_mrcal.simulate.camera import PRESETS, preset_model
from rotstar_mrcal.simulate.dataset import Settings, write_dataset
from rotstar_mrcal.simulate.display import parse_display_maps
from rotstar_mrcal.simulate.poses import default_distance_range, random_poses
from rotstar_mrcal.optics.wavefront import TERMS, Seidel
from rotstar_mrcal.optics.refraction import DEFAULT_INDEX
from rotstar_mrcal.optics.psf import LensPSF
from rotstar_mrcal.simulate.rig import RIGS, rig_cameras, rig_poses, write_rig_dataset
from rotstar_mrcal.simulate.screen import exact_frames, png_frames, shown_light
from rotstar_mrcal.cli.common import HOLD_HELP, hold_arg
from rotstar_mrcal.capture.simulated import ALL_FLAWS, Flaws, write_player_recording
from rotstar_mrcal.pattern.player import DEFAULT_HOLD, hold_text
from rotstar_mrcal.cli.common import (
    EXIT_CODES_HELP, EXIT_FAILED, HelpFormatter, check_output_path, fail, number_arg, out_line, run,
)

DESCRIPTION = """\
Render a synthetic dataset: the rotating-star screen seen by a camera at
random poses, exposed and quantised like a real sensor, with the ground truth
(true camera model, poses and corner projections) next to it. Or, with
--recording, what a camera records while player.html loops (a camera stream
of the sequence, pose after pose), to try rotstar-segment and rotstar-capture
--backend replay without a camera.
"""

EPILOG = """\
examples:
  rotstar-simulate --out seq/ --poses 24 --jobs 2
  rotstar-simulate --out seq-glass/ --glass 0.7          # a tablet's cover glass over the pixels
  rotstar-simulate --rig d435 --rgb --out stereo/
  rotstar-pattern --out pattern/
  rotstar-simulate --recording rec.npy --pattern pattern/ --camera pinhole-small --hold 18 --poses 2
  rotstar-capture --backend replay --device rec.npy --pattern pattern/ --hold 18 --auto --out seq/
  rotstar-segment one-pose.npy --pattern pattern/ --out seq/pose000

""" + EXIT_CODES_HELP + "\n"

DISPLAY_GAMMA = 2.2  # the gamma rotstar-pattern encodes for when pattern.json records none


def seidel_arg(spec: str) -> Seidel:
    """argparse type of --seidel: 'coma=1.5,focus=0.3' -> Seidel (waves at the image corners)

    SYNOPSIS

        >>> seidel_arg("coma=1.5,focus=0.3")
        Seidel(tilt=0.0, focus=0.3, spherical=0.0, coma=1.5, astigmatism=0.0, tilt_angle=0.0, coma_angle=0.0, astigmatism_angle=0.0)
        >>> seidel_arg("coma=x")
        Traceback (most recent call last):
        argparse.ArgumentTypeError: 'coma=x': coma must be a finite number of waves
    """
    terms = {}
    for item in spec.split(","):
        name, eq, value = item.strip().partition("=")
        if not eq or name not in TERMS:
            raise argparse.ArgumentTypeError(f"{spec!r}: expected TERM=WAVES,... with TERM one of {', '.join(TERMS)}")
        if name in terms:
            raise argparse.ArgumentTypeError(f"{spec!r}: {name} given twice")
        try:
            v = float(value)
        except ValueError:
            v = math.nan
        if not math.isfinite(v) or abs(v) > 20:
            raise argparse.ArgumentTypeError(f"{spec!r}: {name} must be a finite number of waves"
                                             + (" (at most 20 in size)" if math.isfinite(v) else ""))
        terms[name] = v
    return Seidel(**terms)


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="rotstar-simulate", description=DESCRIPTION, epilog=EPILOG,
                                formatter_class=HelpFormatter)
    for add in (_scene_arguments, _glass_arguments, _sensor_arguments, _pose_arguments, _recording_arguments):
        add(p)
    args = p.parse_args(argv)
    for check in (_check_recording, _check_values, _check_combinations):
        check(p, args)
    return args


def _scene_arguments(p) -> None:
    """What is written and seen: the dataset, the pattern, the camera or rig, the poses' number and seed"""
    p.add_argument("--out", metavar="SEQ", help="dataset folder to write (needed unless --recording)")
    p.add_argument(
        "--pattern",
        metavar="DIR",
        help="folder with the pattern.json (as rotstar-pattern writes it) describing the screen; "
        "default: make_layout() defaults (2360x1640 screen at 264 dpi)",
    )
    p.add_argument(
        "--no-identity",
        dest="identity",
        action="store_false",
        help="leave out the identity frames (each element's index, shown after the rotating-star frames) and "
        "render the sequence without them, as rotstar-pattern --no-identity writes it; with --pattern, the "
        "dataset's pattern.json then lists no identity frames either",
    )
    p.add_argument(
        "--paper-sequence",
        action="store_true",
        help="without --pattern: the paper's whole sequence (rotstar-pattern --paper-sequence: phase shifts along "
        "x and y, the checkerboard, the 16-segment star); with --pattern, the sequence is the pattern.json's",
    )
    p.add_argument(
        "--screen-png",
        action="store_true",
        help="show the pattern PNGs of --pattern DIR (8-bit, decoded with the display gamma) "
        "instead of the exact linear frames",
    )
    p.add_argument("--camera", default="d435", metavar="NAME|FILE",
                   help=f"camera preset ({', '.join(PRESETS)}) or a .cameramodel file")
    p.add_argument("--rig", choices=list(RIGS), default=None,
                   help="simulate a rig of several cameras instead of --camera: "
                        + "; ".join(f"{k}: {v['description']}" for k, v in RIGS.items())
                        + ". Writes the multi-camera layout (poseNNN/camera-K/) and truth-camera-K.cameramodel")
    p.add_argument("--rgb", action="store_true", help="with --rig: add the colour camera (camera 2, grayscale, 8-bit)")
    p.add_argument("--poses", type=int, default=None, help="number of random poses (default 24; 1 with --recording)")
    p.add_argument("--seed", type=int, default=0, help="seed of the poses and of the noise")


def _glass_arguments(p) -> None:
    """A cover glass over the screen's pixels (optics.refraction)"""
    p.add_argument("--glass", type=number_arg(float, 0, 5), default=0.0, metavar="MM",
                   help="a cover glass this thick (mm, 0-5) over the emitting layer: every camera ray is refracted at "
                        "its surface on the way to the pixels (laminated tablets and phones: 0.5-1.5 mm); the truth "
                        "stays the emitting layer (default 0: none)")
    p.add_argument("--glass-index", type=number_arg(float, 1), default=DEFAULT_INDEX, metavar="N",
                   help=f"refractive index of the --glass (>= 1; default {DEFAULT_INDEX})")


def _sensor_arguments(p) -> None:
    """The lens and the sensor: blur or Seidel PSF, the screen's gamma, noise, gain, bits, sampling"""
    p.add_argument("--blur", type=float, default=None,
                   help="Gaussian PSF sigma in camera pixels (0: none); default 1.0 (without --seidel)")
    p.add_argument("--seidel", type=seidel_arg, default=None, metavar="TERM=WAVES,...",
                   help="a lens PSF from Seidel aberrations instead of the Gaussian --blur: waves at the image "
                        "corners of " + ", ".join(TERMS) + ", e.g. 'coma=1.5,focus=0.3' (make demo's lens); "
                        "field-dependent (tilt and coma grow with the field radius, focus and astigmatism with "
                        "its square, coma and astigmatism point along it), diffraction at F/2, 3 um pixels, "
                        "550 nm; coma's centroid shift is put back by tilt = -coma unless tilt is given; with --rig each "
                        "camera gets the lens over its own imager (the right imager's amplitudes x0.9, the colour "
                        "camera's x1.1)")
    p.add_argument("--screen-gamma", type=number_arg(float, 0.1, 10), default=None, metavar="G",
                   help="the screen's real gamma: the pattern's 8-bit values are encoded for the display gamma "
                        "pattern.json records (rotstar-pattern --gamma; 2.2 if none) and the screen emits "
                        "(value/255)^G; binary frames do not notice, phase-shift fringes bend. Default: no "
                        "mismatch (the exact linear frames, or --screen-png decoded with the encoded gamma)")
    p.add_argument("--noise", type=float, default=0.01, help="additive Gaussian noise sigma, fraction of full scale")
    p.add_argument(
        "--shot", type=float, default=0.0, help="signal-dependent noise: variance per unit signal (1/full-well)"
    )
    p.add_argument("--gain", type=float, default=0.9, help="signal (fraction of full scale) of a white screen head-on")
    p.add_argument("--black", type=float, default=0.0, help="black level, fraction of full scale")
    p.add_argument("--bits", type=int, choices=(8, 16), default=16, help="PNG bit depth")
    p.add_argument(
        "--value-bits",
        type=int,
        default=None,
        metavar="N",
        help="with --bits 16: quantise to N bits (10 or 12, like a D435 Y16 stream) scaled into 16 bits; "
        "default: the full bit depth",
    )
    p.add_argument("--supersample", type=int, default=4, help="s: s x s sub-pixels per camera pixel")
    p.add_argument(
        "--sampling",
        choices=("area", "point"),
        default="area",
        help="sub-pixel sampling of the screen: exact box average over the footprint, or its centre only",
    )
    p.add_argument("--room", type=float, default=0.02, help="luminance seen off the screen (white screen = 1)")


def _pose_arguments(p) -> None:
    """Where the board goes, the player's flaws, the work"""
    p.add_argument(
        "--distance",
        type=float,
        nargs=2,
        metavar=("MIN", "MAX"),
        help="camera to board-centre distance range, metres; default: 0.3 0.6 for the d435 and the "
        "default layout, scaled with fx/width and the board size otherwise",
    )
    p.add_argument("--max-tilt", type=float, default=60.0, help="largest angle, degrees, between the board normal and the line of sight")
    p.add_argument("--margin", type=float, default=None, help="board-to-image-edge margin in pixels; default 2%% of the width")
    p.add_argument("--display-offsets", metavar="SPEC", default=None,
                   help="show each rotating-star frame displaced on the screen, the same in every pose (a "
                        "player or screen that is not pixel-exact): 'x0,y0,x1,y1,...' display pixels per "
                        "frame, or 'random:A' for offsets uniform in a disc of radius A (seeded by --seed)")
    p.add_argument("--display-map", metavar="SPEC", default=None,
                   help="show chosen rotating-star frames shifted, scaled or stretched, the same in every pose: "
                        "'K:DX,DY[,SX,SY][@ANCHOR];...' with K the frame (0-based), DX, DY display px, SX, SY the "
                        "stretch in ppm or in display px over the screen with a 'px' suffix, ANCHOR the point kept "
                        "(center, top, bottom, left, right, top-left, ...); e.g. '2:0,2;3:0,1,0,1px@bottom' "
                        "(frame 3 one display px taller, its bottom kept); composed after --display-offsets")
    p.add_argument("--jobs", type=int, default=1, help="render poses in this many processes (results do not depend on it)")
    p.add_argument("--force", action="store_true", help="write into a folder that already holds a dataset")


def _recording_arguments(p) -> None:
    """--recording: the looping player filmed instead of a dataset"""
    r = p.add_argument_group("a recording of the looping player (instead of a dataset)")
    r.add_argument("--recording", metavar="REC.npy",
                   help="write what a camera records while player.html loops, pose after pose (still for --loops "
                        "loops and a bit, then moving for a second), as REC.npy + REC.json: the recording that "
                        "rotstar-segment and rotstar-capture --backend replay read; no ground truth, no --out")
    r.add_argument("--hold", type=hold_arg, default=DEFAULT_HOLD,
                   help=f"{HOLD_HELP} (default {hold_text(DEFAULT_HOLD)}; give rotstar-capture the same --hold)")
    r.add_argument("--refresh", type=number_arg(float, 0, lo_open=True), default=60.0, help="screen refresh rate, Hz")
    r.add_argument("--fps", type=number_arg(float, 0, lo_open=True), default=25.0, help="camera frame rate")
    r.add_argument("--loops", type=number_arg(float, 0, lo_open=True), default=2.2,
                   help="loops of the player per pose that rotstar-capture records (its --loops); each pose is "
                        "still for 1 s + this + 1 loops")
    r.add_argument("--timing-flaws", action="store_true",
                   help="the display's and the camera's timing flaws on (capture.simulated.ALL_FLAWS: a 5 ms LCD "
                        "response, a 480 Hz PWM backlight, the browser a refresh late or early now and then, 1 %% "
                        "of the camera's frames lost, its clock 200 ppm fast)")


def _check_recording(p, args) -> None:
    """--out or --recording, and what --recording does not take"""
    if (args.out is None) == (args.recording is None):
        p.error("give --out SEQ (a dataset) or --recording REC.npy (a recording of the player), not both" if
                args.out else "--out SEQ is needed (or --recording REC.npy)")
    if args.recording and (args.rig or args.display_offsets or args.display_map or args.screen_png or args.force
                           or args.shot or args.black or args.value_bits or args.glass):
        p.error("--recording takes a single camera and the sensor's gain, noise and bits; drop --rig, "
                "--display-offsets, --display-map, --screen-png, --shot, --black, --value-bits, --glass and --force")
    if args.recording and not args.pattern:
        p.error("--recording needs --pattern DIR: the pattern folder player.html shows (rotstar-pattern --out DIR)")
    if args.recording and not args.recording.endswith(".npy"):
        p.error(f"--recording {args.recording}: the file name must end in .npy")


def _check_values(p, args) -> None:
    """Counts and bit depths in range; the defaults that depend on other arguments"""
    if args.poses is None:
        args.poses = 1 if args.recording else 24
    if args.poses < 1:
        p.error("--poses must be at least 1")
    if args.supersample < 1:
        p.error("--supersample must be at least 1")
    if args.jobs < 1:
        p.error("--jobs must be at least 1")
    if args.value_bits is not None and not 1 <= args.value_bits <= args.bits:
        p.error(f"--value-bits must be between 1 and --bits ({args.bits})")


def _check_combinations(p, args) -> None:
    """Arguments that exclude or need each other; finite, non-negative numbers"""
    if args.paper_sequence and args.pattern:
        p.error("--paper-sequence is for the default screen; with --pattern the sequence is the pattern.json's")
    if args.screen_png and not args.pattern:
        p.error("--screen-png needs --pattern DIR")
    if args.seidel is not None and args.blur is not None:
        p.error("--seidel replaces the Gaussian --blur; give one of them")
    if args.blur is None:
        args.blur = 0.0 if args.seidel is not None else 1.0
    if args.rgb and not args.rig:
        p.error("--rgb adds the colour camera of a --rig")
    if args.rig and (args.display_offsets or args.display_map):
        p.error("--display-offsets and --display-map are not simulated for a --rig")
    if args.rig and args.camera != p.get_default("camera"):
        p.error("--camera and --rig exclude each other: the rig defines its cameras")
    if not all(math.isfinite(v) for v in (args.blur, args.noise, args.shot, args.gain, args.black, args.room,
                                          args.max_tilt, *(args.distance or ()), *([args.margin] if args.margin else []))):
        p.error("--blur, --noise, --shot, --gain, --black, --room, --max-tilt, --distance and --margin must be finite")
    if args.blur < 0 or args.noise < 0 or args.shot < 0:
        p.error("--blur, --noise and --shot must not be negative")

def display_offsets(spec: str | None, n: int, seed: int) -> np.ndarray | None:
    """--display-offsets: (n, 2) display pixels, or None

        >>> display_offsets("1,0,0,-1", 2, 0).tolist()
        [[1.0, 0.0], [0.0, -1.0]]
        >>> float(np.abs(display_offsets("random:3", 8, 0)).max()) <= 3
        True
    """
    if spec is None:
        return None
    try:
        if spec.startswith("random:"):
            a = float(spec.split(":", 1)[1])
            if not (np.isfinite(a) and a >= 0):
                raise ValueError
            rng = np.random.default_rng([2, seed])
            r, t = a * np.sqrt(rng.uniform(0, 1, n)), rng.uniform(0, 2 * np.pi, n)
            return np.column_stack((r * np.cos(t), r * np.sin(t)))
        v = np.array([float(x) for x in spec.split(",")])
    except ValueError:
        raise ValueError(f"--display-offsets {spec!r}: expected 'x0,y0,x1,y1,...' or 'random:A'") from None
    if v.size != 2 * n or not np.isfinite(v).all():
        raise ValueError(f"--display-offsets {spec!r}: need {2 * n} finite numbers, x and y for each of {n} frames")
    return v.reshape(n, 2)


def display_flaws(args, layout) -> dict:
    """write_dataset's display_offsets and display_maps from --display-offsets and --display-map (None: none)"""
    return {"display_offsets": display_offsets(args.display_offsets, layout.nframes, args.seed),
            "display_maps": None if args.display_map is None else
            parse_display_maps(args.display_map, layout.nframes, (layout.screen_width, layout.screen_height))}


def display_gamma(pattern: dict, where: str) -> float:
    """The display gamma a pattern.json says its PNGs are encoded for (DISPLAY_GAMMA if it says none)"""
    g = pattern.get("display_gamma", DISPLAY_GAMMA)
    if isinstance(g, bool) or not isinstance(g, (int, float)) or not 0.1 <= g <= 10:
        raise ValueError(f"{where}: pattern.json's display_gamma {g!r} is not a number in [0.1, 10]")
    return float(g)


def screen_frames(args, layout, encoded: float) -> np.ndarray:
    """The light the screen emits for every frame: exact, or the PNGs, shown with --screen-gamma"""
    if args.screen_png:
        return png_frames(args.pattern, layout, encoded if args.screen_gamma is None else args.screen_gamma)
    frames = exact_frames(layout)
    return frames if args.screen_gamma is None else shown_light(frames, encoded, args.screen_gamma)


def load_camera(spec: str) -> tuple[mrcal.cameramodel, str]:
    if spec in PRESETS:
        return preset_model(spec), spec
    if os.path.isfile(spec):
        try:
            return mrcal.cameramodel(spec), os.path.abspath(spec)
        except Exception:  # mrcal raises a bare Exception listing every format it tried
            raise ValueError(f"{spec}: not a readable camera model (mrcal cannot parse it)") from None
    if os.path.exists(spec):
        raise ValueError(f"{spec}: not a regular file")
    raise ValueError(f"--camera {spec!r}: neither a preset ({', '.join(PRESETS)}) nor a file")


def main(argv=None) -> int:
    return run("rotstar-simulate", _main, argv)


def settings_of(args) -> Settings:
    return Settings(supersample=args.supersample, blur_px=args.blur, sampling=args.sampling, room=args.room,
                    gain=args.gain, black=args.black, noise=args.noise, shot=args.shot, bits=args.bits,
                    value_bits=args.value_bits, seed=args.seed, glass_mm=args.glass, glass_index=args.glass_index)


def _rig(args, layout, frames, cams, distance, say, gammas: dict) -> int:
    """--rig: the board poses drawn for camera 0, each camera rendering those it sees"""
    rt, seen = rig_poses(cams, layout, args.poses, np.random.default_rng([0, args.seed]), distance=distance,
                         max_tilt_deg=args.max_tilt, margin_px=args.margin)
    for k, c in enumerate(cams):
        W, H = (int(v) for v in c.model.imagersize())
        say(f"camera-{k} ({c.role}, {W}x{H}): sees {int(seen[:, k].sum())} of {len(rt)} poses")
    write_rig_dataset(args.out, layout, cams, rt, seen, settings_of(args), frames=frames, jobs=args.jobs,
                      progress=say, extra={"rig": args.rig, "rgb": args.rgb, "screen": "png" if args.screen_png
                                           else "exact", "distance_m": list(distance),
                                           "max_tilt_deg": args.max_tilt, "margin_px": args.margin, **gammas},
                      seidel=args.seidel)
    thin = [k for k in range(len(cams)) if seen[:, k].sum() < 2]
    out_line(args.out)
    if thin:
        say(f"warning: camera-{thin[0]} sees fewer than 2 poses; mrcal needs at least 2 per camera (more --poses)")
        return EXIT_FAILED
    return 0


def _recording(args, layout, model, camera: str, encoded: float, say) -> int:
    """--recording: the camera filming the looping player at --poses random poses, as REC.npy + REC.json"""
    try:
        distance = tuple(args.distance) if args.distance else default_distance_range(model, layout)
        rts = random_poses(model, layout, args.poses, np.random.default_rng([0, args.seed]), distance=distance,
                           max_tilt_deg=args.max_tilt, margin_px=args.margin)
        W, H = (int(v) for v in model.imagersize())
        say(f"a recording of the player (hold {args.hold or 'short'} at {args.refresh:g} Hz) by camera {camera} {W}x{H} at "
            f"{args.fps:g} fps, {args.poses} pose(s)")
        n = write_player_recording(
            args.recording, layout, model, rts, hold=args.hold, refresh_hz=args.refresh, fps=args.fps,
            loops=args.loops, gain=args.gain, noise=args.noise, bits=args.bits, room=args.room,
            supersample=args.supersample, psf=args.blur if args.seidel is None else LensPSF(args.seidel, (W, H)),
            frames=screen_frames(args, layout, encoded), seed=args.seed, progress=say,
            flaws=ALL_FLAWS if args.timing_flaws else Flaws())
    except (DatasetError, ValueError, RuntimeError) as e:
        fail(f"error: {e}", EXIT_FAILED)
    except OSError as e:  # a full disk: the file is removed
        fail(str(e) if not e.filename else f"{e.filename}: {e.strerror}", EXIT_FAILED)
    say(f"{args.recording}: {n} frames; next: rotstar-capture --backend replay --device {args.recording} "
        f"--pattern {args.pattern} --hold {args.hold or 'short'} --loops {args.loops:g} --auto --out seq/")
    out_line(args.recording)
    return 0


def _main(argv=None) -> int:
    args = parse_args(argv)

    def say(msg):
        print(f"rotstar-simulate: {msg}", file=sys.stderr, flush=True)

    try:
        layout, encoded = _layout(args)
        if args.rig:
            cams = rig_cameras(args.rig, args.seed, args.rgb, args.blur)
            model, camera = cams[0].model, f"{args.rig} rig camera 0"
        else:
            model, camera = load_camera(args.camera)
        if args.recording:
            check_output_path(args.recording)
            return _recording(args, layout, model, camera, encoded, say)
        _check_out(args)
        flaws = display_flaws(args, layout)
    except (DatasetError, ValueError) as e:
        fail(str(e))
    try:
        frames = screen_frames(args, layout, encoded)
        gammas = {"display_gamma": encoded,
                  "screen_gamma": args.screen_gamma if args.screen_gamma is not None else encoded}
        distance = tuple(args.distance) if args.distance else default_distance_range(model, layout)
        say(
            f"{args.poses} poses of a {layout.nx}x{layout.ny} grid ({len(frames)} frames each), camera {camera} "
            f"{model.imagersize()[0]}x{model.imagersize()[1]}, {distance[0]:.3g}-{distance[1]:.3g} m"
        )
        if args.rig:
            return _rig(args, layout, frames, cams, distance, say, gammas)
        _one_camera(args, layout, frames, model, camera, distance, say, gammas, flaws)
    except (DatasetError, ValueError, RuntimeError, OSError) as e:
        fail(f"error: {e}", EXIT_FAILED)
    out_line(args.out)
    return 0


def _layout(args):
    """(layout, the display gamma its PNGs are encoded for): --pattern's, or make_layout's"""
    if not args.pattern:
        return make_layout(identity=args.identity, **(PAPER_SEQUENCE if args.paper_sequence else {})), DISPLAY_GAMMA
    d, layout = read_pattern(args.pattern)
    encoded = display_gamma(d, args.pattern)
    if not args.identity:
        layout = dataclasses.replace(layout, identity=False)
    return layout, encoded


def _check_out(args) -> None:
    """--out: a folder to write, not the --pattern folder, not a dataset already (unless --force)"""
    check_output_path(args.out, folder=True)
    if args.pattern and os.path.realpath(args.out) == os.path.realpath(
            args.pattern if os.path.isdir(args.pattern) else os.path.dirname(args.pattern) or "."):
        fail(f"{args.out}: is the --pattern folder; write the dataset elsewhere")
    if not args.force and os.path.exists(os.path.join(args.out, "truth.json")):
        fail(f"{args.out} already holds a simulated dataset (use --force to overwrite)")


def _one_camera(args, layout, frames, model, camera: str, distance, say, gammas: dict, flaws: dict) -> None:
    """One camera: --poses random poses rendered into the dataset --out"""
    rts = random_poses(model, layout, args.poses, np.random.default_rng([0, args.seed]), distance=distance,
                       max_tilt_deg=args.max_tilt, margin_px=args.margin)
    write_dataset(
        args.out, layout, model, rts, settings_of(args), frames=frames,
        psf=None if args.seidel is None else LensPSF(args.seidel, model.imagersize()), jobs=args.jobs,
        progress=say, **flaws,
        extra={"camera": camera, "screen": "png" if args.screen_png else "exact", **gammas,
               "distance_m": list(distance), "max_tilt_deg": args.max_tilt,
               "margin_px": args.margin if args.margin is not None else 0.02 * float(model.imagersize()[0])})


if __name__ == "__main__":
    sys.exit(main())

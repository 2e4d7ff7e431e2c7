"""rotstar-detect: a recorded rotating-star dataset in, mrcal corners.vnl out"""

from __future__ import annotations

import argparse
import os
import stat
import sys

from rotstar_mrcal import dataset
from rotstar_mrcal.detect.blurmap import blur_rows, write_blur_map
from rotstar_mrcal.detect.display_offsets import MAX_MOTION
from rotstar_mrcal.detect.edgespread import PSF_MIN_WINDOW
from rotstar_mrcal.detect.elements import MIN_WINDOW
from rotstar_mrcal.peers.registry import METHODS, REFINERS, reason_counts
from rotstar_mrcal.detect.run import detect_dataset, missing_frames
from rotstar_mrcal.vnl import write_corners
from rotstar_mrcal.cli.common import (
    EXIT_FAILED, HelpFormatter, exit_status_help, Progress, atomic_write, check_output_path, fail,
    number_arg, run, say,
)

DESCRIPTION = """\
Detect the corners of every pose of a recorded rotating-star dataset and write
them as mrcal's corners.vnl (to stdout, or -o FILE). Progress, the poses that
failed and why, and the mrcal-calibrate-cameras command to run next go to
stderr.

Dataset layout: SEQ/pattern.json (as written by rotstar-pattern) and one
folder per pose, SEQ/<pose>/<file> for every frame in pattern.json (8- or
16-bit grayscale PNG). Poses are processed in sorted order; the filename
column of the output is SEQ/<pose>/<first rotating-star frame>. A pose may
lack one identity frame (a short capture that missed it): the elements are
named from the other identity frames, and a line on stderr says so.

Several cameras (SEQ/poseNNN/camera-K/<file>, doc/dataset.md): every
camera's poses are detected and written into the one corners.vnl (filename
column SEQ/poseNNN/camera-K/<first rotating-star frame>), every camera
labelling each board the same way (checked per pose across the cameras);
the printed command has one glob per camera and one focal seed per camera.
"""

EPILOG = """\
example:
  rotstar-detect seq/ > corners.vnl
  mrcal-calibrate-cameras --corners-cache corners.vnl ...   (printed on stderr)

""" + exit_status_help(
    "at least one pose gave a board (with several cameras: every camera gave the >= 2 boards mrcal needs)",
    failed="no pose did, or --method phase|star fell back to the rotating-star corners",
    bad="a dataset that cannot be read at all") + "\n"


DETECT_METHODS = ["rotstar"] + [n for n, m in METHODS.items() if m.start == "rotstar"]
DEFAULT_REFINE = "psf-sim"  # doc/blur-map.md: nearer the light's centroid under coma, the same without it


REFINE_HELP = ("symmetric: the paper's Eq. 1 on all rotating-star frames; "
               "opencv: cv2.cornerSubPix on the checkerboard frame; "
               "psf: the symmetric fit moved to the light's centroid, where the 16 edges meet, each placed "
               "at its line-spread function's mean (corners whose window is under 5 px keep the symmetric "
               "fit's; doc/blur-map.md); "
               "psf-sim (default): the symmetric fit less its offset from the light's centroid, found by running "
               "the same fit on the local star rendered through the coma the edges show, pooled over the "
               "dataset's poses (without coma, or without views of windows of 4 px or more, the symmetric fit's "
               "corners; about 1.4 x its time; doc/blur-map.md); "
               "saddle: Lucchese-Mitra saddle fit on the checkerboard frame")


def parse_args(argv=None):
    p = argparse.ArgumentParser(prog="rotstar-detect", description=DESCRIPTION, epilog=EPILOG,
                                formatter_class=HelpFormatter)
    p.add_argument("seq", help="dataset folder holding pattern.json and one folder per pose")
    p.add_argument("-o", "--output", help="write corners.vnl here instead of stdout")
    p.add_argument("--window", type=number_arg(float, MIN_WINDOW), default=10.0,
                   help="refinement half-window w in camera pixels (default 10); capped per corner "
                        "so the window stays inside its element")
    p.add_argument("--refine", choices=REFINERS, default=None, help=REFINE_HELP)
    p.add_argument("--method", choices=DETECT_METHODS, default="rotstar",
                   help="whose corners to write, all from the same poses and started from the rotating star's "
                        "labelled corners: " + "; ".join(f"{n}: {METHODS[n].description}" for n in DETECT_METHODS[1:])
                        + " (default rotstar; phase and star need a sequence from rotstar-pattern --paper-sequence: without "
                        "its frames the rotating-star corners are written instead, with a message and exit status 1)")
    p.add_argument("--weights", action="store_true",
                   help="write a weight column (1/sigma of each corner, normalised to median 1) "
                        "for mrcal's --corners-cache-has-weights")
    p.add_argument("--blur-map", metavar="DIR",
                   help="also estimate the lens's PSF at every corner from the rotating star's edges and write "
                        "DIR/blur_map.csv and DIR/blur_map.png (width, elongation, coma over the imager; "
                        "doc/blur-map.md)")
    p.add_argument("--max-motion", type=number_arg(float, 0, lo_open=True), default=MAX_MOTION,
                   help="reject a pose whose frames disagree by more than this many pixels beyond the "
                        "screen's per-frame display maps (the camera moved during the sequence; default 0.15)")
    p.add_argument("--jobs", "-j", type=number_arg(int, 1), default=1, help="poses processed in parallel (default 1)")
    p.add_argument("--no-hint", action="store_true", help=argparse.SUPPRESS)  # rotstar-calibrate runs its own
    p.add_argument("--quiet", "-q", action="store_true", help="no progress lines (skipped poses are still reported)")
    a = p.parse_args(argv)
    if a.blur_map and os.path.exists(a.blur_map) and not os.path.isdir(a.blur_map):
        p.error(f"--blur-map {a.blur_map}: exists and is not a folder")
    if a.method != "rotstar" and (a.weights or a.refine is not None):
        p.error(f"--weights and --refine are rotstar's; --method {a.method} gives its own corners")
    if a.refine is None:
        a.refine = DEFAULT_REFINE if a.method == "rotstar" else "symmetric"
    return a


def corners_name(output) -> tuple[str, bool]:
    """(the corners file to name in the hint, whether it is the real one): -o, or the file stdout goes to"""
    if output:
        return output, True
    try:
        if stat.S_ISREG(os.fstat(sys.stdout.fileno()).st_mode):
            path = os.readlink(f"/proc/self/fd/{sys.stdout.fileno()}")
            rel = os.path.relpath(path)
            return (rel if not rel.startswith("..") else path), True
    except (OSError, ValueError):
        pass
    return "corners.vnl", False


def sparse_line(pose: str, s) -> str:
    """The stderr line for a board written as none (vnl.SparseBoard)

    >>> from rotstar_mrcal.vnl import SparseBoard
    >>> sparse_line("pose007", SparseBoard("seq/pose007/rotstar_00.png", 14, 18))
    'pose007: 14 corners, mrcal ignores boards with <= 18; written as no board'
    """
    return f"{pose}: {s.corners} corners, mrcal ignores boards with <= {s.limit}; written as no board"


def summary_line(boards: int, poses: int, sparse: int) -> str:
    """The closing count: the boards mrcal will use

    >>> summary_line(11, 12, 1)
    'rotstar-detect: 11 of 12 poses gave a board (1 more gave too few corners for mrcal: written as no board)'
    """
    return (f"rotstar-detect: {boards} of {poses} poses gave a board"
            + (f" ({sparse} more gave too few corners for mrcal: written as no board)" if sparse else ""))


def main(argv=None) -> int:
    return run("rotstar-detect", _main, argv)


def _main(argv=None) -> int:
    """parse -> open the dataset -> detect (detect.run.detect_dataset) -> write the corners -> print"""
    a = parse_args(argv)
    ds, fell_back = open_for_detection(a)
    progress = Progress(sum(len(v) for v in ds.poses.values()) + len(ds.unmatched), a.quiet)
    say_before(a, ds, progress)
    vnl_name, real = corners_name(a.output)
    try:
        det = detect_dataset(ds, window=a.window, refine=REFINERS[a.refine], max_motion=a.max_motion, jobs=a.jobs,
                             progress=lambda r: progress_line(a, ds.layout, progress, r), method=a.method,
                             corners_file=vnl_name, weights=a.weights, blur_map=bool(a.blur_map))
    except dataset.DatasetError as e:
        fail(str(e))
    say_checks(a, det)
    say_blur_map(a.blur_map, det)
    sparse = write_output(a.output, det.boards(), det.weights() if a.weights else None)
    rc = say_boards(det, sparse) or say_command(a, det, real)
    return EXIT_FAILED if fell_back else rc


def open_for_detection(a) -> tuple[dataset.Dataset, bool]:
    """(the dataset opened once, whether --method fell back to rotstar); fail() on one that cannot be read"""
    try:
        ds = dataset.open_dataset(a.seq)
    except dataset.DatasetError as e:
        fail(str(e))
    fell_back = fall_back_to_rotstar(a, ds)
    if not ds.poses[0] and not ds.multi_camera:
        why = f" ({next(iter(ds.unmatched.values()))})" if ds.unmatched else ""
        fail(f"{a.seq}: no pose folders with frames from pattern.json{why}")
    if a.output:  # never over an input: pattern.json, a frame, anything in a pose folder
        check_output_path(a.output, [os.path.join(a.seq, "pattern.json")]
                          + [os.path.join(a.seq, p) for p in ds.pose_names + list(ds.unmatched)])
    return ds, fell_back


def say_before(a, ds: dataset.Dataset, progress: Progress) -> None:
    """The folders that are no pose, and the poses a camera of a rig did not see"""
    for name, msg in ds.unmatched.items():
        progress.step(name, f"skipped: {msg}", important=True)
    for k in ds.cameras:
        if ds.absent[k] and not a.quiet:
            say(f"rotstar-detect: {dataset.camera_folder(k)} has no folder in {len(ds.absent[k])} pose(s) "
                f"({', '.join(ds.absent[k][:4])}{' ...' if len(ds.absent[k]) > 4 else ''}): no board there")


def progress_line(a, layout, progress: Progress, r) -> None:
    """One pose done: its corners and why some are missing, or why it was skipped (after a note on its frames)"""
    if r.note:
        say(f"rotstar-detect: {r.pose}: {r.note}")
    if not r.found:
        progress.step(r.pose, f"skipped: {r.error}", important=True)
        return
    nx_ny = layout.nx * layout.ny
    why = ""
    if a.method != "rotstar" and r.corners.reasons is not None and r.corners.n_valid < nx_ny:
        why = f" ({a.method}: {reason_counts(r.corners.reasons)})"
    elif r.corners.n_valid < nx_ny:
        why = f" ({r.corners.missing_summary()})"
    progress.step(r.pose, f"{r.corners.n_valid} of {nx_ny} corners{why}")


def say_blur_map(outdir, det) -> None:
    """Write the blur map (detect.blurmap) of the poses that gave a board to outdir, and say where

    A rig gets one map per camera, in outdir/camera-K/.
    """
    if not outdir:
        return
    for k, cam in det.cameras.items():
        where = os.path.join(outdir, dataset.camera_folder(k)) if det.dataset.multi_camera else outdir
        found = cam.found
        rows = blur_rows([(r.pose, r.corners.corners, r.corners.blur) for r in found])
        if not rows:
            say(f"rotstar-detect: --blur-map: no corner with a window of {PSF_MIN_WINDOW:g} px or more; "
                f"nothing written to {where}")
            continue
        title = f"the lens's blur: {len(rows)} corners of {len({r[0] for r in rows})} poses (rotstar-detect --blur-map)"
        csv_path, png_path = write_blur_map(where, rows, found[0].size, title)
        say(f"rotstar-detect: blur map of {len(rows)} corners: {csv_path}, {png_path}")


def say_checks(a, det) -> None:
    """The dataset's checks: poses whose camera moved, the display maps, boards labelled unlike"""
    multi = det.dataset.multi_camera
    for k, d in det.cameras.items():
        for r in d.rejected:
            say(f"{r.pose}: skipped: {r.error}")
        if REFINERS[a.refine].needs == "rotstar" and not (multi and a.quiet):
            for line in d.display.summary().split("\n"):
                say(f"rotstar-detect: {dataset.camera_folder(k) + ': ' if multi else ''}{line}")
        if REFINERS[a.refine].pools and not (multi and a.quiet):
            say(f"rotstar-detect: {dataset.camera_folder(k) + ': ' if multi else ''}{pooled_line(a.refine, d)}")
    for pose, why in det.disagree.items():
        say(f"{pose}: skipped in every camera: {why}")


def pooled_line(name: str, d) -> str:
    """What a pooling refiner (psf-sim) measured over the camera's poses and how far it moved the corners"""
    import numpy as np

    from rotstar_mrcal.detect.pipeline import pooled_corrections
    from rotstar_mrcal.detect.psfbias import pooled_coma

    samples, moved = pooled_corrections([r.corners for r in d.found])  # (a pose the motion check rejected is
    # not found)
    n = 0 if samples is None else len(samples[0])
    if n < 6 or not (moved > 0).any():
        why = "no pose shows it" if n < 6 else f"not significant over {n} corners"
        return (f"{name}: no coma ({why}; it is read on corners whose window is 4 px or more): the corners are "
                f"the symmetric fit's")
    waves = pooled_coma(samples[0], samples[1], samples[0])[0]
    return (f"{name}: coma up to {waves.max():.1f} waves (read on {n} corners, pooled over the poses); the corners "
            f"moved {np.median(moved):.3f} px (median), {moved.max():.3f} px at most, to the light's centroid")


def say_boards(det, sparse) -> int:
    """The boards written as none, and the boards mrcal will use; EXIT_FAILED when there is none"""
    ds = det.dataset
    pose_of = {r.file: r.pose for r in det.results()}
    for s in sparse:
        say(sparse_line(pose_of.get(s.file, s.file), s))
    if not ds.multi_camera:
        say(summary_line(len(det.kept[0]), len(det.cameras[0].results) + len(ds.unmatched), len(sparse)))
    for k in ds.cameras if ds.multi_camera else []:
        say(f"rotstar-detect: {dataset.camera_folder(k)}: {len(det.kept[k])} of {len(ds.pose_names)} poses gave a "
            f"board ({ds.sizes[k][0]}x{ds.sizes[k][1]})")
    return 0 if any(det.kept.values()) else EXIT_FAILED


def say_command(a, det, real: bool) -> int:
    """The mrcal-calibrate-cameras command to run next (unless --no-hint), or why there is none"""
    ds = det.dataset
    if det.thin:
        k = det.thin[0]
        say(f"rotstar-detect: {dataset.camera_folder(k)}: {len(det.kept[k])} board(s); mrcal needs at least "
            "2 per camera to match the cameras' instants (record more poses in its view); no command to print")
        return EXIT_FAILED
    sizes = det.cameras[0].sizes
    if not ds.multi_camera and len(sizes) > 1:
        say(f"rotstar-detect: warning: poses have different image sizes {sizes}")
    if a.no_hint:
        return 0
    if not real:
        say("rotstar-detect: stdout is not a file: save the corners (rotstar-detect ... > corners.vnl, or -o) "
            "and put that file's name for corners.vnl below")
    if not ds.multi_camera:
        say("next, calibrate with:\n  " + det.command)
    else:
        if len(set(ds.sizes.values())) > 1:
            say("rotstar-detect: the cameras' image sizes differ, so the command gives no --imagersize (it applies "
                "to every camera): mrcal reads each camera's size from its first image; run it from this folder")
        say(f"next, calibrate the {len(ds.cameras)} cameras at once with:\n  " + det.command)
    return 0


def write_output(output: str | None, boards, weights):
    """The corners to the file `output` (atomically) or to stdout; write_corners' sparse boards"""
    if output:
        with atomic_write(output) as out:
            return write_corners(out, boards, weights)
    return write_corners(sys.stdout, boards, weights)


def fall_back_to_rotstar(a, ds: dataset.Dataset) -> bool:
    """--method phase|star on a sequence without their frames: say so, and detect rotstar's corners instead

    The corners are still written (a calibration can go on), the exit status
    is 1 (the method asked for did not run), and the message says which
    corners the output holds.
    """
    if a.method == "rotstar":
        return False
    what = missing_frames(ds.layout, a.method)
    if what:
        say(f"rotstar-detect: {dataset.pattern_file(a.seq)}: the sequence has no {what} (it was recorded without "
            f"rotstar-pattern --paper-sequence): --method {a.method} cannot run; writing the rotating-star corners "
            f"(--method rotstar) instead, exit status 1")
        a.method = "rotstar"
    return bool(what)


if __name__ == "__main__":
    sys.exit(main())

"""rotstar-calibrate: a recorded dataset (or its corners.vnl) in, an mrcal camera model out"""

from __future__ import annotations

import argparse
import glob
import json
import os
import sys

from rotstar_mrcal import dataset
from rotstar_mrcal.calibrate import checks, rig, solve as cal
from rotstar_mrcal.calibrate.cornerset import SourceError, load_corner_set
from rotstar_mrcal.calibrate.glass import MAX_PLAUSIBLE_MM, MIN_SIGMAS
from rotstar_mrcal.cli.common import (
    HelpFormatter, atomic_write, exit_status_help, make_folder, number_arg, run, say,
)
from rotstar_mrcal.optics.refraction import DEFAULT_INDEX
from rotstar_mrcal.detect.run import detect_dataset
from rotstar_mrcal.peers.registry import REFINERS
from rotstar_mrcal.vnl import write_corners

DESCRIPTION = f"""\
Calibrate a camera from a rotating-star dataset with mrcal: detect the
corners (rotstar-detect; or take --corners corners.vnl), then run
mrcal-calibrate-cameras with the board geometry from pattern.json, the
imager size from the images and a focal seed from the boards. Every command
is printed (stderr) before it runs; the model's path goes to stdout, what
mrcal says about it to stderr and OUTDIR/calibration.json.

The lens model ('auto', the default) follows mrcal's practice: the lean
{cal.LEAN_LENSMODEL} first (the model of rotstar-detect's printed command);
then, when >= {checks.SPLINED_MIN_BOARDS} boards cover >= {100 * checks.SPLINED_MIN_COVERAGE:.0f}% of the imager, mrcal's
splined model too; the two are compared with mrcal's projection diff against
their uncertainty, and the splined one is written only if it fits the
corners clearly better and differs beyond the uncertainty.

Checks: inputs that cannot give a model (fewer than {checks.MIN_BOARDS} boards, images of
different sizes, a focal seed the boards disagree on, a splined model the
boards cannot constrain) are refused before mrcal runs. A model with more
than {100 * checks.MAX_OUTLIER_FRACTION:.0f}% outliers, an empty valid-intrinsics region, or lean and splined
fits that disagree with no way to tell which is right, is not written
(OUTDIR/camera-0.cameramodel is removed; the fits stay in OUTDIR/candidates/)
unless --keep. The fit itself is checked: a board whose corners are out of
grid order (shuffled rows, a transposed board) is dropped and named before
mrcal runs; after each solve, a fit RMS over 1 px, a focal length not within
2x of the boards' own estimate, or a board far off the rest makes the solve
repeat without the boards (or, with several cameras, the pose) it names. A
fit that stays implausible is never written, not even with --keep. Corners
files in CRLF/CR line endings or UTF-8/16 with a byte-order mark are read as
text and mrcal gets the normalised copy (OUTDIR/candidates/corners.vnl).

Several cameras (a dataset of SEQ/poseNNN/camera-K/ folders, doc/dataset.md):
all cameras are calibrated at once (one glob per camera, a focal seed per
camera, the lean model unless --lensmodel), and mrcal's
OUTDIR/camera-0.cameramodel, camera-1.cameramodel, ... hold each camera's
intrinsics and extrinsics (camera 0 at the origin); the report gives each
camera's residuals, outliers and where it is relative to camera 0. A camera
with more than {100 * checks.MAX_OUTLIER_FRACTION:.0f}% outliers, or a board mrcal mostly rejects (labelled
differently than in the other cameras), fails the checks.

A screen's cover glass (0.5-1.5 mm over the pixels of tablets and phones)
bends every ray by an amount that changes with the viewing angle, and a plain
calibration puts that into the lens model. After the fit, the glass's
thickness is estimated from the data (each corner moved to where the
unrefracted pixel would have been seen, the fit solved again, the thickness
that fits best found with its uncertainty) and the model re-solved for it is
written when the estimate is a plausible glass; an estimate beyond
{MAX_PLAUSIBLE_MM:g} mm is reported as another pose-dependent error and not applied.
--glass MM gives the thickness (0: no correction); a rig gets one thickness
for all its cameras.
"""

EPILOG = """\
examples:
  rotstar-calibrate seq/ --outdir cal/                 # detect, then calibrate (lean, splined if supported)
  rotstar-calibrate seq/ --outdir cal-opencv5/ --lensmodel opencv5 --weights   # one given model, per-corner weights
  rotstar-calibrate seq/ --corners corners.vnl         # corners from rotstar-detect (or any detector)

""" + exit_status_help("a model was written and passed its checks (or --keep)",
                       failed="the calibration ran and failed (mrcal failed, or the checks)",
                       bad="inputs that cannot give a model") + "\n"


def parse_args(argv=None):
    p = argparse.ArgumentParser(prog="rotstar-calibrate", description=DESCRIPTION, epilog=EPILOG,
                                formatter_class=HelpFormatter)
    p.add_argument("seq", help="dataset folder holding pattern.json and one folder per pose")
    p.add_argument("--corners", metavar="VNL", help="use this corners.vnl instead of detecting")
    p.add_argument("--outdir", default="cal", help="where the model (camera-0.cameramodel), calibration.json, "
                   "the candidates' fits and the detected corners.vnl go (default cal)")
    p.add_argument("--lensmodel", default="auto",
                   help=f"'auto' (default: {cal.LEAN_LENSMODEL}, and mrcal's splined model when the boards "
                        "support it), 'splined', 'opencv8', 'opencv5', ..., or any mrcal LENSMODEL_... string")
    p.add_argument("--knots-x", type=int, default=cal.DEFAULT_KNOTS_X,
                   help=f"splined model: knots across (Ny follows the aspect ratio; default {cal.DEFAULT_KNOTS_X})")
    p.add_argument("--focal", type=float, help="focal seed in pixels (default: estimated from the boards)")
    p.add_argument("--imagersize", type=int, nargs=2, metavar=("W", "H"),
                   help="imager size (default: read from the images)")
    p.add_argument("--weights", action="store_true",
                   help="detect with per-corner weights (rotstar-detect --weights); a --corners file "
                        "with a weight column is used with weights anyway")
    p.add_argument("--refine", choices=("psf-sim", "symmetric", "opencv", "saddle"), default="psf-sim",
                   help="refinement for the detection (rotstar-detect --refine; default psf-sim, the symmetric "
                        "fit less its offset under the lens's coma)")
    p.add_argument("--jobs", "-j", type=int, default=1, help="poses detected in parallel (default 1)")
    p.add_argument("--glass", type=number_arg(float, 0, 5), default=None, metavar="MM",
                   help="the screen's cover glass over its pixels, mm (0-5): the calibration is corrected for it "
                        "(0: no correction); default: its thickness estimated from the data, with its uncertainty, "
                        f"and applied when it is a plausible glass (over 0 by {MIN_SIGMAS:g} sigma, at most "
                        f"{MAX_PLAUSIBLE_MM:g} mm)")
    p.add_argument("--glass-index", type=number_arg(float, 1), default=DEFAULT_INDEX, metavar="N",
                   help=f"refractive index of the cover glass (>= 1; default {DEFAULT_INDEX})")
    p.add_argument("--keep", action="store_true", help="write the model even when its checks fail (exit 0)")
    p.add_argument("--force", action="store_true",
                   help="calibrate inputs the checks refuse (a splined model on few boards, a disputed focal seed)")
    p.add_argument("--dry-run", action="store_true", help="print the first mrcal command, do not run it")
    return p.parse_args(argv)


def detect_corners(a) -> tuple[str | None, int]:
    """OUTDIR/corners.vnl, the corners rotstar-detect writes, detected in this process: (vnl, 0);
    (None, 1) for too few boards (none; fewer than 2 in a camera of a rig), (None, 2) for a dataset that
    cannot be read. The one place rotstar-calibrate detects, for one camera and for a rig alike.
    """
    vnl = os.path.join(a.outdir, "corners.vnl")
    say("$ " + cal.command_line(["rotstar-detect", a.seq, "-o", vnl, "--jobs", str(a.jobs), "--refine", a.refine]
                                + ["--weights"] * a.weights) + "    # (run here, in this process)")
    step = (lambda r: say(f"{r.pose}: " + (f"{r.corners.n_valid} corners" if r.found else f"skipped: {r.error}")))
    try:
        ds = dataset.open_dataset(a.seq)
        multi = len(ds.cameras) > 1
        det = detect_dataset(ds, refine=REFINERS[a.refine], jobs=a.jobs, progress=step)
    except dataset.DatasetError as e:
        say(f"rotstar-calibrate: {e}")
        return None, 2
    if not det.results():
        say(f"rotstar-calibrate: {a.seq}: no pose folders with frames from pattern.json")
        return None, 2
    if REFINERS[a.refine].pools:  # psf-sim: what it measured and how far it moved the corners
        from rotstar_mrcal.cli.detect import pooled_line

        for k, d in det.cameras.items():
            say(f"rotstar-calibrate: {dataset.camera_folder(k) + ': ' if multi else ''}{pooled_line(a.refine, d)}")
    with atomic_write(vnl) as f:
        sparse = {s.file for s in write_corners(f, det.boards(), det.weights() if a.weights else None)}
    boards = [f for f, grid in det.boards() if grid is not None and f not in sparse]
    per_camera = [sum(rig.camera_of(f) == k for f in boards) for k in {rig.camera_of(f) for f in boards}]
    say(f"rotstar-calibrate: {len(boards)} boards detected into {vnl}")
    return (vnl, 0) if per_camera and min(per_camera) >= (2 if multi else 1) else (None, 1)


def remove_results(outdir: str) -> None:
    """A failed run leaves no old result behind: OUTDIR's camera-K.cameramodel and calibration.json go"""
    for fn in glob.glob(os.path.join(outdir, "camera-*.cameramodel")) + [os.path.join(outdir, "calibration.json")]:
        if os.path.exists(fn):
            os.remove(fn)


def calibrate(a, vnl: str, layout):
    """The calibration of the corners in vnl, one camera's or a rig's; None after printing a --dry-run's command"""
    log = lambda s: say(s if s.startswith("$ ") else f"rotstar-calibrate: {s}")  # noqa: E731
    if dataset.is_multi_camera(a.seq):
        rs = rig.load_rig_corners(vnl, a.seq, a.imagersize)
        if a.dry_run:
            return say("$ " + cal.command_line(rig.first_argv(rs, a.outdir, a.lensmodel, a.focal)))
        return rig.calibrate_rig(rs, a.outdir, a.lensmodel, a.focal, keep=a.keep, log=log, glass_mm=a.glass,
                                 glass_index=a.glass_index)
    cs = load_corner_set(vnl, imagersize=a.imagersize, truth=False, layout=layout)
    if a.dry_run:
        return say("$ " + cal.command_line(cal.first_argv(cs, a.outdir, a.lensmodel, a.focal, a.knots_x, a.force)))
    return cal.calibrate(cs, a.outdir, a.lensmodel, a.focal, a.knots_x, keep=a.keep, force=a.force, log=log,
                         glass_mm=a.glass, glass_index=a.glass_index)


def main(argv=None) -> int:
    return run("rotstar-calibrate", _main, argv)


def _main(argv=None) -> int:
    a = parse_args(argv)
    try:
        _, layout = dataset.read_pattern(a.seq)
    except dataset.DatasetError as e:
        say(f"rotstar-calibrate: {e}")
        return 2
    if a.corners and not os.path.exists(a.corners):
        say(f"rotstar-calibrate: {a.corners}: no such file")
        return 2
    make_folder(a.outdir)
    remove_results(a.outdir)
    few, unkept = (("gave too few boards", "no models written; --keep writes them anyway")
                   if dataset.is_multi_camera(a.seq) else ("found no board", "no model written; --keep writes it anyway"))
    vnl, rc = (a.corners, 0) if a.corners else detect_corners(a)
    if vnl is None:
        say("rotstar-calibrate: detection " + (f"{few}; nothing to calibrate" if rc == 1 else "failed"))
        return rc
    try:
        c = calibrate(a, vnl, layout)
    except (SourceError, cal.InputError, dataset.DatasetError) as e:
        say(f"rotstar-calibrate: {e}")
        return 2
    except cal.CalibrationError as e:
        say(f"rotstar-calibrate: {e}")
        return 1
    if c is None:
        return 0
    report(c, a.outdir, unkept)
    for path in c.paths:
        print(path)
    return 0 if c.paths else 1


def report(c, outdir: str, unkept: str) -> None:
    """A calibration's summary lines and failures (stderr) and its calibration.json in outdir"""
    for line in c.summary_lines():
        say(f"rotstar-calibrate: {line}")
    with atomic_write(os.path.join(outdir, "calibration.json")) as f:
        json.dump(c.to_json(), f, indent=1)
        f.write("\n")
    if c.failures:
        say(f"rotstar-calibrate: {'kept despite: ' if c.kept else 'FAILED: '}" + "; ".join(c.failures)
            + ("" if c.kept else f" ({unkept})"))


if __name__ == "__main__":
    sys.exit(main())

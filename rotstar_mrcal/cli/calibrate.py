"""rotstar-calibrate: a recorded dataset (or its corners.vnl) in, an mrcal camera model out"""

from __future__ import annotations

import argparse
import os
import sys


from .. import dataset
from ..focal import estimate_focal
from ..validate import calibrate as cal
from ..validate.sources import CornerSet, SourceError, load_corner_set
from .common import say

DESCRIPTION = """\
Calibrate a camera from a rotating-star dataset with mrcal: detect the
corners (rotstar-detect; or take --corners corners.vnl), then run
mrcal-calibrate-cameras with the board geometry from pattern.json, the
imager size from the images and a focal seed from the boards. Every command
is printed (stderr) before it runs; the model's path goes to stdout.

The lens model defaults to mrcal's recommendation: a splined stereographic
model of order 3 with Nx x Ny knots matched to the imager's aspect ratio and
a field of view from the focal seed. It needs boards all over the imager
(mrcal's dances have ~100 views); for a few poses use --lensmodel opencv8.
"""

EPILOG = """\
examples:
  rotstar-calibrate seq/ --outdir cal/                 # detect, then calibrate (splined)
  rotstar-calibrate seq/ --lensmodel opencv8 --weights # OPENCV8, per-corner weights
  rotstar-calibrate seq/ --corners corners.vnl         # corners from rotstar-detect (or any detector)
"""


def parse_args(argv=None):
    p = argparse.ArgumentParser(prog="rotstar-calibrate", description=DESCRIPTION, epilog=EPILOG,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("seq", help="dataset folder holding pattern.json and one folder per pose")
    p.add_argument("--corners", metavar="VNL", help="use this corners.vnl instead of detecting")
    p.add_argument("--outdir", default="cal", help="where the model (camera-0.cameramodel) and the "
                   "detected corners.vnl go (default cal)")
    p.add_argument("--lensmodel", default="splined",
                   help="'splined' (default: mrcal's recommended LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_...), "
                        "'opencv8', or any mrcal LENSMODEL_... string")
    p.add_argument("--knots-x", type=int, default=cal.DEFAULT_KNOTS_X,
                   help=f"splined model: knots across (Ny follows the aspect ratio; default {cal.DEFAULT_KNOTS_X})")
    p.add_argument("--focal", type=float, help="focal seed in pixels (default: estimated from the boards)")
    p.add_argument("--imagersize", type=int, nargs=2, metavar=("W", "H"),
                   help="imager size (default: read from the images)")
    p.add_argument("--weights", action="store_true",
                   help="detect with per-corner weights (rotstar-detect --weights); a --corners file "
                        "with a weight column is used with weights anyway")
    p.add_argument("--refine", choices=("symmetric", "opencv", "saddle"), default="symmetric",
                   help="refinement for the detection (rotstar-detect --refine; default symmetric)")
    p.add_argument("--jobs", "-j", type=int, default=1, help="poses detected in parallel (default 1)")
    p.add_argument("--dry-run", action="store_true", help="print the mrcal command, do not run it")
    return p.parse_args(argv)


def resolve_lensmodel(spec: str, imagersize, focal: float, knots_x: int = cal.DEFAULT_KNOTS_X) -> str:
    """'splined' / 'opencv8' / LENSMODEL_... -> the lens model string"""
    s = spec.strip()
    if s.lower() == "splined":
        return cal.recommended_lensmodel(imagersize, focal, knots_x)
    if s.lower() in ("opencv8", "opencv4", "opencv5", "opencv12", "pinhole", "stereographic"):
        return "LENSMODEL_" + s.upper()
    if not s.startswith("LENSMODEL_"):
        raise ValueError(f"--lensmodel {spec!r}: use 'splined', 'opencv8' or an mrcal LENSMODEL_... string")
    return s


def focal_seed(cs: CornerSet) -> float:
    """estimate_focal over the boards of a corner set"""
    return estimate_focal(list(cs.corners), cs.layout.board_points()[..., :2], cs.imagersize)


def calibration_argv(cs: CornerSet, outdir: str, lensmodel: str, focal: float | None = None) -> list[str]:
    """The mrcal-calibrate-cameras command for a corner set"""
    focal = focal_seed(cs) if focal is None else focal
    return cal.calibrate_argv(cs.vnl, cs.layout, cs.imagersize, focal, lensmodel, outdir,
                              cal.image_glob(cs.files), weights=cs.weights)


def summary_line(stats: dict) -> str:
    return (f"{stats['boards']} boards, {stats['points']} corners, fit RMS {stats['rms_px']:.4f} px "
            f"(2-D, unweighted), worst {stats['max_px']:.3f} px")


def main(argv=None) -> int:
    a = parse_args(argv)
    try:
        _, layout = dataset.read_pattern(a.seq)
    except dataset.DatasetError as e:
        say(f"rotstar-calibrate: {e}")
        return 2
    os.makedirs(a.outdir, exist_ok=True)
    vnl = a.corners
    if vnl is None:
        from .detect import main as detect_main

        vnl = os.path.join(a.outdir, "corners.vnl")
        dargs = [a.seq, "-o", vnl, "--jobs", str(a.jobs), "--refine", a.refine] + (["--weights"] if a.weights else [])
        say("$ " + cal.command_line(["rotstar-detect"] + dargs))
        rc = detect_main(dargs + ["--no-hint"])
        if rc != 0:
            say("rotstar-calibrate: detection found no board; nothing to calibrate")
            return 1
    try:
        cs = load_corner_set(vnl, pattern=a.seq, imagersize=a.imagersize, truth=False)
        focal = a.focal or focal_seed(cs)
        lensmodel = resolve_lensmodel(a.lensmodel, cs.imagersize, focal, a.knots_x)
    except (SourceError, ValueError) as e:
        say(f"rotstar-calibrate: {e}")
        return 2
    if "SPLINED" in lensmodel and len(cs.files) < cal.SPLINED_MIN_BOARDS:
        say(f"rotstar-calibrate: warning: {len(cs.files)} boards for a splined model; it needs boards over "
            f"the whole imager (>= ~{cal.SPLINED_MIN_BOARDS}); consider --lensmodel opencv8")
    cmd = calibration_argv(cs, a.outdir, lensmodel, focal)
    say("$ " + cal.command_line(cmd))
    if a.dry_run:
        return 0
    try:
        model = cal.run_calibration(cmd)
    except cal.CalibrationError as e:
        say(f"rotstar-calibrate: {e}")
        return 1
    stats = cal.calibration_stats(model)
    say(f"rotstar-calibrate: {summary_line(stats)}")
    lens, intr = model.intrinsics()
    say(f"rotstar-calibrate: {lens}, fx fy cx cy = {' '.join(f'{v:.2f}' for v in intr[:4])}")
    print(os.path.join(a.outdir, "camera-0.cameramodel"))
    return 0


if __name__ == "__main__":
    sys.exit(main())

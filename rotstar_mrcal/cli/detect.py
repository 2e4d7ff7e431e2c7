"""rotstar-detect: a recorded rotating-star dataset in, mrcal corners.vnl out"""

from __future__ import annotations

import argparse
import os
import shlex
import sys

from .. import dataset
from ..detect.pipeline import REFINERS
from ..detect.run import detect_dataset
from ..focal import estimate_focal
from ..vnl import write_corners
from .common import Progress, say

DESCRIPTION = """\
Detect the corners of every pose of a recorded rotating-star dataset and write
them as mrcal's corners.vnl (to stdout, or -o FILE). Progress, the poses that
failed and why, and the mrcal-calibrate-cameras command to run next go to
stderr.

Dataset layout: SEQ/pattern.json (as written by rotstar-pattern) and one
folder per pose, SEQ/<pose>/<file> for every frame in pattern.json (8- or
16-bit grayscale PNG). Poses are processed in sorted order; the filename
column of the output is SEQ/<pose>/<first rotating-star frame>.

Exit status: 0 when at least one pose gave a board, 1 when none did, 2 for
a dataset that cannot be read at all.
"""

EPILOG = """\
example:
  rotstar-detect seq/ > corners.vnl
  mrcal-calibrate-cameras --corners-cache corners.vnl ...   (printed on stderr)
"""


def parse_args(argv=None):
    p = argparse.ArgumentParser(prog="rotstar-detect", description=DESCRIPTION, epilog=EPILOG,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("seq", help="dataset folder holding pattern.json and one folder per pose")
    p.add_argument("-o", "--output", help="write corners.vnl here instead of stdout")
    p.add_argument("--window", type=float, default=10.0,
                   help="refinement half-window w in camera pixels (default 10); capped per corner "
                        "so the window stays inside its element")
    p.add_argument("--refine", choices=REFINERS, default="symmetric",
                   help="symmetric: the paper's Eq. 1 on all rotating-star frames (default); "
                        "opencv: cv2.cornerSubPix on the checkerboard frame; "
                        "saddle: Lucchese-Mitra saddle fit on the checkerboard frame")
    p.add_argument("--weights", action="store_true",
                   help="write a weight column (1/sigma of each corner, normalised to median 1) "
                        "for mrcal's --corners-cache-has-weights")
    p.add_argument("--max-motion", type=float, default=0.15,
                   help="reject a pose whose frames disagree by more than this many pixels "
                        "(the camera moved during the sequence; default 0.15)")
    p.add_argument("--jobs", "-j", type=int, default=1, help="poses processed in parallel (default 1)")
    p.add_argument("--no-hint", action="store_true", help=argparse.SUPPRESS)  # rotstar-calibrate runs its own
    p.add_argument("--quiet", "-q", action="store_true", help="no progress lines (skipped poses are still reported)")
    return p.parse_args(argv)


def mrcal_command(layout, imagersize, focal, vnl_name, glob) -> str:
    return " ".join([
        "mrcal-calibrate-cameras",
        "--corners-cache", shlex.quote(vnl_name),
        "--lensmodel", "LENSMODEL_OPENCV8",
        "--focal", f"{focal:.0f}",
        "--imagersize", str(imagersize[0]), str(imagersize[1]),
        *layout.mrcal_object_args(),
        "--outdir", ".",
        shlex.quote(glob),
    ])


def main(argv=None) -> int:
    a = parse_args(argv)
    progress = None

    def report(r):
        if r.found:
            progress.step(r.pose, f"{r.corners.n_valid} of {layout.nx * layout.ny} corners")
        else:
            progress.step(r.pose, f"skipped: {r.error}", important=True)

    try:
        _, layout = dataset.read_pattern(a.seq)
        poses = dataset.list_poses(a.seq, _["frames"])
        if not poses:
            raise dataset.DatasetError(f"{a.seq}: no pose folders with frames from pattern.json")
        progress = Progress(len(poses), a.quiet)
        det = detect_dataset(a.seq, window=a.window, refine=a.refine, max_motion=a.max_motion, jobs=a.jobs,
                             poses=poses, progress=report)
    except dataset.DatasetError as e:
        say(f"rotstar-detect: {e}")
        return 2
    for r in det.rejected:
        say(f"{r.pose}: skipped: {r.error}")
    if a.refine == "symmetric":
        say(f"rotstar-detect: {det.display.summary()}")
    boards = det.boards()
    out = open(a.output, "w") if a.output else sys.stdout
    try:
        write_corners(out, boards, det.weights() if a.weights else None)
    finally:
        if a.output:
            out.close()
    found = [r.corners.corners for r in det.found]
    say(f"rotstar-detect: {len(found)} of {len(det.results)} poses gave a board")
    if not found:
        return 1
    sizes = det.sizes
    if len(sizes) > 1:
        say(f"rotstar-detect: warning: poses have different image sizes {sizes}")
    imagersize = sizes[0]
    focal = estimate_focal(found, layout.board_points()[..., :2], imagersize)
    first_frame = next(f["file"] for f in det.pattern["frames"] if f["kind"] == "rotstar")
    glob = os.path.join(a.seq, "*", first_frame)
    cmd = mrcal_command(layout, imagersize, focal, a.output or "corners.vnl", glob)
    if a.weights:
        cmd = cmd.replace("--corners-cache ", "--corners-cache-has-weights --corners-cache ", 1)
    if not a.no_hint:
        say("next, calibrate with:\n  " + cmd)
    return 0


if __name__ == "__main__":
    sys.exit(main())

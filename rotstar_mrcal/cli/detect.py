"""rotstar-detect: a recorded rotating-star dataset in, mrcal corners.vnl out"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import os
import sys


from .. import dataset
from ..detect.pipeline import REFINERS, detect_pose
from ..focal import estimate_focal
from ..vnl import mrcal_can_read, write_corners
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


def _detect_one(seq, pose, frames, layout, opts):
    """Worker: returns (pose, first file, PoseCorners or None, message, imagersize)"""
    if not mrcal_can_read(os.path.join(seq, pose)):
        return pose, None, None, (f"{os.path.join(seq, pose)}: mrcal cannot read file names with whitespace "
                                  "or non-ASCII characters; rename the folder (left out of the output)"), None
    try:
        p = dataset.load_pose(seq, pose, frames)
    except dataset.DatasetError as e:
        return pose, None, None, str(e), None
    r = detect_pose(p.rotstar, layout, full_scale=p.full_scale, checkerboard=p.checkerboard,
                    window=opts["window"], refine=opts["refine"], max_motion=opts["max_motion"])
    size = (p.rotstar.shape[2], p.rotstar.shape[1])
    return pose, p.first_file, r, r.error, size


def mrcal_command(layout, imagersize, focal, vnl_name, glob, weights=False) -> str:
    """The mrcal-calibrate-cameras command to run next: rotstar-calibrate's lean model, one builder"""
    from ..validate.calibrate import hint_command

    return hint_command(layout, imagersize, focal, vnl_name, glob, weights)


def corners_name(output) -> tuple[str, bool]:
    """(the corners file to name in the hint, whether it is the real one): -o, or the file stdout goes to"""
    if output:
        return output, True
    try:
        import stat

        if stat.S_ISREG(os.fstat(sys.stdout.fileno()).st_mode):
            path = os.readlink(f"/proc/self/fd/{sys.stdout.fileno()}")
            rel = os.path.relpath(path)
            return (rel if not rel.startswith("..") else path), True
    except (OSError, ValueError):
        pass
    return "corners.vnl", False


def main(argv=None) -> int:
    a = parse_args(argv)
    try:
        pattern, layout = dataset.read_pattern(a.seq)
        frames = pattern["frames"]
        poses = dataset.list_poses(a.seq, frames)
    except dataset.DatasetError as e:
        say(f"rotstar-detect: {e}")
        return 2
    if not poses:
        say(f"rotstar-detect: {a.seq}: no pose folders with frames from pattern.json")
        return 2
    opts = dict(window=a.window, refine=a.refine, max_motion=a.max_motion)
    progress = Progress(len(poses), a.quiet)
    results = {}

    def report(res):
        pose, _, r, msg, _ = res
        results[pose] = res
        if r is not None and r.found:
            extra = f", {r.motion_px:.3f} px frame motion" if r.motion_px else ""
            progress.step(pose, f"{r.n_valid} of {layout.nx * layout.ny} corners{extra}")
        else:
            progress.step(pose, f"skipped: {msg}", important=True)

    if a.jobs > 1 and len(poses) > 1:
        with cf.ProcessPoolExecutor(max_workers=a.jobs) as ex:
            futs = [ex.submit(_detect_one, a.seq, p, frames, layout, opts) for p in poses]
            for f in cf.as_completed(futs):
                report(f.result())
    else:
        for p in poses:
            report(_detect_one(a.seq, p, frames, layout, opts))

    boards, weights, found, sizes = [], [], [], set()
    first_frame = next(f["file"] for f in frames if f["kind"] == "rotstar")
    for pose in poses:
        _, fn, r, msg, size = results[pose]
        fn = fn or os.path.join(a.seq, pose, first_frame)
        if not mrcal_can_read(fn):
            continue  # reported above; mrcal could not parse the row
        if r is not None and r.found:
            boards.append((fn, r.corners))
            weights.append(r.weights())
            found.append(r.corners)
            sizes.add(size)
        else:
            boards.append((fn, None))
            weights.append(None)
    out = open(a.output, "w") if a.output else sys.stdout
    try:
        write_corners(out, boards, weights if a.weights else None)
    finally:
        if a.output:
            out.close()
    say(f"rotstar-detect: {len(found)} of {len(poses)} poses gave a board")
    if not found:
        return 1
    if len(sizes) > 1:
        say(f"rotstar-detect: warning: poses have different image sizes {sorted(sizes)}")
    imagersize = sorted(sizes)[0]
    focal = estimate_focal(found, layout.board_points()[..., :2], imagersize)
    glob = os.path.join(a.seq, "*", first_frame)
    vnl_name, real = corners_name(a.output)
    cmd = mrcal_command(layout, imagersize, focal, vnl_name, glob, a.weights)
    if not a.no_hint:
        if not real:
            say("rotstar-detect: stdout is not a file: save the corners (rotstar-detect ... > corners.vnl, or -o) "
                "and put that file's name for corners.vnl below")
        say("next, calibrate with:\n  " + cmd)
    return 0


if __name__ == "__main__":
    sys.exit(main())

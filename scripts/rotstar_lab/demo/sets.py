"""The demo's corner sets and truth on disk, per exposure and group; mrgingham over all square boards

SYNOPSIS

    vnls = write_group(edir, "A", layout, model, rts, corners_by_method, square, rts_square)
    vnls["saddle"]               # edir/A/saddle.vnl, one of the --set files of rotstar-crossval
    mrg = program_sets(out, {"A": 9, "B": 9}, "mrgingham")    # {(exposure, group): vnl}

edir/<group>/ gets pattern.json, truth.json, truth.cameramodel and one
<method>.vnl per method (and charuco.vnl, OpenCV's ChArUco detector on the
ChArUco board whose corners are the grid's: its images are poseNNN/charuco.png,
not written); edir/<group>-square/ the same truth for the square board (whose
images capture.capture_pose wrote), where the square-board methods' sets go.
"""

from __future__ import annotations

import os
import time

from rotstar_mrcal.peers.registry import METHODS
from rotstar_lab.demo.scene import EXPOSURES, SQUARE_N, exposure_dir
from rotstar_mrcal.peers.checkerboard import mrgingham_detect
from rotstar_mrcal.vnl import write_corners
from rotstar_mrcal.simulate.dataset import Truth, write_truth
from rotstar_mrcal import dataset, simulate

# the image a method's corners of one pose are written against, by what it needs
FIRST_FILE = {"rotstar": "rotstar_00.png", "checkerboard": "checkerboard.png", "phase": "phase_x_0.png",
              "star": "star.png"}


def write_group(edir, group, layout, model, rts, corners_by_method, square, rts_square) -> dict[str, str]:
    """edir/<group>/: pattern.json, truth.*, <method>.vnl; edir/<group>-square/: the same truth; {method: vnl}

    corners_by_method: {method: per pose (corners or None, weights or None)}.
    """
    for name, lay, poses in ((group, layout, rts), (f"{group}-square", square, rts_square)):
        seq = os.path.join(edir, name)
        os.makedirs(seq, exist_ok=True)
        dataset.write_pattern(seq, lay)
        model.write(os.path.join(seq, "truth.cameramodel"))
        names = simulate.pose_names(len(poses))
        write_truth(seq, Truth(model, lay, dict(zip(names, poses)),
                               {n: simulate.true_corners(model, lay, r) for n, r in zip(names, poses)},
                               {"camera": "d435", "psf": "demo coma (rotstar_lab.demo.scene)"}))
    vnls = {}
    seq = os.path.join(edir, group)
    for m, per_pose in corners_by_method.items():
        first = "charuco.png" if m == "charuco" else FIRST_FILE[METHODS[m].needs]
        boards = [(f"pose{i:03d}/{first}", c) for i, (c, w) in enumerate(per_pose)]
        weights = [w for c, w in per_pose] if m in METHODS and METHODS[m].variant_of else None
        vnls[m] = os.path.join(seq, f"{m}.vnl")
        with open(vnls[m], "w") as f:
            write_corners(f, boards, weights)
    return vnls


def program_sets(out: str, npose: dict[str, int], name: str = "mrgingham", log=None) -> dict[tuple, str]:
    """Run a square-board program method once over every square-board image; write <exposure>/<g>-square/<name>.vnl"""
    paths = {}
    for label, _ in EXPOSURES:
        for g, n in npose.items():
            for i in range(n):
                paths[(label, g, i)] = os.path.join(exposure_dir(out, label), f"{g}-square", f"pose{i:03d}",
                                                    "checkerboard.png")
    jobs = os.cpu_count() or 1
    args = METHODS[name].args
    if log:
        log(f"$ mrgingham --jobs {jobs} --gridn {SQUARE_N} {' '.join(args) + ' ' if args else ''}"
            f"<{len(paths)} square-board images>")
    t = time.monotonic()
    found = mrgingham_detect(list(paths.values()), SQUARE_N, jobs=jobs, extra_args=args)
    if log:
        log(f"  ({time.monotonic() - t:.0f} s, {sum(v is not None for v in found.values())} of {len(found)} boards)")
    vnls = {}
    for label, _ in EXPOSURES:
        for g, n in npose.items():
            fn = os.path.join(exposure_dir(out, label), f"{g}-square", f"{name}.vnl")
            with open(fn, "w") as f:
                write_corners(f, [(f"pose{i:03d}/checkerboard.png", found[paths[(label, g, i)]]) for i in range(n)])
            vnls[(label, g)] = fn
    return vnls

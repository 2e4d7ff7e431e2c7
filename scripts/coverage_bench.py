#!/usr/bin/env python3
"""make coverage-bench: whole boards only against boards hanging over the imager's edges (issue 13)

    python scripts/coverage_bench.py [--poses 20] [--hanging 8] [--seed 0] [--work coverage-bench-out]
                                     [--jobs 2] [--lensmodel LENSMODEL_OPENCV8] [--doc]
    python scripts/coverage_bench.py --corners truth+noise     # checks the machinery only, in seconds

Simulates both captures on the D435 preset, detects them with rotstar,
calibrates each with mrcal (one lens model for both) and measures mrcal's
projection uncertainty and the error against the true camera at the imager's
corners, over its outer 10 % and in the centre
(rotstar_mrcal.benchmark.coverage). Prints the table and the verdict (is the
uncertainty at every imager corner at least 2x lower with hanging boards?);
writes results.json and coverage.png into --work. With --doc also writes the
table into doc/uncertainty.md (between its coverage-bench markers) and the
figure to doc/img/coverage/coverage.png: only from rotstar's detection, and
only when the detection gave boards for most of the hanging poses. Exit 1
when --doc is refused.
"""

import argparse
import json
import os
import shutil
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from rotstar_mrcal.benchmark.coverage import figure, run, table, verdict  # noqa: E402
from rotstar_mrcal.docblock import rewrite_block  # noqa: E402

MIN_HANGING_USED = 0.75
"""--doc needs boards from at least this fraction of the hanging poses"""


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--poses", type=int, default=20)
    p.add_argument("--hanging", type=int, default=8, help="poses of the second capture hanging over an edge (default 8)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--work", default="coverage-bench-out")
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--lensmodel", default="LENSMODEL_OPENCV8")
    p.add_argument("--corners", choices=("detect", "truth+noise"), default="detect",
                   help="detect: rotstar's detection (default); truth+noise: checks the machinery only")
    p.add_argument("--doc", action="store_true", help="write the table and the figure into doc/")
    a = p.parse_args()
    t0 = time.time()
    r = run(a.work, a.poses, a.hanging, a.seed, a.corners, lensmodel=a.lensmodel, jobs=a.jobs,
            log=lambda s: print(s, file=sys.stderr, flush=True))
    with open(os.path.join(a.work, "results.json"), "w") as f:
        json.dump(r.to_json(), f, indent=1)
    fig = figure(r, os.path.join(a.work, "coverage.png"))
    ok, line = verdict(r)
    e = r.captures["edges"]
    text = (table(r) + f"\n\n{line}.\n\n*Written by `make coverage-bench` (scripts/coverage_bench.py, seed {a.seed}, "
            f"{time.time() - t0:.0f} s): {a.poses} poses each, the second capture with {a.hanging} of them hanging "
            "over the imager's corners and edges; ratio = whole / with edges.*")
    print(text)
    if not a.doc:
        return 0
    if r.corners != "detect":
        print("coverage-bench: --doc refused: truth+noise corners check the machinery, they are no result",
              file=sys.stderr)
        return 1
    if e.hanging_used < MIN_HANGING_USED * e.hanging:
        print(f"coverage-bench: --doc refused: rotstar's detection gave mrcal boards for {e.hanging_used} of the "
              f"{e.hanging} hanging poses (boards partly out of view); the numbers wait for the partial-board "
              "detection", file=sys.stderr)
        return 1
    root = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
    if rewrite_block(os.path.join(root, "doc", "uncertainty.md"), "coverage-bench", text):
        print(f"wrote {os.path.join(root, 'doc', 'uncertainty.md')}", file=sys.stderr)
    os.makedirs(os.path.join(root, "doc", "img", "coverage"), exist_ok=True)
    shutil.copyfile(fig, os.path.join(root, "doc", "img", "coverage", "coverage.png"))
    return 0


if __name__ == "__main__":
    sys.exit(main())

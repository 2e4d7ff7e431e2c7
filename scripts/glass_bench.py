#!/usr/bin/env python3
"""make glass-bench: a screen's cover glass, plain calibration vs rotstar-calibrate's correction (issue 22)

    python scripts/glass_bench.py [--poses 20 40] [--glass 0 0.5 1.0 1.5] [--seed 0] [--work glass-bench-out] [--doc]

Exact D435 corners through each glass plus 0.005 px noise, calibrated by
rotstar-calibrate's library (LENSMODEL_OPENCV8, the glass estimated), against
the true camera (rotstar_lab.benchmark.glass); one more row per number of
poses without glass through a lens whose entrance pupil moves; then the
D435's infrared pair (--rig-poses) through the same glasses. Prints the
tables; with --doc also writes it into doc/simulator.md (between its
glass-bench markers). Exit 1 when a corrected model with glass is not within
1.2x of the glass-free plain one of the same poses, or an estimate is neither
within 0.1 mm of the truth nor inside its 2 sigma, or the moving pupil's
estimate is applied.
"""

import argparse
import json
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from rotstar_lab.benchmark.glass import failures, report, rig_failures, rig_row, run  # noqa: E402
from rotstar_lab.docblock import rewrite_block  # noqa: E402


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--poses", type=int, nargs="+", default=[20, 40])
    p.add_argument("--glass", type=float, nargs="+", default=[0.0, 0.5, 1.0, 1.5])
    p.add_argument("--rig-poses", type=int, default=20, help="poses of the stereo pair (0: none)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--work", default="glass-bench-out")
    p.add_argument("--doc", action="store_true", help="rewrite the table in doc/simulator.md")
    a = p.parse_args()
    if 0.0 not in a.glass:
        p.error("--glass needs 0 among the thicknesses (the glass-free reference)")
    os.makedirs(a.work, exist_ok=True)
    t0 = time.time()
    rows = run(a.work, a.poses, a.glass, a.seed, log=lambda s: print(s, file=sys.stderr, flush=True))
    rig = [rig_row(a.rig_poses, t, a.seed) for t in a.glass] if a.rig_poses else []
    with open(os.path.join(a.work, "results.json"), "w") as f:
        json.dump({"one camera": rows, "stereo pair": rig}, f, indent=1)
    bad = failures(rows) + rig_failures(rig)
    text = report(rows, rig, a.seed, time.time() - t0, bad, "glass-bench", "scripts/glass_bench.py")
    print(text)
    if a.doc and rewrite_block(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "doc", "simulator.md"),
                               "glass-bench", text):
        print("wrote doc/simulator.md", file=sys.stderr)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env python3
"""make glass-bench: a screen's cover glass, plain calibration vs rotstar-calibrate's correction (issue 22)

    python scripts/glass_bench.py [--poses 20 40] [--glass 0 0.5 1.0 1.5] [--seed 0] [--work glass-bench-out] [--doc]

Exact D435 corners through each glass plus 0.005 px noise, calibrated by
rotstar-calibrate's library (LENSMODEL_OPENCV8, the glass estimated), against
the true camera (rotstar_lab.benchmark.glass); one more row per number of
poses without glass through a lens whose entrance pupil moves. Prints the
table; with --doc also writes it into doc/simulator.md (between its
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

from rotstar_lab.benchmark.glass import run, table  # noqa: E402
from rotstar_lab.docblock import rewrite_block  # noqa: E402

TOLERANCE = 1.2


def failures(rows) -> list[str]:
    """What the issue asks that the rows do not show"""
    free = {r["poses"]: r["plain"][0] for r in rows if r["glass_mm"] == 0 and not r["pupil_mm"]}
    out = []
    for r in rows:
        what = f"{r['poses']} poses, glass {r['glass_mm']:g} mm" + (", moving pupil" if r["pupil_mm"] else "")
        if r["pupil_mm"]:
            if r["applied"]:
                out.append(f"{what}: the estimate {r['estimate_mm']:.3f} mm was applied")
            continue
        if r["glass_mm"] and r["corrected"][0] > TOLERANCE * free[r["poses"]]:
            out.append(f"{what}: corrected {r['corrected'][0]:.4f} px > {TOLERANCE}x the glass-free "
                       f"{free[r['poses']]:.4f} px")
        e = r["estimate_mm"]
        if e is None or (abs(e - r["glass_mm"]) > 0.1 and abs(e - r["glass_mm"]) > 2 * r["sigma_mm"]):
            out.append(f"{what}: estimate {e} +- {r['sigma_mm']} mm")
    return out


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--poses", type=int, nargs="+", default=[20, 40])
    p.add_argument("--glass", type=float, nargs="+", default=[0.0, 0.5, 1.0, 1.5])
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--work", default="glass-bench-out")
    p.add_argument("--doc", action="store_true", help="rewrite the table in doc/simulator.md")
    a = p.parse_args()
    if 0.0 not in a.glass:
        p.error("--glass needs 0 among the thicknesses (the glass-free reference)")
    os.makedirs(a.work, exist_ok=True)
    t0 = time.time()
    rows = run(a.work, a.poses, a.glass, a.seed, log=lambda s: print(s, file=sys.stderr, flush=True))
    with open(os.path.join(a.work, "results.json"), "w") as f:
        json.dump(rows, f, indent=1)
    bad = failures(rows)
    text = (table(rows) + f"\n\n*Written by `make glass-bench` (scripts/glass_bench.py, seed {a.seed}, "
            f"{time.time() - t0:.0f} s): exact corners + 0.005 px noise, LENSMODEL_OPENCV8, vs the true camera "
            "over the imager at infinity; corrected / glass-free: the corrected median over the plain glass-free "
            "median of the same poses." + (" Not met: " + "; ".join(bad) if bad else "") + "*")
    print(text)
    if a.doc and rewrite_block(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "doc", "simulator.md"),
                               "glass-bench", text):
        print("wrote doc/simulator.md", file=sys.stderr)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())

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

from rotstar_lab.benchmark.glass import rig_row, rig_table, run, table  # noqa: E402
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
        if estimate_off(r):
            out.append(f"{what}: estimate {r['estimate_mm']} +- {r['sigma_mm']} mm")
    return out


def estimate_off(r: dict) -> bool:
    """The estimate neither within 0.1 mm of the truth nor inside its 2 sigma"""
    e, s = r["estimate_mm"], r["sigma_mm"]
    return e is None or (abs(e - r["glass_mm"]) > 0.1 and abs(e - r["glass_mm"]) > 2 * s)


def rig_failures(rig) -> list[str]:
    """The stereo rows' estimates off, or a glass left in"""
    return [f"stereo pair, glass {r['glass_mm']:g} mm: estimate {r['estimate_mm']} +- {r['sigma_mm']} mm"
            + ("" if r["applied"] or not r["glass_mm"] else ", not applied")
            for r in rig if estimate_off(r) or (r["glass_mm"] and not r["applied"])]


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
    text = (table(rows) + f"\n\n*Written by `make glass-bench` (scripts/glass_bench.py, seed {a.seed}, "
            f"{time.time() - t0:.0f} s): exact corners + 0.005 px noise, LENSMODEL_OPENCV8, vs the true camera "
            "over the imager at infinity; corrected / glass-free: the corrected median over the plain glass-free "
            "median of the same poses." + (" Not met: " + "; ".join(bad) if bad else "") + "*")
    if rig:
        text += ("\n\nThe D435's infrared pair, " + f"{a.rig_poses} poses, the same glass in both views (solved jointly "
                 "with mrcal.optimize from near the truth, then the correction; camera 1 against the truth):\n\n"
                 + rig_table(rig))
    print(text)
    if a.doc and rewrite_block(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "doc", "simulator.md"),
                               "glass-bench", text):
        print("wrote doc/simulator.md", file=sys.stderr)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env python3
"""rotstar-calibrate's default model against rotstar-detect's printed command, on simulated D435 captures

    python scripts/calib_bench.py [--poses 12 20 40] [--seed 0] [--work calib-bench] [--jobs 2] [--doc]

Prints the table (rotstar_mrcal.validate.modelcheck); with --doc also
writes it into doc/validation.md between its calib-bench markers. Exit 1 if a
default run is neither within 2x the better model nor refused with a reason.
"""

import argparse
import json
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from rotstar_mrcal.validate.modelcheck import rewrite_block, run_case, table  # noqa: E402


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--poses", type=int, nargs="+", default=[12, 20, 40])
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--work", default="calib-bench")
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--doc", action="store_true", help="rewrite the table in doc/validation.md")
    a = p.parse_args()
    os.makedirs(a.work, exist_ok=True)
    t0 = time.time()
    rows = [run_case(a.work, n, a.seed, a.jobs, log=lambda s: print(s, file=sys.stderr, flush=True))
            for n in a.poses]
    with open(os.path.join(a.work, "results.json"), "w") as f:
        json.dump(rows, f, indent=1)
    text = (table(rows) + f"\n\n*Written by `make calib-bench` (scripts/calib_bench.py, seed {a.seed}, "
            f"{time.time() - t0:.0f} s); median / worst: over the imager, at infinity, px.*")
    print(text)
    if a.doc:
        doc = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "doc", "validation.md")
        if rewrite_block(doc, "calib-bench", text):
            print(f"wrote {os.path.normpath(doc)}", file=sys.stderr)
    return 0 if all(r["ok"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())

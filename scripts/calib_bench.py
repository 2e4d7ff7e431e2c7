#!/usr/bin/env python3
"""rotstar-calibrate's default model against rotstar-detect's printed command, on simulated D435 captures

    python scripts/calib_bench.py [--poses 12 20 40] [--seed 0] [--work calib-bench] [--jobs 2] [--doc]

Prints the table (rotstar_lab.modelcheck); with --doc also
writes it into doc/validation.md between its calib-bench markers. Exit 1 if a
default run is neither within 2x the better model nor refused with a reason.
"""

import argparse
import json
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from rotstar_lab.docblock import rewrite_block  # noqa: E402
from rotstar_mrcal.programs import run_tool  # noqa: E402
from rotstar_lab.modelcheck import run_case, table  # noqa: E402
from rotstar_lab.uncertaintydoc import uncertainty_doc  # noqa: E402


def figures_doc(work, n, seed, docdir, jobs):
    """doc/uncertainty.md's pictures from the n-pose capture: its calibration, its two halves, its splined fit"""
    name = f"d435-{n}poses-seed{seed}"
    xval = f"{name}-xval"
    print(f"$ rotstar-crossval {name} --outdir {xval}", file=sys.stderr)
    r = run_tool([os.path.join(os.path.dirname(sys.executable), "rotstar-crossval"), name, "--outdir", xval,
                        "--jobs", str(jobs)], cwd=work, capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(r.stderr[-2000:])
    print(r.stdout, file=sys.stderr)
    cal = os.path.join(work, f"{name}-cal")
    halves = tuple(os.path.join(work, xval, "rotstar", s, "camera-0.cameramodel") for s in "AB")
    spl = os.path.join(cal, "candidates", "splined", "camera-0.cameramodel")
    names = {os.path.join(cal, "camera-0.cameramodel"): "cal/camera-0.cameramodel",
             halves[0]: "xval/rotstar/A/camera-0.cameramodel", halves[1]: "xval/rotstar/B/camera-0.cameramodel",
             spl: "cal/candidates/splined/camera-0.cameramodel"}
    uncertainty_doc(os.path.join(cal, "camera-0.cameramodel"), os.path.join(docdir, "img", "uncertainty"),
                    os.path.join(docdir, "uncertainty.md"), halves=halves,
                    splined=spl if os.path.exists(spl) else None, image_root=work, names=names)
    print(f"wrote {os.path.join(docdir, 'uncertainty.md')}", file=sys.stderr)


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
        docdir = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "doc"))
        if rewrite_block(os.path.join(docdir, "validation.md"), "calib-bench", text):
            print(f"wrote {os.path.join(docdir, 'validation.md')}", file=sys.stderr)
        figures_doc(a.work, max(a.poses), a.seed, docdir, a.jobs)
    return 0 if all(r["ok"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())

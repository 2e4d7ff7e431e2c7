#!/usr/bin/env python3
"""How much of a 10-pose comparison is the draw of the noise: the short capture of the same poses, again and again

    nice -n 10 .venv/bin/python scripts/capture_calib_repeats.py --seed 0 --repeats 3 [--hold short|30] [--work W]

The poses of `capture_calib_bench.py --poses N --seed S` (the same camera,
pattern, flaws and capture path), each captured again with other draws of
the noise and the flaws (capture seed r = 1, 2, ...; the bench's own capture
is r = 0), then detected and calibrated as the bench does: per repeat the
model's median error against the truth (px) and mrcal's uncertainty. With
--hold 30 today's capture is repeated instead. The spread over the repeats
is the error bar of one row of the bench's table.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from capture_calib_bench import LAYOUT, calibrate, capture_pose, half_d435, render, say, write_truth_of  # noqa: E402
from rotstar_mrcal import simulate  # noqa: E402
from rotstar_mrcal.capture.session import OutputDataset  # noqa: E402


def repeat(work: str, n: int, seed: int, hold, r: int) -> dict:
    """One capture of the n poses with capture seed r, calibrated: calibrate()'s summary"""
    model = half_d435()
    rts = simulate.random_poses(model, LAYOUT, n, np.random.default_rng([23, seed]))
    folder = os.path.join(work, f"r{r}")
    shutil.rmtree(folder, ignore_errors=True)
    ds = OutputDataset(folder, None)
    for k, rt in enumerate(rts):
        capture_pose(render(model, rt), hold, ds, f"pose{k:03d}", os.path.join(work, "raw"),
                     np.random.default_rng([25, seed, k, 0 if hold is None else 30, r]))
    write_truth_of(folder, model, {f"pose{k:03d}": rts[k] for k in range(n)})
    return calibrate(folder)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--poses", type=int, default=10)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--hold", default="short", help="short (pattern.loop.SHORT_HOLDS, until enough) or 30 (today's)")
    p.add_argument("--work", default="capture-calib-repeats")
    a = p.parse_args(argv)
    hold = None if a.hold == "short" else int(a.hold)
    out = []
    for r in range(1, a.repeats + 1):
        res = repeat(a.work, a.poses, a.seed, hold, r)
        say(f"seed {a.seed} hold {a.hold} repeat {r}: {json.dumps(res)}")
        out.append(res)
    med = [o.get("median_px", np.nan) for o in out]
    print(f"seed {a.seed}, hold {a.hold}, {a.repeats} repeats: median vs truth "
          + ", ".join(f"{m:.4f}" for m in med) + f" px (mean {np.nanmean(med):.4f}); mrcal's uncertainty "
          + ", ".join(f"{o.get('sigma_px', np.nan):.4f}" for o in out))
    return 0


if __name__ == "__main__":
    sys.exit(main())

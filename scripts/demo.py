#!/usr/bin/env python3
"""make demo: the whole chain on a simulated D435 infrared capture

pattern -> simulated capture (Y16 1280x800, OPENCV8 lens) -> rotstar-detect ->
mrcal-calibrate-cameras -> distance of the calibrated model from the true one.
Every step is the command a user would type; each is printed before it runs.
"""

from __future__ import annotations

import argparse
import os
import shlex
import subprocess
import sys
import time

import numpy as np


def run(cmd, **kw):
    print("$ " + " ".join(shlex.quote(c) for c in cmd), file=sys.stderr, flush=True)
    t = time.monotonic()
    r = subprocess.run(cmd, **kw)
    if r.returncode != 0:
        sys.exit(f"demo: step failed ({cmd[0]}, exit {r.returncode})")
    print(f"  ({time.monotonic() - t:.1f} s)", file=sys.stderr, flush=True)
    return r


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="demo-out", help="output folder (default demo-out)")
    p.add_argument("--poses", type=int, default=24, help="simulated poses (default 24)")
    p.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="parallel processes")
    p.add_argument("--seed", type=int, default=1)
    a = p.parse_args()

    import mrcal

    from rotstar_mrcal import dataset, simulate
    from rotstar_mrcal.vnl import read_corners

    out = os.path.abspath(a.out)
    pat, seq, cal = (os.path.join(out, d) for d in ("pattern", "seq", "cal"))
    os.makedirs(out, exist_ok=True)
    t0 = time.monotonic()
    run(["rotstar-pattern", "--out", pat])
    run(["rotstar-simulate", "--out", seq, "--pattern", pat, "--camera", "d435", "--poses", str(a.poses),
         "--seed", str(a.seed), "--bits", "16", "--jobs", str(a.jobs)])
    vnl = os.path.join(out, "corners.vnl")
    with open(vnl, "w") as fh:
        r = run(["rotstar-detect", "--jobs", str(a.jobs), seq], stdout=fh, stderr=subprocess.PIPE, text=True)
    sys.stderr.write(r.stderr)
    cmd = r.stderr.split("next, calibrate with:\n", 1)[1].strip()
    cmd = shlex.split(cmd)
    cmd[cmd.index("--corners-cache") + 1] = vnl
    cmd[cmd.index("--outdir") + 1] = cal
    os.makedirs(cal, exist_ok=True)
    run(cmd, stdout=subprocess.PIPE, text=True)

    # how far is the calibration from the truth?
    _, layout = dataset.read_pattern(seq)
    truth = simulate.load_truth(seq)
    true_model = mrcal.cameramodel(os.path.join(seq, "truth.cameramodel"))
    model = mrcal.cameramodel(os.path.join(cal, "camera-0.cameramodel"))
    difflen, *_ = mrcal.projection_diff((true_model, model), gridn_width=40, use_uncertainties=False,
                                        focus_radius=min(true_model.imagersize()) * 0.4)
    with open(vnl) as fh:
        found = read_corners(fh, layout.nx, layout.ny)
    errs = []
    for name, rt in truth.rt_cam_board.items():
        fn = os.path.join(seq, name, layout.frames()[0]["file"])
        if found.get(fn) is not None:
            errs.append(np.linalg.norm(found[fn] - truth.corners[name], axis=-1).ravel())
    e = np.concatenate(errs)
    e = e[np.isfinite(e)]
    oi = model.optimization_inputs()
    res = np.linalg.norm(mrcal.measurements_board(oi), axis=-1)
    print()
    print(f"rotstar-mrcal demo: {len(errs)} of {len(truth.rt_cam_board)} poses detected, {e.size} corners")
    print(f"  corner error vs truth:      RMS {np.sqrt(np.mean(e ** 2)):.4f} px, p95 {np.percentile(e, 95):.4f}, max {e.max():.4f}")
    print(f"  mrcal residuals:            RMS {np.sqrt(np.mean(res ** 2)):.4f} px (2-D)")
    print(f"  calibrated vs true model:   projection diff median {np.median(difflen):.4f} px, "
          f"p95 {np.percentile(difflen, 95):.4f}, max {difflen.max():.4f} (over the imager, at infinity)")
    print(f"  model: {os.path.join(cal, 'camera-0.cameramodel')}   total {time.monotonic() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())

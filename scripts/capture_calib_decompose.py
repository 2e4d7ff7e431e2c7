#!/usr/bin/env python3
"""What of a capture_calib_bench calibration's error is the detector's bias and what its noise (issue 23)

    nice -n 10 .venv/bin/python scripts/capture_calib_decompose.py WORK [WORK ...]

WORK: a finished `capture_calib_bench.py --same-only --work WORK` folder
(today/ and short-same/, each with corners.vnl and the truth). Per pose the
detector's corners on the noise-free displayed frames are the bias part
(their error against the truth, the same in both captures); a capture's
corners less those are its noise. Calibrated again (rotstar-calibrate, as
the bench) from

- bias: the noise-free detections alone;
- noise: the true corners plus the capture's noise (no bias);

and compared with the truth as the bench does, with mrcal's uncertainty.
Also the noise's rms per axis and how much of it is common to a pose's corners
(the rms of its per-pose mean over what independent corners would give).
"""

from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from capture_calib_bench import LAYOUT, calibrate_corners, render, say  # noqa: E402
from capture_tail_lab import ideal_detection  # noqa: E402
from rotstar_mrcal.simulate.dataset import load_truth  # noqa: E402
from rotstar_mrcal.vnl import read_corners, write_corners  # noqa: E402


def calibrate_with(seq: str, boards: dict, tag: str) -> dict:
    """rotstar-calibrate seq on the given boards {filename: (ny, nx, 2)}; the model against the truth"""
    vnl = os.path.join(seq, f"corners-{tag}.vnl")
    with open(vnl, "w") as f:
        write_corners(f, list(boards.items()))
    r = calibrate_corners(seq, vnl, seq + f"-cal-{tag}")
    return r if "error" in r else {"median_px": r["median_px"], "sigma_px": r["sigma_px"]}


def one_work(work: str, ideal_cache: dict) -> dict:
    out = {}
    for cap in ("today", "short-same"):
        seq = os.path.join(work, cap)
        t = load_truth(seq)
        with open(os.path.join(seq, "corners.vnl")) as f:
            boards = {fn: c for fn, c in read_corners(f, LAYOUT.nx, LAYOUT.ny).items() if c is not None}
        noise, means, bias_b, noise_b = [], [], {}, {}
        for fn, c in boards.items():
            pose = os.path.basename(os.path.dirname(fn))
            key = (work, pose)
            if key not in ideal_cache:
                ideal_cache[key] = ideal_detection(render(t.model, t.rt_cam_board[pose])).corners
            ideal = ideal_cache[key]
            n = c - ideal
            ok = np.isfinite(n[..., 0])
            noise.append(n[ok])
            means.append((n[ok].mean(axis=0), ok.sum()))
            bias_b[fn] = ideal
            noise_b[fn] = t.corners[pose] + np.where(ok[..., None], n, np.nan)
        v = np.concatenate(noise)
        rms = float(np.sqrt(np.mean(v ** 2)))
        common = float(np.sqrt(np.mean([np.sum(m ** 2) / 2 * k for m, k in means])) / rms)
        out[cap] = {"noise_rms_px": rms, "common_mode": common,
                    "bias": calibrate_with(seq, bias_b, "bias"), "noise": calibrate_with(seq, noise_b, "noise")}
        with open(os.path.join(work, "results.json")) as f:
            res = json.load(f)
        key = "today" if cap == "today" else "short-same"
        out[cap]["as_detected"] = {q: res[key][q] for q in ("median_px", "sigma_px") if q in res[key]}
        say(f"{work} {cap}: {out[cap]}")
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("work", nargs="+", help="capture_calib_bench.py --same-only --work folders")
    works = p.parse_args(argv).work
    cache: dict = {}
    rows = []
    for w in works:
        if not os.path.isdir(os.path.join(w, "short-same")):
            print(f"capture_calib_decompose.py: {w}: not a capture_calib_bench --same-only work folder",
                  file=sys.stderr)
            return 2
        r = one_work(w, cache)
        rows.append((w, r))
    print("| work | capture | noise rms px (common-mode x) | as detected: vs truth (uncertainty) | bias only | "
          "noise only: vs truth (uncertainty) |")
    print("|---|---|---|---|---|---|")
    for w, r in rows:
        for cap, s in r.items():
            a, b, n = s["as_detected"], s["bias"], s["noise"]
            print(f"| {os.path.basename(w)} | {cap} | {s['noise_rms_px']:.4f} ({s['common_mode']:.2f}) | "
                  f"{a.get('median_px', np.nan):.4f} ({a.get('sigma_px', np.nan):.4f}) | "
                  f"{b.get('median_px', np.nan):.4f} | "
                  f"{n.get('median_px', np.nan):.4f} ({n.get('sigma_px', np.nan):.4f}) |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

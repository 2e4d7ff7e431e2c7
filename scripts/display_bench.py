#!/usr/bin/env python3
"""Per-frame display maps like a real monitor's: what the detector keeps, skips and calibrates (issue 22)

    nice -n 10 python scripts/display_bench.py [--poses 12] [--seed 0] [--jobs 2] [--work display-bench]
                                               [--no-calibrate] [--reuse]

Renders the same simulated D435 poses twice, on a clean display and on one
that shows the eight rotating-star frames as measured on recordings of a
monitor (doc/detector.md): shifted 0, 0, +2, +1, +1, -1, +1, +1 display px
along v, the fourth (turned 3 pi/16) 640 ppm taller with its bottom in
place, the same in every pose. Both get one more pose, a copy of pose 1
whose camera moved MOVE_PX image px sideways from frame 4 on. Each dataset
is detected as rotstar-detect does (detect_dataset); printed: the poses kept
and skipped (with the reason), the display maps the detector reports, the
corner error against the truth (RMS, kept poses) and, unless
--no-calibrate, mrcal (OPENCV8) on the kept boards against the true camera
(median / max over the imager, at infinity).
"""

import argparse
import math
import os
import sys
import time

import mrcal
import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from rotstar_lab.benchmark.calibration import calibrate_one  # noqa: E402
from rotstar_mrcal.dataset import open_dataset  # noqa: E402
from rotstar_mrcal.detect.run import detect_dataset  # noqa: E402
from rotstar_mrcal.pattern.layout import make_layout  # noqa: E402
from rotstar_mrcal.simulate.camera import preset_model  # noqa: E402
from rotstar_mrcal.simulate.dataset import Settings, load_truth, write_dataset  # noqa: E402
from rotstar_mrcal.simulate.display import parse_display_maps  # noqa: E402
from rotstar_mrcal.simulate.poses import random_poses  # noqa: E402

REAL_MONITOR = "2:0,2;3:0,1,0,640@bottom;4:0,1;5:0,-1;6:0,1;7:0,1"
MOVE_PX = 0.3


def moved(rt: np.ndarray, model, layout, px: float) -> np.ndarray:
    """(nframes, 6): the camera shifted sideways by about px image pixels from frame 4 on"""
    depth = mrcal.transform_point_rt(rt, layout.board_points()).reshape(-1, 3)[:, 2].mean()
    out = np.repeat(rt[None], len(layout.frames()), axis=0)
    out[4:, 3] += px * depth / model.intrinsics()[1][0]
    return out


def corner_rms(det, truth) -> float:
    e = []
    for r in det.found:
        t = truth.corners[r.pose]
        e.append(np.linalg.norm(r.corners.corners - (t.mean(axis=0) if t.ndim == 4 else t), axis=-1).ravel())
    e = np.concatenate(e)
    return float(np.sqrt(np.nanmean(e**2)))


def run(name: str, work: str, layout, model, rts, maps, args) -> dict:
    seq = os.path.join(work, name)
    t0 = time.perf_counter()
    if args.reuse and os.path.exists(os.path.join(seq, "truth.json")):
        truth = load_truth(seq)
    else:
        truth = write_dataset(seq, layout, model, rts, Settings(bits=16, seed=args.seed), jobs=args.jobs,
                              display_maps=maps, extra={"camera": "d435"})
        print(f"{name}: rendered {len(rts)} poses in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    det = detect_dataset(open_dataset(seq), jobs=args.jobs).cameras[0]
    out = {"kept": [r.pose for r in det.found], "skipped": {r.pose: r.error for r in det.results if not r.found},
           "display": det.display.summary(), "motion": det.display.motion_px, "corner_rms": corner_rms(det, truth)}
    if not args.no_calibrate:
        boards = [None] * len(rts)
        for r in det.found:
            boards[int(r.pose[4:])] = r.corners.corners
        rt_mean = [r if r.ndim == 1 else r.mean(axis=0) for r in rts]
        out["cal"] = calibrate_one(boards, None, layout, np.array(rt_mean), model, os.path.join(work, name + "-cal"))
    return out


def report(name: str, r: dict) -> None:
    print(f"== {name}")
    print(f"kept {len(r['kept'])} poses; skipped: " + ("; ".join(f"{p}: {e}" for p, e in r["skipped"].items())
                                                        or "none"))
    print("motion px per pose: " + " ".join(f"{m:.3f}" for m in r["motion"].values()))
    print(r["display"])
    print(f"corner error vs truth, RMS over kept poses: {r['corner_rms']:.4f} px")
    if "cal" in r:
        c = r["cal"]
        print("calibration vs truth: " + (c["error"] if "error" in c else
                                          f"median {c['median_px']:.4f} / max {c['max_px']:.4f} px over the imager, "
                                          f"fit RMS {c['fit_rms_px']:.4f} px, {c['boards']} boards"))


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--poses", type=int, default=12)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--work", default="display-bench")
    p.add_argument("--no-calibrate", action="store_true")
    p.add_argument("--reuse", action="store_true", help="detect the datasets already rendered in --work again")
    args = p.parse_args()
    layout, model = make_layout(), preset_model("d435")
    rts = list(random_poses(model, layout, args.poses, np.random.default_rng([0, args.seed]),
                            max_tilt_deg=60.0))
    rts.append(moved(rts[1], model, layout, MOVE_PX))
    maps = parse_display_maps(REAL_MONITOR, 8, (layout.screen_width, layout.screen_height))
    print(f"{args.poses} still poses + pose{args.poses:03d} moved {MOVE_PX} px; display maps {REAL_MONITOR!r} "
          f"on a {layout.screen_width}x{layout.screen_height} screen", file=sys.stderr)
    res = {name: run(name, args.work, layout, model, rts, m, args)
           for name, m in (("clean", None), ("real-monitor", maps))}
    for name, r in res.items():
        report(name, r)
    a, b = res["clean"].get("cal", {}), res["real-monitor"].get("cal", {})
    if "median_px" in a and "median_px" in b:
        print(f"calibration, real-monitor display / clean: median x{b['median_px'] / a['median_px']:.2f}, "
              f"max x{b['max_px'] / a['max_px']:.2f}")
    still = [f"pose{i:03d}" for i in range(args.poses)]
    ok = all(r["kept"] == still and list(r["skipped"]) == [f"pose{args.poses:03d}"] and
             "camera moved" in r["skipped"][f"pose{args.poses:03d}"] for r in res.values())
    print("every still pose kept, the moved pose alone skipped for camera motion: " + ("yes" if ok else "NO"))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())

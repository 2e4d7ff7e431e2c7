#!/usr/bin/env python3
"""make display-bench: per-frame display maps like a real monitor's; what the detector keeps, skips, calibrates (issue 22)

    nice -n 10 python scripts/display_bench.py [--poses 12] [--seed 0] [--jobs 2] [--work display-bench-out]
                                               [--no-calibrate] [--reuse] [--doc]

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
(median / max over the imager, at infinity). With --doc the table
(doc_table) is also written into doc/detector.md between its display-bench
markers (`make display-bench`, run by `make bench`). Exit 1 unless every
still pose is kept and the moved pose alone skipped for camera motion.
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
from rotstar_lab.docblock import rewrite_block  # noqa: E402
from rotstar_mrcal.dataset import open_dataset  # noqa: E402
from rotstar_mrcal.detect.run import detect_dataset  # noqa: E402
from rotstar_mrcal.pattern.layout import make_layout  # noqa: E402
from rotstar_mrcal.simulate.camera import preset_model  # noqa: E402
from rotstar_mrcal.simulate.dataset import Settings, load_truth, write_dataset  # noqa: E402
from rotstar_mrcal.simulate.display import identity_maps, parse_display_maps  # noqa: E402
from rotstar_mrcal.simulate.poses import random_poses  # noqa: E402

REAL_MONITOR = "2:0,2;3:0,1,0,640@bottom;4:0,1;5:0,-1;6:0,1;7:0,1"
MOVE_PX = 0.3
MARK = 1.2  # issue 22: the real monitor's calibration within 1.2x of the clean display's
DOC = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "doc", "detector.md")


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


def map_error(display, maps: np.ndarray, origin) -> tuple[float, float]:
    """(display px, ppm): the largest error of the detector's maps against the true ones (n, 2, 3)

    Both relative to the frames' mean; px at the board points the maps were
    judged at, ppm of the linear parts. (NaN, NaN) when the detector gave no maps.

        >>> from rotstar_mrcal.detect.display_offsets import DisplayCheck
        >>> from rotstar_mrcal.simulate.display import offset_maps
        >>> c = DisplayCheck(np.array([[-0.5, 0], [0.5, 0.01]]), {}, 8, linear=np.zeros((2, 2, 2)),
        ...                  centre=np.zeros(2), uv=np.zeros((1, 2)))
        >>> [round(e, 6) for e in map_error(c, offset_maps([[0, 0], [1, 0]]), (10, 20))]
        [0.01, 0.0]
    """
    if display.offsets is None:
        return math.nan, math.nan
    true_lin = maps[:, :, :2] - np.eye(2)
    true_lin -= true_lin.mean(axis=0)
    uv = np.asarray(display.uv if display.uv is not None else display.centre[None], float)
    screen = uv + np.asarray(origin, float)
    true_d = np.einsum("kab,nb->kna", maps[:, :, :2], screen) + maps[:, None, :, 2] - screen
    true_d -= true_d.mean(axis=0)
    px = float(np.linalg.norm(display.displacement() - true_d, axis=-1).max())
    lin = display.linear if display.linear is not None else np.zeros_like(true_lin)
    return px, float(np.abs(lin - true_lin).max() * 1e6)


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
           "display": det.display.summary(), "reported": det.display.significant(),
           "map_error": map_error(det.display, identity_maps(8) if maps is None else maps,
                                  layout.origin),
           "motion": det.display.motion_px, "corner_rms": corner_rms(det, truth)}
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


def verdict(res: dict, poses: int) -> bool:
    """Every still pose kept and pose POSES (the moved one) alone skipped for camera motion, on every display"""
    still, moved_pose = [f"pose{i:03d}" for i in range(poses)], f"pose{poses:03d}"
    return all(r["kept"] == still and list(r["skipped"]) == [moved_pose] and
               "camera moved" in r["skipped"][moved_pose] for r in res.values())


def ratio(res: dict) -> tuple[float, float]:
    """(median, max): the real monitor's calibration error over the clean display's; NaN without both"""
    a, b = res["clean"].get("cal", {}), res["real-monitor"].get("cal", {})
    if "median_px" not in a or "median_px" not in b:
        return math.nan, math.nan
    return b["median_px"] / a["median_px"], b["max_px"] / a["max_px"]


def _cal_cells(r: dict) -> str:
    c = r.get("cal")
    if c is None:
        return "not run | not run"
    if "error" in c:
        return f"{c['error']} |"
    return f"{c['median_px']:.4f} / {c['max_px']:.4f} | {c['fit_rms_px']:.4f}"


def _row(name: str, r: dict, poses: int) -> str:
    moved_pose = f"pose{poses:03d}"
    still = [m for p, m in r["motion"].items() if p != moved_pose]
    skipped = "; ".join(f"{p}: {e}" for p, e in r["skipped"].items()).replace("|", "/") or "none"
    px, ppm = r["map_error"]
    maps = ("reported" if r["reported"] else "none reported") + (f"; {px:.3f} px / {ppm:.0f} ppm"
                                                                 if math.isfinite(px) else "; no estimate")
    return (f"| {name} | {len(r['kept'])} of {poses} | {skipped} | "
            f"{min(still, default=math.nan):.3f}-{max(still, default=math.nan):.3f} / "
            f"{r['motion'].get(moved_pose, math.nan):.3f} | {maps} | {r['corner_rms']:.4f} | {_cal_cells(r)} |")


def doc_table(res: dict, poses: int, seed: int, seconds: float) -> str:
    """The result as the Markdown block of doc/detector.md (display-bench markers), with its footer"""
    lines = ["| display | still poses kept | skipped (reason) | motion, still poses / moved pose, px | "
             "display maps; largest error vs the true maps, display px / ppm | corner error vs truth, RMS px | "
             "mrcal OPENCV8 vs the true camera, median / max px | fit RMS px |",
             "|---|---|---|---|---|---|---|---|"]
    lines += [_row(name.replace("-", " "), r, poses) for name, r in res.items()]
    rm, rx = ratio(res)
    mark = ("met" if max(rm, rx) <= MARK else "NOT met") if math.isfinite(rm) else "not measured"
    lines += ["", f"Real monitor / clean display: median x{rm:.2f}, max x{rx:.2f} (issue 22's mark: within "
                  f"{MARK}x): {mark}. Every still pose kept, the moved pose alone skipped for camera motion: "
                  f"{'yes' if verdict(res, poses) else 'NO'}.",
              "", f"*Written by `make display-bench` (scripts/display_bench.py --poses {poses}, seed {seed}, "
                  f"{seconds:.0f} s, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}): {poses} simulated D435 "
                  f"poses up to 60 degrees plus pose{poses:03d}, a copy of pose001 whose camera moved {MOVE_PX} px "
                  f"from frame 4 on, rendered on a clean display and with `--display-map '{REAL_MONITOR}'`; "
                  "motion: the largest frame-to-frame shift the display maps do not explain (limit 0.15 px); "
                  "the maps' error at the board points, relative to the frames' mean; corner error over the kept "
                  "poses; calibration on the kept boards, over the imager at infinity.*"]
    return "\n".join(lines)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--poses", type=int, default=12)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--work", default="display-bench-out")
    p.add_argument("--no-calibrate", action="store_true")
    p.add_argument("--reuse", action="store_true", help="detect the datasets already rendered in --work again")
    p.add_argument("--doc", action="store_true", help="rewrite the table in doc/detector.md (display-bench block)")
    args = p.parse_args()
    if args.poses < 2:
        p.error(f"--poses {args.poses}: needs at least 2 (the moved pose copies pose 1)")
    t0 = time.time()
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
    text = doc_table(res, args.poses, args.seed, time.time() - t0)
    print(text)
    if args.doc and rewrite_block(DOC, "display-bench", text):
        print(f"wrote {os.path.normpath(DOC)} (display-bench)", file=sys.stderr)
    return 0 if verdict(res, args.poses) else 1


if __name__ == "__main__":
    sys.exit(main())

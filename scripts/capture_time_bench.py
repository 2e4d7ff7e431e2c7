"""Seconds at the screen per pose: today's hold against the short holds, with every timing flaw on

    .venv/bin/python scripts/capture_time_bench.py [--n 60] [--n-old 8]

Each recording is the capture's simulated camera (capture.simulated.record_player,
every flaw of simulated.ALL_FLAWS on) filming the looping player of a small test
pattern (800 x 600 screen, 6 x 4 corners, 20 loop entries) from a random pose of
the pinhole-small camera at half size (320 x 200), from a random point of the loop,
8 ms exposures, split by capture.segment.segment (start markers, else content) and
detected as rotstar-capture's quick check does (capture.pose.quick_check). Printed per
setting: seconds recorded per pose, the fraction of poses kept, camera frames of
another entry or blends (impurity > 0.1 of white) accepted, the worst impurity
accepted, and the corner error against the true projection (median and 95th
percentile over every corner of every kept pose, px at full size).

Settings: today's default (every entry 30 refreshes, 2.2 loops: 22 s for this
20-entry pattern, 25.3 s for the default 23-entry one), and the short holds
(pattern.loop.SHORT_HOLDS: 2.4 s a loop here, 2.7 s for the default) recorded for
one loop and two entries, and for two loops and two entries.
"""

from __future__ import annotations

import argparse
import sys
import time

import cv2
import numpy as np

from rotstar_mrcal import simulate
from rotstar_mrcal.capture.pose import quick_check
from rotstar_mrcal.capture.segment import Options, SegmentError, segment
from rotstar_mrcal.capture.simulated import ALL_FLAWS, loop_irradiance, record_player
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.pattern.loop import entry_holds, player_loop

LAYOUT = make_layout(screen=(800, 600), pitch=100, band=24)
LOOP = player_loop(LAYOUT.frames())
N = len(LOOP)
SCALE = 2  # images at half the camera's size


def scenes(k: int, seed: int = 11):
    """[(E: irradiance of every entry at half size, true corners at half size)] of k random poses"""
    model = simulate.preset_model("pinhole-small")
    out = []
    for rt in simulate.random_poses(model, LAYOUT, k, np.random.default_rng(seed)):
        E = loop_irradiance(LAYOUT, model, rt)
        small = np.stack([cv2.resize(e, (e.shape[1] // SCALE, e.shape[0] // SCALE), interpolation=cv2.INTER_AREA)
                          for e in E])
        truth = (simulate.true_corners(model, LAYOUT, rt) + 0.5) / SCALE - 0.5  # pixel centres at integers
        out.append((small, truth))
    return out


def one(E, truth, holds, seconds: float, fps: float, opts: Options, s: int):
    """(kept, wrong frames accepted, blends accepted, worst impurity, corner errors px full size)"""
    rng = np.random.default_rng([13, s])
    T = int(seconds * fps)
    tr: list = []
    frames, seq = record_player(E, holds, T, ALL_FLAWS, fps=fps, exposure_s=0.008, start_entry=int(rng.integers(N)),
                                start_phase=float(rng.uniform()), rng=rng, truth=tr, noise=0.01)
    try:
        seg = segment(frames, LAYOUT.frames(), LAYOUT, 65535.0, opts, times=seq / fps)
    except SegmentError:
        return False, 0, 0, 0.0, np.array([])
    wrong = blends = 0
    worst = 0.0
    for k in range(1, N):
        f = LOOP[k]["file"]
        used = seg.used[f] if seg.used else range(*seg.ranges[f])
        for i in used:
            e, imp = tr[i]
            wrong += e != k
            blends += e == k and imp > 0.1
            worst = max(worst, imp)
    r = quick_check(seg, LAYOUT, LAYOUT.to_dict(), 65535.0)
    if not r.found:
        return False, wrong, blends, worst, np.array([])
    err = np.linalg.norm(r.corners - truth, axis=-1).ravel() * SCALE
    return True, wrong, blends, worst, err[np.isfinite(err)]


def row(name, holds, seconds, fps, n, poses, opts):
    t0 = time.time()
    res = [one(*poses[s % len(poses)], holds, seconds, fps, opts, s) for s in range(n)]
    kept = sum(r[0] for r in res)
    err = np.concatenate([r[4] for r in res if r[0]]) if kept else np.array([np.nan])
    print(f"| {name} | {fps:g} | {seconds:.1f} | {kept}/{n} | {sum(r[1] for r in res)} | {sum(r[2] for r in res)} | "
          f"{max(r[3] for r in res):.3f} | {np.median(err):.4f} / {np.percentile(err, 95):.4f} |", flush=True)
    print(f"  ({time.time() - t0:.0f} s)", file=sys.stderr)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--n", type=int, default=60, help="recordings per short-hold setting (default 60)")
    p.add_argument("--n-old", type=int, default=8, help="recordings of today's default (default 8)")
    p.add_argument("--poses", type=int, default=6, help="camera poses the recordings cycle through (default 6)")
    a = p.parse_args(argv)
    poses = scenes(a.poses)
    short = entry_holds(LOOP)
    old = entry_holds(LOOP, 30)
    print("| setting | fps | s per pose | poses kept | other-entry frames accepted | blends accepted | "
          "worst impurity | corner error median / 95 % (px) |")
    print("|---|---|---|---|---|---|---|---|")
    for fps in (25.0, 30.0):
        row("today: hold 30, 2.2 loops", old, 2.2 * old.sum() / 60, fps, a.n_old, poses, Options(hold=30))
        for loops, name in ((1, "short, 1 loop + 2 entries"), (2, "short, 2 loops + 2 entries")):
            row(name, short, (loops * short.sum() + 2 * short.max()) / 60, fps, a.n, poses, Options())
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Seconds at the screen per pose: today's hold against the short holds, with every timing flaw on

    .venv/bin/python scripts/capture_time_bench.py [--n 60] [--n-old 8] [--n-until 200]

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
(pattern.loop.SHORT_HOLDS: 2.6 s a loop here, 2.9 s for the default) recorded for
--until-enough's first look (cli.capture.first_look: one loop and two camera
frames), and for two loops.

Then (--n-until recordings per frame rate) what --until-enough takes for the
default 23-entry sequence (2360 x 1640 screen, 14 x 9 corners, seen by the
pinhole-small camera at a quarter size: the split only, no corners):
capture.session.record_until_enough on the simulated camera's stream, the
first look and then a third of it at a time until every frame has two clean
camera frames, at most 2.2 loops. Printed: the seconds per pose (mean, median,
95 %, the worst; the camera's frames the driver lost count), how many were enough
after the first look, poses kept, camera frames of another entry or blends
accepted, and the clean camera frames per rotating-star frame.
"""

from __future__ import annotations

import argparse
import sys
import time
import types

import cv2
import numpy as np

from rotstar_mrcal import simulate
from rotstar_mrcal.capture.pose import quick_check
from rotstar_mrcal.capture.segment import Options, SegmentError, segment
from rotstar_mrcal.capture.session import SessionOptions, record_until_enough
from rotstar_mrcal.capture.simulated import ALL_FLAWS, loop_irradiance, record_player
from rotstar_mrcal.capture.source import ArraySource
from rotstar_mrcal.cli.capture import first_look, frames_per_recording
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.pattern.loop import entry_holds, player_loop

LAYOUT = make_layout(screen=(800, 600), pitch=100, band=24)
LOOP = player_loop(LAYOUT.frames())
N = len(LOOP)
SCALE = 2  # images at half the camera's size


def scenes(k: int, seed: int = 11, layout=LAYOUT, scale: int = SCALE):
    """[(E: irradiance of every entry at 1 / scale size, true corners at that size)] of k random poses"""
    model = simulate.preset_model("pinhole-small")
    out = []
    for rt in simulate.random_poses(model, layout, k, np.random.default_rng(seed)):
        E = loop_irradiance(layout, model, rt, supersample=4 if scale == SCALE else 2)
        small = np.stack([cv2.resize(e, (e.shape[1] // scale, e.shape[0] // scale), interpolation=cv2.INTER_AREA)
                          for e in E])
        truth = (simulate.true_corners(model, layout, rt) + 0.5) / scale - 0.5  # pixel centres at integers
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
        used = seg.used.get(f, []) if seg.used else range(*seg.ranges[f])
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


def until_enough(E, layout, fps: float, s: int, extra: int = 2, exposure_s: float = 0.008) -> dict:
    """One pose taken as rotstar-capture --hold short --until-enough takes it; its seconds and what was accepted"""
    loop = player_loop(layout.frames())
    holds = entry_holds(loop)
    a = types.SimpleNamespace(frames=None, loops=2.2, refresh=60.0, hold=None)
    nframes = frames_per_recording(a, holds, fps)
    rng = np.random.default_rng([17, s])
    tr: list = []
    frames, seq = record_player(E, holds, int(nframes * 1.05) + 2, ALL_FLAWS, fps=fps, exposure_s=exposure_s,
                                start_entry=int(rng.integers(len(loop))), start_phase=float(rng.uniform()), rng=rng,
                                truth=tr, noise=0.01)
    pattern = layout.to_dict()
    opts = SessionOptions(Options(), False, first_look(a, pattern, fps) - 2 + extra)
    src = ArraySource(frames, seq, fps)
    first = src.read()
    buf = np.empty((nframes,) + first.image.shape, first.image.dtype)
    buf[0] = first.image
    got, _ = record_until_enough(src, buf, first.sequence, pattern, layout, opts)
    span = int(got[-1]) - int(got[0]) + 1  # frame periods, a lost camera frame's included
    out = {"seconds": span / fps, "first": span < opts.until_enough + max(1, opts.until_enough // 3),
           "look": opts.until_enough / fps, "kept": False, "wrong": 0, "blends": 0, "stars": np.nan, "spared": 0}
    try:
        seg = segment(buf[:len(got)], pattern["frames"], layout, 65535.0, opts.segment, times=got / fps)
    except SegmentError:
        return out
    for k in range(1, len(loop)):
        for i in seg.used.get(loop[k]["file"], []):
            e, imp = tr[i]
            out["wrong"] += e != k
            out["blends"] += e == k and imp > 0.1
    stars = [len(seg.used[e["file"]]) for e in loop[1:] if e["kind"] == "rotstar"]
    out.update(kept=min(len(u) for u in seg.used.values()) >= 2, stars=float(np.mean(stars)), spared=len(seg.missing))
    return out


def until_enough_rows(n: int, poses: int, extra: int = 2, exposure_s: float = 0.008) -> None:
    """The --until-enough table (module doc) at 25 and 30 fps"""
    layout = make_layout()
    es = [E for E, _ in scenes(poses, 12, layout, 4)]
    print("\n| default sequence, --until-enough | fps | s per pose: mean / median / 95 % / worst | enough after the first "
          "look | poses kept (of them without a frame they spare) | other-entry frames accepted | blends accepted | "
          "clean camera frames per star frame |")
    print("|---|---|---|---|---|---|---|---|")
    for fps in (25.0, 30.0):
        t0 = time.time()
        res = [until_enough(es[s % len(es)], layout, fps, s, extra, exposure_s) for s in range(n)]
        secs = np.array([r["seconds"] for r in res])
        print(f"| short holds | {fps:g} | {secs.mean():.2f} / {np.median(secs):.2f} / {np.percentile(secs, 95):.2f} / "
              f"{secs.max():.2f} | "
              f"{sum(r['first'] for r in res)}/{n} ({res[0]['look']:.2f} s) | {sum(r['kept'] for r in res)}/{n} "
              f"({sum(r['kept'] and r['spared'] > 0 for r in res)}) | "
              f"{sum(r['wrong'] for r in res)} | {sum(r['blends'] for r in res)} | "
              f"{np.nanmean([r['stars'] for r in res]):.2f} |", flush=True)
        print(f"  ({time.time() - t0:.0f} s)", file=sys.stderr)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--n", type=int, default=60, help="recordings per short-hold setting (default 60)")
    p.add_argument("--n-old", type=int, default=8, help="recordings of today's default (default 8)")
    p.add_argument("--n-until", type=int, default=200, help="--until-enough recordings per frame rate (default 200)")
    p.add_argument("--look-extra", type=int, default=2, help="--n-until: camera frames after one loop in the first "
                   "look (default 2, as cli.capture.first_look)")
    p.add_argument("--exposure-ms", type=float, default=8.0, help="--n-until: the camera's exposure (default 8 ms)")
    p.add_argument("--poses", type=int, default=6, help="camera poses the recordings cycle through (default 6)")
    a = p.parse_args(argv)
    short = entry_holds(LOOP)
    old = entry_holds(LOOP, 30)
    if a.n or a.n_old:
        poses = scenes(a.poses)
        print("| setting | fps | s per pose | poses kept | other-entry frames accepted | blends accepted | "
              "worst impurity | corner error median / 95 % (px) |")
        print("|---|---|---|---|---|---|---|---|")
    for fps in (25.0, 30.0) if a.n or a.n_old else ():
        if a.n_old:
            row("today: hold 30, 2.2 loops", old, 2.2 * old.sum() / 60, fps, a.n_old, poses, Options(hold=30))
        look = first_look(types.SimpleNamespace(hold=None, refresh=60.0), LAYOUT.to_dict(), fps) / fps
        for seconds, name in ((look, "short, first look (1 loop + 2 camera frames)"),
                              (2 * short.sum() / 60, "short, 2 loops")):
            if a.n:
                row(name, short, seconds, fps, a.n, poses, Options())
    if a.n_until:
        until_enough_rows(a.n_until, a.poses, a.look_extra, a.exposure_ms / 1000)
    return 0


if __name__ == "__main__":
    sys.exit(main())

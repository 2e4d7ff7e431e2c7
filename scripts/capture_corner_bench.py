#!/usr/bin/env python3
"""What each timing flaw does to the corners: the short capture against today's, per flaw, at the corner level

    nice -n 10 .venv/bin/python scripts/capture_corner_bench.py [--poses 4] [--repeats 4] [--flaws all,none,pwm]

The poses, camera, pattern and capture path of capture_calib_bench.py (the
capture's simulated camera -> capture_one -> quick_check's detection), but
per recording only the corners of the pose against their true positions:
per pose, `--repeats` recordings (new noise, a new point of the loop, new
flaw draws) with each flaw set, then over the repeats

- bias: the distance of the repeats' mean corner from the truth (what
  averaging more recordings would not remove), median over the corners;
- noise: the repeats' spread about their mean (rms over the two axes),
  median over the corners;
- rms: the root mean square distance from the truth over all corners;
- impure: the largest departure (fraction of white) of any camera frame the
  split averaged from the displayed frame it was taken for (camera_stream's
  truth), and the clean camera frames per rotating-star frame.

A flaw set is one of: none (the panel's scan-out only), all (ALL_FLAWS),
or the name of one flaw of Flaws (response_s, pwm, late, drop_rate,
clock_drift) on alone at ALL_FLAWS's value.
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from capture_calib_bench import (  # noqa: E402
    EXPOSURE_S, FPS, LAYOUT, LOOP, PATTERN, REFRESH, cli_args, half_d435, render, say,
)
from rotstar_mrcal import simulate  # noqa: E402
from rotstar_mrcal.capture.pose import quick_check  # noqa: E402
from rotstar_mrcal.capture.segment import Options, SegmentError, segment  # noqa: E402
from rotstar_mrcal.capture.session import SessionOptions, record_until_enough  # noqa: E402
from rotstar_mrcal.capture.simulated import ALL_FLAWS, Flaws, record_player  # noqa: E402
from rotstar_mrcal.capture.source import ArraySource, record  # noqa: E402
from rotstar_mrcal.detect.pipeline import detect_pose  # noqa: E402
from rotstar_mrcal.cli.capture import first_look, frames_per_recording  # noqa: E402
from rotstar_mrcal.pattern.loop import entry_holds  # noqa: E402


def flaw_set(name: str) -> Flaws:
    """none, all, or one flaw of ALL_FLAWS alone (late: early too)"""
    if name == "none":
        return Flaws()
    if name == "all":
        return ALL_FLAWS
    if name == "late":
        return Flaws(late=ALL_FLAWS.late, early=ALL_FLAWS.early)
    return Flaws(**{name: getattr(ALL_FLAWS, name)})


def one_recording(E, hold, flaws: Flaws, rng, blend_z: float = Options.content_blend_z, keep: dict | None = None
                  ) -> tuple[np.ndarray | None, float, float]:
    """(corners (ny, nx, 2) or None, worst impurity of a frame averaged, clean camera frames per star frame)

    Recorded, split and checked as capture.session.capture_one does (its
    record_until_enough for the short holds, a fixed length for today's),
    without writing the pose folder. keep: a dict that receives the averaged
    frames by kind (rotstar, identity, checkerboard), the full scale and the
    detection's refinement windows.
    """
    a = cli_args(hold)
    nframes = frames_per_recording(a, entry_holds(LOOP, hold), FPS)
    truth: list = []
    frames, seq = record_player(E, entry_holds(LOOP, hold), int(nframes * 1.05) + 2, flaws, fps=FPS,
                                exposure_s=EXPOSURE_S, refresh_hz=REFRESH, start_entry=int(rng.integers(len(LOOP))),
                                start_phase=float(rng.uniform()), rng=rng, noise=0.01, truth=truth)
    opts = SessionOptions(Options(hold=hold or 0, refresh_hz=REFRESH, content_blend_z=blend_z), False,
                          first_look(a, PATTERN, FPS) if hold is None else 0)
    src = ArraySource(frames, seq, FPS)
    first = src.read()
    buf = np.empty((nframes,) + first.image.shape, first.image.dtype)
    buf[0] = first.image
    if opts.until_enough:
        seqnums, _ = record_until_enough(src, buf, first.sequence, PATTERN, LAYOUT, opts)
    else:
        seqnums = np.r_[first.sequence, record(src, nframes - 1, out=buf[1:]).sequence]
    try:
        seg = segment(buf[:len(seqnums)], PATTERN["frames"], LAYOUT, src.full_scale, opts.segment,
                      times=seqnums / FPS)
    except SegmentError:
        return None, np.nan, np.nan
    r = quick_check(seg, LAYOUT, PATTERN, src.full_scale)
    if keep is not None:
        for kind in ("rotstar", "identity", "checkerboard"):
            keep[kind] = np.stack([seg.images[f["file"]] for f in PATTERN["frames"] if f["kind"] == kind])
        keep["full_scale"] = src.full_scale
        keep["window"] = r.window
    if not r.found:
        return None, np.nan, np.nan
    used = seg.used or {f: list(range(*rg)) for f, rg in seg.ranges.items()}
    imp = max(truth[i][1] for u in used.values() for i in u)
    stars = [f["file"] for f in PATTERN["frames"] if f["kind"] == "rotstar"]
    return r.corners, imp, float(np.mean([len(used[f]) for f in stars]))


def ideal_corners(E: np.ndarray) -> np.ndarray:
    """The detector's corners on the noise-free displayed frames (no capture at all): its own error"""
    files = [f["kind"] for f in PATTERN["frames"]]
    img = E[1:] * 0.9 * 65535

    def stack(kind):
        return np.stack([img[i] for i, k in enumerate(files) if k == kind]).astype(np.float32)

    return detect_pose(stack("rotstar"), LAYOUT, full_scale=65535.0, checkerboard=stack("checkerboard")[0],
                       identity=stack("identity")).corners


def pose_stats(cs: list, true: np.ndarray, ideal: np.ndarray) -> dict:
    """bias (against the detector on noise-free frames), noise, rms against the truth (px, median over corners)"""
    C = np.stack([c for c in cs if c is not None])
    mean = np.nanmean(C, axis=0)
    bias = np.linalg.norm(mean - ideal, axis=-1)
    noise = np.sqrt(np.nanmean(np.sum((C - mean) ** 2, axis=-1), axis=0) / 2)
    rms = np.sqrt(np.nanmean(np.sum((C - true) ** 2, axis=-1)))
    worst = np.nanmax(np.linalg.norm(C - ideal, axis=-1))
    return {"bias": float(np.nanmedian(bias)), "noise": float(np.nanmedian(noise)), "rms": float(rms),
            "worst": float(worst), "found": len(C)}


def one_pose(model, rt, k: int, a) -> dict:
    """{(flaw set, hold): pose_stats} of --repeats recordings of pose rt with every flaw set and hold"""
    E = render(model, rt)
    true = simulate.true_corners(model, LAYOUT, rt)
    ideal = ideal_corners(E)
    say(f"pose {k}: detector on noise-free frames vs truth, rms "
        f"{np.sqrt(np.nanmean(np.sum((ideal - true) ** 2, axis=-1))):.4f} px")
    out = {}
    for fl in a.flaws.split(","):
        for h in [None if h == "short" else int(h) for h in a.holds.split(",")]:
            if h is not None and fl not in a.today_flaws.split(","):
                continue
            got = [one_recording(E, h, flaw_set(fl), np.random.default_rng([26, a.seed, k, r]), a.blend_z)
                   for r in range(a.repeats)]
            s = pose_stats([c for c, _, _ in got], true, ideal)
            s.update(impure=float(np.nanmax([g[1] for g in got])), n_star=float(np.nanmean([g[2] for g in got])))
            out[fl, h] = s
            say(f"pose {k} {fl:12s} hold {h or 'short'}: " + ", ".join(f"{q} {v:.4f}" for q, v in s.items()))
    return out


def table(res: dict) -> str:
    """The Markdown table: per flaw set and hold, the means over the poses (the worst: the largest)"""
    rows = ["| flaws | hold | bias vs noise-free px | noise px | rms vs truth px | worst corner vs noise-free px "
            "| worst impurity averaged | clean camera frames per star frame |", "|---|---|---|---|---|---|---|---|"]
    for (fl, h), ss in res.items():
        m = {q: np.mean([s[q] for s in ss]) for q in ss[0]}
        rows.append(f"| {fl} | {h or 'short'} | {m['bias']:.4f} | {m['noise']:.4f} | {m['rms']:.4f} | "
                    f"{max(s['worst'] for s in ss):.4f} | {max(s['impure'] for s in ss):.4f} | {m['n_star']:.1f} |")
    return "\n".join(rows)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--poses", type=int, default=4)
    p.add_argument("--repeats", type=int, default=4)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--flaws", default="none,all")
    p.add_argument("--holds", default="30,short", help="30 (today's) and/or short (pattern.loop.SHORT_HOLDS)")
    p.add_argument("--blend-z", type=float, default=Options.content_blend_z, help="segment.Options.content_blend_z")
    p.add_argument("--today-flaws", default="none,all", help="the flaw sets today's hold is recorded with")
    a = p.parse_args(argv)
    model = half_d435()
    res: dict = {}
    for k, rt in enumerate(simulate.random_poses(model, LAYOUT, a.poses, np.random.default_rng([23, a.seed]))):
        for key, s in one_pose(model, rt, k, a).items():
            res.setdefault(key, []).append(s)
    print(table(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())

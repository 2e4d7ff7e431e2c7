#!/usr/bin/env python3
"""The short capture's heavy tail of corners (issue 23): per-corner errors of many recordings, and why

    nice -n 10 .venv/bin/python scripts/capture_tail_lab.py [--seeds 0,1] [--poses 3] [--repeats 3] [--hold short]

capture_corner_bench's recordings (the capture's simulated camera, split and
detected as capture_one does), no flaws by default; per corner the distance
from the detector's own corner on the noise-free frames, and the same
refinement redone on the recording with the noise-free detection's windows
and low-pass (what the window's draw adds). Prints the distributions
(median, 95 %, 99 %, max) and the windows' departure from the noise-free
ones, and with --out writes the averaged frames of the recordings that hold
an outlier (> 4x the median) to OUT/s{seed}p{pose}r{repeat}.npz.
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from capture_calib_bench import LAYOUT, PATTERN, half_d435, render, say  # noqa: E402
from capture_corner_bench import flaw_set, one_recording  # noqa: E402
from rotstar_mrcal import simulate  # noqa: E402
from rotstar_mrcal.detect.pipeline import detect_pose  # noqa: E402
from rotstar_mrcal.detect.refine import prefilter, symmetric_refine  # noqa: E402
from rotstar_mrcal.simulate.visibility import true_windows  # noqa: E402


def ideal_detection(E: np.ndarray):
    """detect_pose on the noise-free displayed frames (capture_corner_bench.ideal_corners, whole result)"""
    kinds = [f["kind"] for f in PATTERN["frames"]]
    img = E[1:] * 0.9 * 65535

    def stack(kind):
        return np.stack([img[i] for i, k in enumerate(kinds) if k == kind]).astype(np.float32)

    return detect_pose(stack("rotstar"), LAYOUT, full_scale=65535.0, checkerboard=stack("checkerboard")[0],
                       identity=stack("identity"))


def with_windows(rotstar: np.ndarray, corners: np.ndarray, window: np.ndarray, sigma: float) -> np.ndarray:
    """(ny, nx, 2) the joint symmetric refinement of corners redone on rotstar with other windows"""
    ok = np.isfinite(corners[..., 0]) & np.isfinite(window)
    out = np.full(corners.shape, np.nan)
    r = symmetric_refine(prefilter(np.asarray(rotstar, np.float32), sigma), corners[ok], window[ok])
    out[ok] = r.corners
    return out


def common_mode(e: np.ndarray) -> tuple[float, float]:
    """(shift, affine): the rms of the corners' mean error and of their affine fit over the corners, each over
    what independent errors of the corners' rms would give (sqrt(1 / N), sqrt(3 / N))"""
    ok = np.isfinite(e[..., 0])
    j, i = np.nonzero(ok)
    v = e[ok]
    X = np.column_stack((np.ones(len(i)), i, j))
    fit = X @ np.linalg.lstsq(X, v, rcond=None)[0]
    rms = np.sqrt(np.mean(v ** 2))
    return (float(np.linalg.norm(v.mean(axis=0)) / np.sqrt(2) / (rms * np.sqrt(1 / len(v)))),
            float(np.sqrt(np.mean(fit ** 2)) / (rms * np.sqrt(3 / len(v)))))


def quantiles(name: str, v: np.ndarray) -> str:
    v = v[np.isfinite(v)]
    q = np.percentile(v, [50, 95, 99, 100])
    return (f"{name}: {len(v)} corners, median {q[0]:.4f}, 95 % {q[1]:.4f}, 99 % {q[2]:.4f}, max {q[3]:.4f} px, "
            f"> 4x median {int(np.sum(v > 4 * q[0]))}")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seeds", default="0")
    p.add_argument("--poses", type=int, default=3)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--flaws", default="none")
    p.add_argument("--hold", default="short")
    p.add_argument("--out", default="")
    a = p.parse_args(argv)
    model = half_d435()
    hold = None if a.hold == "short" else int(a.hold)
    err, err_w, dw, dtrue, common, rows = [], [], [], [], [], []
    for seed in [int(s) for s in a.seeds.split(",")]:
        for k, rt in enumerate(simulate.random_poses(model, LAYOUT, a.poses, np.random.default_rng([23, seed]))):
            E = render(model, rt)
            ideal = ideal_detection(E)
            dtrue.append((ideal.window - true_windows(model, LAYOUT, rt)).ravel())
            for r in range(a.repeats):
                keep: dict = {}
                c, _, nstar = one_recording(E, hold, flaw_set(a.flaws), np.random.default_rng([26, seed, k, r]),
                                            keep=keep)
                if c is None:
                    say(f"seed {seed} pose {k} draw {r}: no board")
                    continue
                d = np.linalg.norm(c - ideal.corners, axis=-1)
                cw = with_windows(keep["rotstar"], c, ideal.window, ideal.prefilter_px)
                err.append(d.ravel())
                common.append(common_mode(c - ideal.corners))
                err_w.append(np.linalg.norm(cw - ideal.corners, axis=-1).ravel())
                dw.append((keep["window"] - ideal.window).ravel())
                say(f"seed {seed} pose {k} draw {r}: median {np.nanmedian(d):.4f} max {np.nanmax(d):.4f} px, "
                    f"windows off by up to {np.nanmax(np.abs(dw[-1])):.2f} px, {nstar:.1f} star frames")
                rows.append((seed, k, r, d, keep, E, ideal.corners, simulate.true_corners(model, LAYOUT, rt), c))
    err, err_w, dw, dtrue = (np.concatenate(v) for v in (err, err_w, dw, dtrue))
    print(quantiles("vs noise-free, as detected", err))
    print(quantiles("vs noise-free, with the noise-free windows", err_w))
    big = err > 4 * np.nanmedian(err)
    print(f"window minus noise-free window: |.| median {np.nanmedian(np.abs(dw)):.3f}, 95 % "
          f"{np.nanpercentile(np.abs(dw), 95):.3f}, max {np.nanmax(np.abs(dw)):.3f} px; at the outliers "
          + ", ".join(f"{v:+.2f}" for v in dw[big]))
    print(f"noise-free window minus the true one (simulate.visibility.true_windows): mean {np.nanmean(dtrue):+.3f}, "
          f"|.| median {np.nanmedian(np.abs(dtrue)):.3f}, max {np.nanmax(np.abs(dtrue)):.3f} px")
    cm = np.array(common)
    print(f"per recording, the error field's affine part over the corners against independent noise (1 if "
          f"independent): shift {np.mean(cm[:, 0]):.2f}, affine {np.mean(cm[:, 1]):.2f} (means over "
          f"{len(cm)} recordings)")
    if a.out:
        os.makedirs(a.out, exist_ok=True)
        med = np.nanmedian(err)
        for seed, k, r, d, keep, E, ideal, true, c in rows:
            if np.nanmax(d) > 4 * med:
                np.savez_compressed(os.path.join(a.out, f"s{seed}p{k}r{r}.npz"), E=E, ideal=ideal, true=true,
                                    corners=c, **keep)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Corner error against the centroid truth under coma: rotstar, rotstar-psf and the saddle fit (issue 24)

SYNOPSIS

    nice -n 10 .venv/bin/python -m rotstar_lab.benchmark.psfcheck --coma 2.5 --focus 0.3 --npose 4
    (PYTHONPATH=scripts; renders are cached in --cache, default /tmp/rotstar-psfcheck)

The scene of the failure tables (failures.py): the d435 preset, make demo's
lens (optics.LensPSF, coma and focus in waves at the image corners; the
light's centroid on the true model), the paper layout without identity
frames, random poses from failures.make_units' generator, read noise 1 %,
shot 1e-4, 16 bits. Per pose the 8 rotating-star frames are detected by
rotstar (detect_pose, the symmetric fit) and by rotstar-psf; the saddle fit
runs on the 8-capture averaged checkerboard from the true corners moved 0.5
px, in the true windows (as in the failure tables). --gaussian S replaces the
lens by a symmetric Gaussian PSF of S px.

Printed: per method the RMS of the corner error against the truth, and its
pose-dependent part: the error minus the mean error of its image cell
(CELL_PX squares, over all poses; cells with one corner left out), RMS, with
the n/(n-1) correction; and the detection time per pose.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

from rotstar_mrcal import simulate
from rotstar_mrcal.detect.pipeline import detect_pose
from rotstar_mrcal.optics.psf import LensPSF
from rotstar_mrcal.optics.wavefront import Seidel
from rotstar_mrcal.peers.checkerboard import refine_by_window, saddle_refine
from rotstar_mrcal.peers.registry import REFINERS
from rotstar_mrcal.simulate.captures import averaged_captures, lit_box
from rotstar_mrcal.simulate.visibility import in_view, true_windows
from rotstar_lab.benchmark.failures import paper_layout
from rotstar_lab.benchmark.scoring import MATCH_PX, perturbed_start

CELL_PX = 80.0


def render(model, layout, rt, psf, path):
    """(rotstar frames irradiance (8, H, W), checkerboard irradiance (H, W)), cached in path"""
    if os.path.exists(path):
        z = np.load(path)
        return z["rot"], z["cb"]
    fr = [f for f in layout.frames() if f["kind"] in ("rotstar", "checkerboard")]
    kinds = np.array([f["kind"] for f in fr])
    light = simulate.shown_light(simulate.exact_frames(layout, fr), 2.2, 2.2)
    screen = simulate.make_screen(light, layout)
    E = simulate.render_irradiance(screen, model, rt, supersample=4, psf=psf)
    rot, cb = E[kinds == "rotstar"], E[kinds == "checkerboard"][0]
    np.savez(path, rot=rot, cb=cb)
    return rot, cb


def pose_dependent(pos, err):
    """RMS of err (n, 2) minus its CELL_PX cell's mean over all poses (cells of >= 2 corners), n/(n-1) corrected"""
    cell = np.floor(pos / CELL_PX).astype(int)
    key = cell[:, 0] * 1000 + cell[:, 1]
    out, dof = 0.0, 0
    for k in np.unique(key):
        e = err[key == k]
        if len(e) < 2:
            continue
        out += ((e - e.mean(axis=0)) ** 2).sum()
        dof += (len(e) - 1) * 2
    return float(np.sqrt(out / max(dof, 1) * 2))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--coma", type=float, default=1.5)
    p.add_argument("--focus", type=float, default=0.3)
    p.add_argument("--gaussian", type=float, default=0.0)
    p.add_argument("--npose", type=int, default=4)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--cache", default="/tmp/rotstar-psfcheck")
    p.add_argument("--methods", default="symmetric,psf,saddle")
    p.add_argument("--distance", default="", help="near,far metres (default: random_poses' range)")
    a = p.parse_args(argv)
    os.makedirs(a.cache, exist_ok=True)
    model = simulate.preset_model("d435")
    layout = paper_layout()
    psf = a.gaussian if a.gaussian > 0 else LensPSF(Seidel(coma=a.coma, focus=a.focus), model.imagersize())
    tag = f"g{a.gaussian:g}" if a.gaussian > 0 else f"c{a.coma:g}f{a.focus:g}"
    dist = tuple(float(v) for v in a.distance.split(",")) if a.distance else None
    rts = simulate.random_poses(model, layout, a.npose, np.random.default_rng([3, a.seed]), distance=dist)
    if dist:
        tag += f"-d{a.distance}"
    fs = float(simulate.full_scale_code(16))
    methods = a.methods.split(",")
    acc = {m: ([], [], []) for m in methods}  # positions, errors, seconds
    for i, rt in enumerate(rts):
        t0 = time.perf_counter()
        rot, cb = render(model, layout, rt, psf, os.path.join(a.cache, f"{tag}-s{a.seed}-p{i}.npz"))
        print(f"pose {i}: rendered ({time.perf_counter() - t0:.0f} s)", file=sys.stderr)
        truth = simulate.true_corners(model, layout, rt)
        view = in_view(model, layout, rt)
        rng = np.random.default_rng([5, a.seed, i])

        def expose(img):
            return simulate.expose(img, gain=0.9, noise=0.01, shot=1e-4, bits=16, rng=rng)

        frames = expose(rot).astype(np.float32)
        for m in methods:
            t0 = time.perf_counter()
            if m == "saddle":
                avg = averaged_captures(cb, expose, 8, lit_box(cb, 0.02))
                q = refine_by_window(lambda im, x, w: saddle_refine(im, x, win=w), avg,
                                     perturbed_start(truth, a.seed, i), true_windows(model, layout, rt))
            else:
                q = detect_pose(frames, layout, full_scale=fs, refine=REFINERS[m]).corners
            dt = time.perf_counter() - t0
            e = q - truth
            ok = view & np.isfinite(e).all(axis=-1) & (np.linalg.norm(e, axis=-1) <= MATCH_PX)
            acc[m][0].append(truth[ok])
            acc[m][1].append(e[ok])
            acc[m][2].append(dt)
        print(f"pose {i}: windows {np.nanpercentile(true_windows(model, layout, rt), [5, 50, 95]).round(1)}",
              file=sys.stderr)
    print(f"{tag}, {a.npose} poses (seed {a.seed})")
    for m in methods:
        pos, err = np.concatenate(acc[m][0]), np.concatenate(acc[m][1])
        rms = float(np.sqrt((err ** 2).sum(axis=1).mean()))
        print(f"  {m:10s} corners {len(err):5d}  RMS {rms:.4f} px  pose-dependent {pose_dependent(pos, err):.4f} px"
              f"  mean error ({err[:, 0].mean():+.4f}, {err[:, 1].mean():+.4f})  {np.mean(acc[m][2]):.2f} s/pose")


if __name__ == "__main__":
    main()

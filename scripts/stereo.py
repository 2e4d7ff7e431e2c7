#!/usr/bin/env python3
"""make stereo: a simulated D435 stereo pair calibrated with mrcal, validated against the truth and in depth terms

SYNOPSIS

    python scripts/stereo.py --out stereo-out           # what `make stereo` runs (~4 min on 2 cores)
    python scripts/stereo.py --out /tmp/s --quick       # fewer poses, for a smoke run
    python scripts/stereo.py --out /tmp/s --rgb         # the colour camera too (calibrated with the pair)

The chain, each command printed (stderr) before it runs:

1. rotstar-pattern (the screen's frames and pattern.json);
2. rotstar-simulate --rig d435 --seidel coma=1.5,focus=0.3: the D435's two
   infrared imagers through make demo's lens (coma and field curvature at
   the image corners; the right imager's x0.9), camera 1
   50 mm to the right of camera 0, a lens and a small rotation of its own;
   --rgb: the colour camera as camera 2), --poses board poses with the
   truth (truth-camera-K.cameramodel, truth.json), the screen's pixels under
   --glass mm of cover glass (0.7 by default; rotstar-simulate --glass);
3. the poses split into two groups A and B (folders of links to the pose
   folders: blocks of as many poses as cameras alternately, so that each
   group has the poses drawn for each camera);
4. per group and method (rotstar, and the demo's best checkerboard
   detector, saddle: the Lucchese-Mitra fit on the checkerboard frame,
   started from rotstar's corners; both from the same poses):
   rotstar-detect --method, then rotstar-calibrate --corners (one joint
   mrcal-calibrate-cameras solve of all cameras, LENSMODEL_OPENCV8, then the
   cover glass estimated and taken out when it is a plausible glass);
5. per method (rotstar_mrcal.evaluate.stereo.evaluate): each camera of each
   calibration against the true camera, camera 1's baseline and rotation
   against the truth, the cross-validation of A against B, and the depth
   error of held-out boards at 0.5, 1 and 2 m (validate.depth: their
   corners seen by the true cameras, rectified with the calibrated pair by
   mrcal.rectified_system, depth from the disparity by mrcal.stereo_range),
   without noise and with the method's own corner noise (its corners
   against the true ones, RMS per coordinate); and the glass: the thickness
   each calibration estimated, and the plain joint solve (before the
   correction) against the truth beside the written one and beside it
   corrected for the known thickness (what rotstar-calibrate --glass MM
   writes: calibrate.glass.correct_glass on the same solve);
6. OUT/stereo/results.json (rotstar-stereo/1) and rotstar-report over it
   (OUT/report/index.html).

stdout: the tables (Markdown); a full run (not --quick, the default seed
and poses, the default glass, no --rgb) also writes them into the marked blocks of
doc/validation.md (stereo:tables) and README.md (stereo:headline);
--no-docs: not.
"""

from __future__ import annotations

import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import shutil  # noqa: E402
import signal  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import mrcal  # noqa: E402
import numpy as np  # noqa: E402

from rotstar_lab.benchmark.glass import observed_corners  # noqa: E402
from rotstar_lab.benchmark.glassrender import same_noise_reference, true_grids  # noqa: E402
from rotstar_lab.docblock import rewrite_block  # noqa: E402
from rotstar_lab.steps import log, run_step, short_path, start_clock, wall_time_note  # noqa: E402
from rotstar_mrcal.calibrate.glass import correct_glass  # noqa: E402
from rotstar_mrcal.calibrate.rig import camera_of  # noqa: E402
from rotstar_mrcal.evaluate import depth, stereo  # noqa: E402
from rotstar_mrcal.evaluate.stereo import pose_of_path  # noqa: E402
from rotstar_mrcal.optics.refraction import Glass  # noqa: E402
from rotstar_mrcal.report import stereo as stereoreport  # noqa: E402
from rotstar_mrcal.simulate.rig import load_rig_truth  # noqa: E402
from rotstar_mrcal.vnl import read_corners  # noqa: E402


def run(cmd, **kw):
    """A step of make stereo (rotstar_lab.steps.run_step)"""
    return run_step(cmd, "stereo", **kw)


ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEFAULT_SEED = 1
DEFAULT_POSES = 24
METHODS = ("rotstar", "saddle")
LENSMODEL = "LENSMODEL_OPENCV8"
SUPERSAMPLE = 2
LENS = "coma=1.5,focus=0.3"  # make demo's lens (rotstar_lab.demo.scene), for every camera of the rig
GLASS_MM = 0.7  # the screen's cover glass (issue 22: laminated tablets 0.5-1.5 mm), index 1.5


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="stereo-out", help="output folder (default stereo-out)")
    p.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="parallel processes")
    p.add_argument("--seed", type=int, default=DEFAULT_SEED, help=f"rig, poses and noise seed (default {DEFAULT_SEED})")
    p.add_argument("--poses", type=int, default=None,
                   help=f"board poses in all, split into the groups A and B (default {DEFAULT_POSES}; with --rgb "
                   f"{DEFAULT_POSES * 3 // 2}, as the colour camera's narrower field sees fewer whole boards)")
    p.add_argument("--rgb", action="store_true", help="add the D435's colour camera (camera 2) to the rig")
    p.add_argument("--glass", type=float, default=GLASS_MM,
                   help=f"the screen's cover glass, mm (default {GLASS_MM}; 0: none)")
    p.add_argument("--quick", action="store_true", help="half the poses, 30 with --rgb (a smoke run)")
    p.add_argument("--no-docs", action="store_true", help="do not rewrite README.md and doc/validation.md")
    return p.parse_args(argv)


def group_of(index: int, ncam: int) -> str:
    """A or B: blocks of ncam poses alternately (pose i was drawn for camera i % ncam)"""
    return "AB"[(index // ncam) % 2]


def simulate(a, out: str) -> tuple[str, int]:
    """Steps 1-3: pattern, the rig's dataset, the two groups as folders of links; (seq, ncam)"""
    pat, seq = os.path.join(out, "pattern"), os.path.join(out, "seq")
    run(["rotstar-pattern", "--out", short_path(pat)], stdout=subprocess.DEVNULL)
    cmd = ["rotstar-simulate", "--rig", "d435", "--poses", str(a.poses), "--seed", str(a.seed), "--pattern",
           short_path(pat), "--supersample", str(SUPERSAMPLE), "--seidel", LENS, "--glass", f"{a.glass:g}",
           "--jobs", str(a.jobs), "--out", short_path(seq)]
    run(cmd + (["--rgb"] if a.rgb else []), stdout=subprocess.DEVNULL)
    ncam = 3 if a.rgb else 2
    poses = sorted(p for p in os.listdir(seq) if p.startswith("pose"))
    for g in "AB":
        gdir = os.path.join(out, g)
        os.makedirs(gdir)
        shutil.copy(os.path.join(seq, "pattern.json"), gdir)
        for i, p in enumerate(poses):
            if group_of(i, ncam) == g:
                os.symlink(os.path.join("..", "seq", p), os.path.join(gdir, p))
    log(f"groups: A {sum(group_of(i, ncam) == 'A' for i in range(len(poses)))} poses, "
        f"B {sum(group_of(i, ncam) == 'B' for i in range(len(poses)))} (blocks of {ncam})")
    return seq, ncam


def calibrate(a, out: str, ncam: int) -> dict:
    """Step 4: {method: {group: (camera models)}}, and each method's corners files"""
    cals, vnls = {}, {}
    for m in METHODS:
        for g in "AB":
            gdir = os.path.join(out, g)
            vnl = os.path.join(gdir, f"{m}.vnl")
            run(["rotstar-detect", short_path(gdir), "--method", m, "--jobs", str(a.jobs), "--quiet", "-o",
                 short_path(vnl)])
            cdir = os.path.join(out, "cal", m, g)
            run(["rotstar-calibrate", short_path(gdir), "--corners", short_path(vnl), "--lensmodel", LENSMODEL,
                 "--outdir", short_path(cdir)], stdout=subprocess.DEVNULL)
            cals.setdefault(m, {})[g] = [os.path.join(cdir, f"camera-{k}.cameramodel") for k in range(ncam)]
            vnls.setdefault(m, []).append(vnl)
    return cals, vnls


def corner_rms(vnls, truth, glass_mm: float = 0.0) -> float:
    """RMS (per coordinate, px) of a method's corners against the true projections, over its corners files

    Through a cover glass the true projection is the refracted one (where the
    emitting point is seen through the glass; rotstar_lab.benchmark.glass).
    """
    lay = truth.layout
    d = []
    for vnl in vnls:
        with open(vnl) as f:
            found = read_corners(f, lay.nx, lay.ny)
        for fn, q in found.items():
            pose, k = pose_of_path(fn, set(truth.corners)), camera_of(fn)
            if q is not None and pose and k in truth.corners[pose]:
                true = truth.corners[pose][k]
                if glass_mm:
                    rt = mrcal.compose_rt(truth.models[k].extrinsics_rt_fromref(), truth.rt_ref_board[pose])
                    true = observed_corners(truth.models[k], lay, rt[None], Glass.mm(glass_mm))[0]
                d.append((q - true).reshape(-1, 2))
    d = np.concatenate(d)
    return float(np.sqrt(np.nanmean(d**2)))


def glass_effect(files: list, truth, glass_mm: float) -> dict:
    """What rotstar-calibrate found about the glass in one calibration (its calibration.json); the plain joint
    solve before the correction (candidates/rig/), it corrected for the known glass_mm ("known": what
    rotstar-calibrate --glass MM writes, calibrate.glass.correct_glass on the same solve) and its same-noise
    reference (the glass-free solve with the calibration's own corner errors, rotstar_lab.benchmark.glassrender)
    against the truth"""
    cdir = os.path.dirname(files[0])
    with open(os.path.join(cdir, "calibration.json")) as f:
        g = json.load(f).get("glass") or {}
    plain = [mrcal.cameramodel(os.path.join(cdir, "candidates", "rig", os.path.basename(fn))) for fn in files[:2]]
    oi = plain[0].optimization_inputs()
    rts = {(p, k): mrcal.compose_rt(m.extrinsics_rt_fromref(), rt)
           for p, rt in truth.rt_ref_board.items() for k, m in enumerate(truth.models)}
    ref, _ = same_noise_reference(oi, *true_grids(truth.models, truth.layout, rts, Glass.mm(glass_mm), oi))
    reference = [mrcal.cameramodel(optimization_inputs=ref, icam_intrinsics=k) for k in range(len(plain))]
    known = correct_glass(plain[0], glass_mm).models(plain) if glass_mm else None  # rotstar-calibrate --glass MM
    return {**{k: g.get(k) for k in ("thickness_mm", "sigma_mm", "applied", "reason")},
            "plain": stereo.pair_truth_error(plain, truth.models[:2], truth.rt_ref_board),
            "reference": stereo.pair_truth_error(reference, truth.models[:2], truth.rt_ref_board),
            "known": known and {"thickness_mm": glass_mm,
                                **stereo.pair_truth_error(known, truth.models[:2], truth.rt_ref_board)}}


def evaluate(a, out: str, seq: str, cals: dict, vnls: dict) -> dict:
    """Step 5: the rotstar-stereo/1 results"""
    truth = load_rig_truth(seq)
    true = tuple(truth.models[:2])
    lay = truth.layout
    pts = depth.heldout_points(true, lay.spacing_m, lay.nx, lay.ny)
    methods = []
    for m, groups in cals.items():
        t = time.monotonic()
        models = {g: [mrcal.cameramodel(f) for f in files] for g, files in groups.items()}
        noise = corner_rms(vnls[m], truth, a.glass)
        r = stereo.evaluate(m, {g: tuple(v[:2]) for g, v in models.items()}, true, truth.rt_ref_board, pts,
                            noise_px=noise, seed=a.seed)
        r["corner_rms_px"] = noise
        r["glass"] = {g: glass_effect(files, truth, a.glass) for g, files in groups.items()}
        for g, v in models.items():  # the colour camera (--rgb): against its truth too
            for k in range(2, len(v)):
                r["truth"][g]["cameras"].append(
                    stereo.camera_truth_error(v[k], truth.models[k], truth.rt_ref_board).summary())
        methods.append(r)
        log(f"evaluated {m} ({time.monotonic() - t:.0f} s)")
    nA = len([p for p in os.listdir(os.path.join(out, "A")) if p.startswith("pose")])
    nB = len([p for p in os.listdir(os.path.join(out, "B")) if p.startswith("pose")])
    e = stereo.extrinsics_error(true, true)
    setup = (f"Simulated Intel RealSense D435 (rotstar-simulate --rig d435 --seidel {LENS}{' --rgb' if a.rgb else ''}, "
             f"seed {a.seed}): two infrared imagers 1280x800, camera 1 {e.baseline_true_mm:.1f} mm to the right of "
             f"camera 0 with a lens and a small rotation of its own{'; the colour camera as camera 2' if a.rgb else ''}; "
             "every camera through make demo's lens (Seidel coma 1.5 and focus 0.3 waves at the image corners, "
             "its centroid on the chief ray; the right imager's x0.9, the colour camera's x1.1). "
             + (f"The screen's pixels lie under {a.glass:g} mm of cover glass (index 1.5; rotstar-simulate --glass): "
                "every ray is refracted on its way to them, and rotstar-calibrate estimates the thickness and "
                "takes it out when the estimate is a plausible glass; the known thickness (rotstar-calibrate "
                f"--glass {a.glass:g}) is applied beside it. " if a.glass else "The screen has no cover glass. ") +
             f"{a.poses} board poses (iPad, 14 x 9 corners, 0.3-0.6 m) split into groups A ({nA} poses) and "
             f"B ({nB}); each group calibrated jointly with mrcal ({LENSMODEL}) from rotstar's corners and from "
             "the saddle fit's (the best checkerboard detector of the demo) of the same poses. Held-out boards "
             f"for the depth error: {', '.join(str(len(v)) for v in pts.values())} boards at "
             f"{', '.join(f'{z:g}' for z in pts)} m, 20 degrees of tilt, over the field of view both cameras "
             "share.")
    return {"format": "rotstar-stereo/1", "label": "simulated D435 infrared pair", "setup": setup,
            "distances": sorted(pts), "seed": a.seed, "poses": a.poses, "rgb": a.rgb, "glass_mm": a.glass,
            "methods": methods}


def write_docs(result: dict, seconds: float) -> None:
    """The tables into doc/validation.md (stereo:tables), the headline into README.md (stereo:headline) and
    the run's wall time (seconds) and cores under it (stereo:time)"""
    said = "\n".join(f"- {v}" for v in stereoreport.verdicts(result))
    full = said + "\n\n" + "\n".join(f"**{title}**\n\n{t.markdown()}\n\n*{t.caption}*\n"
                                      for title, t in stereoreport.tables(result))
    short = stereoreport.headline(result).markdown() + "\n\n" + said
    for path, name, text in ((os.path.join(ROOT, "doc", "validation.md"), "stereo:tables", full),
                             (os.path.join(ROOT, "README.md"), "stereo:headline", short),
                             (os.path.join(ROOT, "README.md"), "stereo:time", wall_time_note(seconds, os.cpu_count() or 1))):
        if rewrite_block(path, name, text):
            log(f"rewrote the block {name} of {os.path.relpath(path, ROOT)}")


def main(argv=None) -> int:
    a = parse_args(argv)
    full = a.poses is None
    if a.poses is None:
        a.poses = DEFAULT_POSES * 3 // 2 if a.rgb else DEFAULT_POSES
        if a.quick:  # the colour camera needs its >= 4 boards in each group: 5 of 30
            a.poses = 30 if a.rgb else a.poses // 2
    signal.signal(signal.SIGTERM, lambda signum, frame: sys.exit(128 + signum))
    t0 = time.monotonic()
    out = os.path.abspath(a.out)
    for sub in ("pattern", "seq", "A", "B", "cal", "stereo", "report"):  # a previous run's
        shutil.rmtree(os.path.join(out, sub), ignore_errors=True)
    os.makedirs(out, exist_ok=True)
    clock = start_clock(os.path.join(out, ".steps-quick.json" if a.quick else ".steps.json"))  # (time left)
    seq, ncam = simulate(a, out)
    cals, vnls = calibrate(a, out, ncam)
    result = evaluate(a, out, seq, cals, vnls)
    sdir = os.path.join(out, "stereo")
    os.makedirs(sdir, exist_ok=True)
    with open(os.path.join(sdir, "results.json"), "w") as f:
        json.dump(result, f, indent=1)
    rep = os.path.join(out, "report")
    run(["rotstar-report", short_path(sdir), "--out", short_path(rep), "--no-mrcal-figures",
         "--title", "rotstar-mrcal stereo: a simulated D435 pair calibrated twice, against the truth and in depth"],
        stdout=subprocess.DEVNULL)

    print(f"rotstar-mrcal stereo ({time.monotonic() - t0:.0f} s): report {os.path.join(rep, 'index.html')} "
          "(also index.md)")
    print()
    print(stereoreport.section(result))
    if not (a.no_docs or a.quick or a.rgb or a.seed != DEFAULT_SEED or a.glass != GLASS_MM or not full):
        write_docs(result, clock.elapsed())
    clock.finish()
    return 0


if __name__ == "__main__":
    sys.exit(main())

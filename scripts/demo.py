#!/usr/bin/env python3
"""make demo: the paper's real-world experiment on a simulated D435, validated with mrcal

SYNOPSIS

    python scripts/demo.py --out demo-out          # what `make demo` runs (~5 min on 2 cores)
    python scripts/demo.py --out /tmp/d --quick    # fewer poses, for a smoke run

The set-up (camera, coma, pose groups, exposures) is rotstar_lab.demo.scene;
the methods are rotstar_mrcal.peers.registry' with demo=True. The chain, each step
printed before it runs:

1. rotstar-pattern (the screen's frames and pattern.json);
2. rendering and detection (here, in --jobs processes, rotstar_lab.demo.capture):
   every method on every pose and exposure, written as corners.vnl files next
   to each group's truth; OpenCV's ChArUco detector on a ChArUco board whose
   corners are the grid's (pattern.charuco), at the same poses; mrgingham on
   a square 9 x 9 checkerboard seen from the same poses;
3. rotstar-crossval per exposure: every corner set calibrated on A and on B
   with mrcal-calibrate-cameras, tested both ways (held-out MRE),
   cross-validated (projection diff vs uncertainty) and compared with the
   true camera;
4. rotstar-report over the three exposures;
5. the screen's cover glass (scene.GLASS_MM, every capture rendered through
   it): rotstar-crossval --glass corrects every calibration for the known
   thickness (the models the report tests) and keeps the plain ones' error
   against the truth; at GLASS_EXPOSURE each plain calibration also
   estimates the thickness (rotstar_lab.demo.glass): OUT/glass.md.

The pattern is the paper's whole sequence (rotstar-pattern --paper-sequence),
so the phase-shift and star methods run beside rotstar and the checkerboard
ones. The report's path, its headline table and the paper's claims as
verdicts (rotstar_lab.claims, added to the report's pages by
add_claims) are printed at the end (stdout); a
full run (not --quick, seed 1) also writes the table and the verdict lines
into the marked blocks of README.md, and the table, the error by tilt of the
test poses and every claim with its numbers into doc/validation.md
(--no-docs: not). The images are not kept
(3 exposures x 18 poses x 31 frames of 16-bit PNG would be several GB);
--keep-images writes them as rotstar datasets.
"""

from __future__ import annotations

import os

# one BLAS thread per process: the work is spread over processes, and
# OpenBLAS threads spinning on the same cores made small SVDs 50x slower here
for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import re  # noqa: E402
import shutil  # noqa: E402
import signal  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

from rotstar_lab import claims  # noqa: E402
from rotstar_lab.demo import capture, glass, plots, scene, sets  # noqa: E402
from rotstar_lab.demo.scene import EXPOSURES, exposure_dir  # noqa: E402
from rotstar_lab.docblock import rewrite_block  # noqa: E402
from rotstar_lab.steps import log, run_step, short_path, start_clock, wall_time_note  # noqa: E402
from rotstar_mrcal.peers.registry import Found, method_names, pooled  # noqa: E402
from rotstar_mrcal.simulate.poses import centred_pose  # noqa: E402


def run(cmd, **kw):
    """A step of make demo (rotstar_lab.steps.run_step)"""
    return run_step(cmd, "demo", **kw)


ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEFAULT_SEED = 1
GLASS_EXPOSURE = "4000 us"  # the exposure whose calibrations estimate the cover glass (glass_section)


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="demo-out", help="output folder (default demo-out)")
    p.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="parallel processes")
    p.add_argument("--seed", type=int, default=DEFAULT_SEED, help=f"noise seed (default {DEFAULT_SEED})")
    p.add_argument("--quick", action="store_true", help="two turn angles per place instead of three (smoke run)")
    p.add_argument("--keep-images", action="store_true", help="also write every frame (16-bit PNG, several GB)")
    p.add_argument("--no-docs", action="store_true", help="do not rewrite README.md and doc/validation.md")
    return p.parse_args(argv)


def corner_sets(a, out: str) -> tuple[dict, dict]:
    """Steps 1-2: the pattern, every pose rendered and detected; ({exposure: {method: {group: vnl}}}, crops)"""
    pat = os.path.join(out, "pattern")
    run(["rotstar-pattern", "--paper-sequence", "--out", pat], stdout=subprocess.DEVNULL)
    model, layout, square = scene.camera_and_boards(pat)
    rts = scene.group_poses(model, layout, scene.TILTS[::2] if a.quick else scene.TILTS)
    rts_sq = {g: centred_pose(v, layout, square) for g, v in rts.items()}
    npose = {g: len(v) for g, v in rts.items()}
    methods = method_names(needs=("rotstar", "checkerboard", "phase", "star"), demo=True)
    log(f"rendering {sum(npose.values())} poses once, exposing and detecting at {len(scene.EXPOSURES)} exposures "
        f"({', '.join(methods)}, ChArUco) in {a.jobs} processes")
    res = capture.capture_all(a.jobs, layout, square, model, rts, rts_sq, a.seed, out, a.keep_images, methods, log,
                              charuco=True)
    found = {}
    for label, _ in scene.EXPOSURES:
        for g in rts:
            per = {m: [res[(g, i)].found[label][m][:2] for i in range(npose[g])] for m in methods + ["charuco"]}
            for m in methods:  # a group is one dataset: psf-sim pools the coma over its poses, as rotstar-detect
                got = pooled(m, layout, [Found(*res[(g, i)].found[label][m][:3], pose=res[(g, i)].found[label][m][3])
                                         for i in range(npose[g])])
                per[m] = [(f.corners, f.weights) for f in got]
            edir = scene.exposure_dir(out, label)
            for m, vnl in sets.write_group(edir, g, layout, model, rts[g], per, square, rts_sq[g]).items():
                found.setdefault(label, {}).setdefault(m, {})[g] = vnl
    if shutil.which("mrgingham"):
        for name in method_names(needs="square", demo=True):
            for (label, g), vnl in sets.program_sets(out, npose, name, log).items():
                found[label].setdefault(name, {})[g] = vnl
    else:
        log("demo: mrgingham not installed; its baseline is left out")
    crops = res[("B", 0)].crops
    if crops:
        plots.exposure_figure(crops, os.path.join(out, "exposures.png"))
    with open(os.path.join(out, "setup.md"), "w") as f:
        f.write(scene.setup_notes(npose, scene.reach_px(model, layout, rts)))
        f.write(scene.rejection_notes({label: [r.rejected.get(label, {}) for r in res.values()]
                                       for label, _ in scene.EXPOSURES}))
    return found, crops


def crossval_and_report(a, out: str, found: dict, crops: dict) -> tuple[str, str]:
    """Steps 3-4: rotstar-crossval per exposure, rotstar-report over them; (report folder, its headline)"""
    xdirs = []
    for label, _ in scene.EXPOSURES:
        xdir = os.path.join(scene.exposure_dir(out, label), "xval")
        cmd = ["rotstar-crossval", "--lensmodel", scene.LENSMODEL, "--label", label, "--outdir", short_path(xdir),
               "--jobs", str(a.jobs), "--glass", f"{scene.GLASS_MM:g}", "--glass-index", f"{scene.GLASS_INDEX:g}"]
        for m, v in found[label].items():
            cmd += ["--set", m, short_path(v["A"]), short_path(v["B"])]
        run(cmd, stdout=subprocess.DEVNULL)
        xdirs.append(xdir)
    rep = os.path.join(out, "report")
    cmd = ["rotstar-report", *[short_path(x) for x in xdirs], "--out", short_path(rep),
           "--title", "rotstar-mrcal demo: simulated D435 with coma, two pose groups, three exposures",
           "--notes", short_path(os.path.join(out, "setup.md"))]
    if crops:
        cmd += ["--figure", short_path(os.path.join(out, "exposures.png"))
                + ":Close-ups of one corner near the image corner at the three exposures"]
    run(cmd, stdout=subprocess.PIPE, text=True)  # (its headline, without the claims: read below)
    return rep, add_claims(rep)


def glass_section(out: str) -> str:
    """Step 5: the cover glass at GLASS_EXPOSURE, each plain calibration's thickness estimated
    (rotstar_lab.demo.glass); Markdown (the table, its caption and rotstar's sentence), also OUT/glass.md"""
    xdir = os.path.join(exposure_dir(out, GLASS_EXPOSURE), "xval")
    with open(os.path.join(xdir, "results.json")) as f:
        res = json.load(f)
    log(f"estimating the cover glass from each plain calibration at {GLASS_EXPOSURE} (rotstar_lab.demo.glass)")
    est = glass.estimates(res, xdir, log)
    t = glass.table(res, est)
    text = f"{t.markdown()}\n\n*{t.caption}*\n\n{glass.summary(res, est)}\n"
    with open(os.path.join(out, "glass.md"), "w") as f:
        f.write(text)
    return text


def add_claims(rep: str) -> str:
    """The paper's claims (rotstar_lab.claims) into the report folder REP that rotstar-report wrote: its pages,
    paper.md and headline.md; returns headline.md"""
    # (here, not at the top: report.folder brings matplotlib.pyplot, 1.8-3.5 s measured with python -X importtime,
    # into every worker process, which imports this script as __mp_main__)
    from rotstar_mrcal.report.folder import add_sections

    with open(os.path.join(rep, "results.json")) as f:
        sec = claims.section(json.load(f)["conditions"])
    if sec is not None:
        add_sections(rep, [sec])
        log(f"added the paper's claims to {short_path(rep)} (rotstar_lab.claims)")
    with open(os.path.join(rep, "headline.md")) as f:
        return f.read()


def write_docs(headline: str, rep: str, seconds: float, glass_md: str) -> None:
    """The headline table into the marked blocks of README.md and doc/validation.md; the report's verdicts
    and the paper's claims in short into README.md (demo:claims), whole with the table by tilt (the report's paper.md) into
    doc/validation.md (demo:paper); the report's figure against the truth as doc/img/demo-vs-truth.png; the run's
    wall time (seconds) and cores into README.md (demo:time); the cover glass's table (glass_section) into
    README.md and doc/simulator.md (demo:glass)"""
    lines = headline.splitlines()
    table = "\n".join(line for line in lines if line.startswith("|"))
    claims = "\n".join([line for line in lines if line.startswith("- ")] + [""]
                       + [line for line in lines if re.match(r"\d+\. ", line)])
    with open(os.path.join(rep, "paper.md")) as f:
        paper = f.read().replace("## ", "### ")  # sections below doc/validation.md's "The demo"
    readme, validation = os.path.join(ROOT, "README.md"), os.path.join(ROOT, "doc", "validation.md")
    for path, name, text in ((readme, "demo:headline", table), (validation, "demo:headline", table),
                             (readme, "demo:claims", claims), (validation, "demo:paper", paper),
                             (readme, "demo:time", wall_time_note(seconds, os.cpu_count() or 1)),
                             (readme, "demo:glass", glass_md),
                             (os.path.join(ROOT, "doc", "simulator.md"), "demo:glass", glass_md)):
        if rewrite_block(path, name, text):
            log(f"rewrote the block {name} of {os.path.relpath(path)}")
    fig = os.path.join(ROOT, "doc", "img", "demo-vs-truth.png")  # README's figure: the report's, redrawn
    shutil.copyfile(os.path.join(rep, "summary-truth.png"), fig)
    log(f"wrote {os.path.relpath(fig)}")


def main(argv=None) -> int:
    a = parse_args(argv)
    signal.signal(signal.SIGTERM, lambda signum, frame: sys.exit(128 + signum))  # workers stopped on the way out

    t0 = time.monotonic()
    out = os.path.abspath(a.out)
    os.makedirs(out, exist_ok=True)
    clock = start_clock(os.path.join(out, ".steps-quick.json" if a.quick else ".steps.json"))  # (time left)
    for k, _ in EXPOSURES:  # a previous run's square-board images would be read by mrgingham again
        shutil.rmtree(exposure_dir(out, k), ignore_errors=True)
    found, crops = corner_sets(a, out)
    rep, headline = crossval_and_report(a, out, found, crops)
    glass_md = glass_section(out)
    print()
    print(f"rotstar-mrcal demo ({time.monotonic() - t0:.0f} s): report {os.path.join(rep, 'index.html')} "
          f"(also index.md)")
    print()
    print(headline.rstrip())
    print()
    print(glass_md.rstrip())
    if not (a.no_docs or a.quick or a.seed != DEFAULT_SEED):
        write_docs(headline, rep, clock.elapsed(), glass_md)
    clock.finish()
    return 0


if __name__ == "__main__":
    sys.exit(main())

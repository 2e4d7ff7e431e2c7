#!/usr/bin/env python3
"""make bench: corner accuracy and speed of rotstar against OpenCV and mrgingham

SYNOPSIS

    python scripts/bench.py                 # 20 poses, 16-bit, results in bench-out/
    python scripts/bench.py --quick         # 4 poses, a smoke run
    python scripts/bench.py --poses 40 --bits 8 --jobs 2 --out /tmp/b

Prints one Markdown table (stdout) with the goals evaluated beneath it; writes
bench.json, bench.md and error-cdf.png into --out. Progress goes to stderr.
A run with the documented settings (20 poses, seed 0, 16-bit) also rewrites
the marked blocks of doc/benchmark.md and README.md (--no-docs: not).

The scene, the methods, the scoring, the timing and the memory are the
package's: rotstar_mrcal.benchmark (scene, detection, scoring, timing,
memory, calibration, tables, plots) over rotstar_mrcal.methods. See
doc/benchmark.md.
"""

from __future__ import annotations

# One BLAS thread: the detectors are timed on one core, and BLAS threads
# spinning on that same core would only slow them down.  Set before numpy loads.
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import datetime  # noqa: E402
import json  # noqa: E402
import shutil  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

from rotstar_mrcal.benchmark import calibration, detection, scene as scenes, scoring, tables  # noqa: E402
from rotstar_mrcal.benchmark.plots import plot_cdf  # noqa: E402
from rotstar_mrcal.docblock import rewrite_block  # noqa: E402
from rotstar_mrcal.methods import METHODS  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOCUMENTED = {"poses": 20, "seed": 0, "bits": 16}  # the run doc/benchmark.md shows


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--poses", type=int, default=20, help="random poses (default 20)")
    p.add_argument("--quick", action="store_true", help="smoke run: 4 poses")
    p.add_argument("--seed", type=int, default=0, help="poses and noise (default 0)")
    p.add_argument("--bits", type=int, choices=(8, 16), default=16, help="image depth (default 16)")
    p.add_argument("--jobs", type=int, default=os.cpu_count() or 1,
                   help="processes for rendering only; detectors are always timed on one core (default: all cores)")
    p.add_argument("--out", default="bench-out", help="folder for bench.json, bench.md, error-cdf.png")
    p.add_argument("--no-docs", action="store_true", help="do not rewrite doc/benchmark.md and README.md")
    a = p.parse_args(argv)
    if a.quick:
        a.poses = 4
    if a.poses < 1:
        p.error("--poses must be at least 1")
    return a


def main(argv=None) -> int:
    a = parse_args(argv)
    t0 = time.perf_counter()
    started = datetime.datetime.now().astimezone()
    have_mrgingham = shutil.which("mrgingham") is not None
    if not have_mrgingham:
        log("note: mrgingham is not installed (Debian package 'mrgingham'); its rows are skipped")
    scene = scenes.make_scene(a.poses, a.seed, a.bits)
    poses = scenes.render_all(scene, max(1, a.jobs), log)
    t_render = time.perf_counter() - t0
    with tempfile.TemporaryDirectory(prefix="rotstar-bench-") as tmp:
        run = detection.detect_all(scene, poses, tmp, log)
        log("calibrating with mrcal from each method's boards")
        cal = calibration.calibrate_all(scene, run.labelled, run.weights, tmp, log)
    # ---- speed: rotstar_mrcal.benchmark.speed plugs in here; its Markdown goes into `sections` below ----
    speed_sections: list[str] = []

    results = run.results
    layouts = {k: scene.layout_for(METHODS[k].needs) for k in results}
    summary = {k: scoring.summarize(rows, layouts[k].nx * layouts[k].ny) for k, rows in results.items()}
    titles = {k: m.title for k, m in METHODS.items()}
    standalone = {k for k, m in METHODS.items() if m.start == "own"}
    g = scoring.goals(summary, results, titles, standalone)
    wall = time.perf_counter() - t0
    mach = tables.machine()
    tilts, dist = scene.tilts_deg(), scene.distances_m()

    tab, gl, cal_tab = tables.accuracy_table(summary, run.memory), tables.goal_lines(g), tables.calibration_table(cal)
    cal_title = (f"Calibration with mrcal ({calibration.CAL_LENSMODEL}) from each method's correct boards, "
                 "against the true camera over the imager (at infinity, board poses aligned with the true ones):")
    print("\n\n".join([tab, gl, *speed_sections, cal_title, cal_tab]))
    sys.stdout.flush()

    os.makedirs(a.out, exist_ok=True)
    when = (f"{started:%Y-%m-%d %H:%M %Z}, {mach['cpu']}, {mach['cores']} cores; wall time {wall:.0f} s "
            f"(rendering {t_render:.0f} s with {a.jobs} process(es))")
    sections = ["# rotstar-mrcal benchmark", tables.setup_line(scene, tilts, dist, scenes.CAPTURES), when, tab, gl,
                *speed_sections, cal_title, cal_tab,
                "Poses a method did not get complete and right:\n\n" + tables.failures(results),
                tables.notes(run.memory_pose, run.batch, a.poses, have_mrgingham)]
    with open(os.path.join(a.out, "bench.md"), "w") as f:
        f.write("\n\n".join(sections) + "\n")
    doc = {
        "format": "rotstar-bench/2",
        "date": started.isoformat(timespec="seconds"),
        "machine": mach,
        "wall_seconds": wall,
        "render_seconds": t_render,
        "config": {"poses": a.poses, "seed": a.seed, "bits": a.bits, "jobs": a.jobs, "camera": "d435",
                   "layout": [scene.layout.nx, scene.layout.ny], "square_layout": [scenes.SQUARE_N] * 2,
                   "settings": dataclasses.asdict(scene.settings), "captures_averaged": scenes.CAPTURES,
                   "match_px": scoring.MATCH_PX, "start_perturb_px": scoring.START_PERTURB_PX,
                   "timing_cpu": run.cpu, "memory_pose": run.memory_pose},
        "mrgingham_batch_seconds_per_image": run.batch,
        "poses": [{"pose": i, "rt_cam_board": rt.tolist(), "tilt_deg": float(t), "distance_m": float(d)}
                  for i, (rt, t, d) in enumerate(zip(scene.rts, tilts, dist))],
        "methods": {k: {"name": titles[k], "input": tables.input_text(k), **summary[k],
                        "memory": run.memory.get(k), "per_pose": results[k]} for k in results},
        "goals": g,
        "calibration": {"lensmodel": calibration.CAL_LENSMODEL, "methods": cal},
    }
    with open(os.path.join(a.out, "bench.json"), "w") as f:
        json.dump(doc, f, indent=1)
        f.write("\n")
    plot_cdf(results, titles, os.path.join(a.out, "error-cdf.png"))
    log(f"wrote {a.out}/bench.json, bench.md, error-cdf.png; wall time {wall:.0f} s")

    if not a.no_docs and {"poses": a.poses, "seed": a.seed, "bits": a.bits} == DOCUMENTED:
        run_line = tables.run_line(started, mach, scene, tilts, dist, wall, t_render, a.jobs)
        result = "\n\n".join([run_line, tab, gl, tables.batch_lines(run.batch, a.poses), *speed_sections])
        for path, name, text in ((os.path.join(ROOT, "doc", "benchmark.md"), "bench:result", result),
                                 (os.path.join(ROOT, "doc", "benchmark.md"), "bench:calibration", cal_tab),
                                 (os.path.join(ROOT, "README.md"), "bench:summary",
                                  tables.summary_sentence(summary, cal, a.poses))):
            if rewrite_block(path, name, text):
                log(f"rewrote the block {name} of {os.path.relpath(path)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

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
import datetime  # noqa: E402
import json  # noqa: E402
import shutil  # noqa: E402
import signal  # noqa: E402
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


def measure(a) -> dict:
    """Render, detect, calibrate, score: everything the outputs are made of"""
    t0 = time.perf_counter()
    started = datetime.datetime.now().astimezone()
    if shutil.which("mrgingham") is None:
        log("note: mrgingham is not installed (Debian package 'mrgingham'); its rows are skipped")
    scene = scenes.make_scene(a.poses, a.seed, a.bits)
    poses = scenes.render_all(scene, max(1, a.jobs), log)
    t_render = time.perf_counter() - t0
    with tempfile.TemporaryDirectory(prefix="rotstar-bench-") as tmp:
        run = detection.detect_all(scene, poses, tmp, log)
        log("calibrating with mrcal from each method's boards")
        cal = calibration.calibrate_all(scene, run.labelled, run.weights, tmp, log)
    # ---- speed: rotstar_mrcal.benchmark.speed plugs in here; its Markdown goes into m["speed"] ----
    speed: list[str] = []
    layouts = {k: scene.layout_for(METHODS[k].needs) for k in run.results}
    summary = {k: scoring.summarize(rows, layouts[k].nx * layouts[k].ny) for k, rows in run.results.items()}
    g = scoring.goals(summary, run.results, {k: m.title for k, m in METHODS.items()},
                      {k for k, m in METHODS.items() if m.start == "own"})
    return dict(scene=scene, run=run, cal=cal, summary=summary, goals=g, speed=speed, started=started,
                render=t_render, wall=time.perf_counter() - t0, machine=tables.machine())


def write_outputs(a, m: dict, text: dict) -> None:
    """bench.md, bench.json, error-cdf.png into a.out"""
    sc, run = m["scene"], m["run"]
    os.makedirs(a.out, exist_ok=True)
    when = (f"{m['started']:%Y-%m-%d %H:%M %Z}, {m['machine']['cpu']}, {m['machine']['cores']} cores; wall time "
            f"{m['wall']:.0f} s (rendering {m['render']:.0f} s with {a.jobs} process(es))")
    md = ["# rotstar-mrcal benchmark", tables.setup_line(sc, sc.tilts_deg(), sc.distances_m(), scenes.CAPTURES), when,
          text["table"], text["goals"], *m["speed"], text["cal_title"], text["cal_table"],
          "Poses a method did not get complete and right:\n\n" + tables.failures(run.results),
          tables.notes(run.memory_pose, run.batch, a.poses, "mrgingham" in run.results)]
    with open(os.path.join(a.out, "bench.md"), "w") as f:
        f.write("\n\n".join(md) + "\n")
    doc = tables.bench_json(m["started"], m["machine"], m["wall"], m["render"], a.jobs, sc, run, m["summary"],
                            m["goals"], m["cal"], calibration.CAL_LENSMODEL, scenes.CAPTURES)
    with open(os.path.join(a.out, "bench.json"), "w") as f:
        json.dump(doc, f, indent=1)
        f.write("\n")
    plot_cdf(run.results, {k: v.title for k, v in METHODS.items()}, os.path.join(a.out, "error-cdf.png"))
    log(f"wrote {a.out}/bench.json, bench.md, error-cdf.png; wall time {m['wall']:.0f} s")


def write_docs(a, m: dict, text: dict) -> None:
    """The marked blocks of doc/benchmark.md and README.md"""
    sc, run = m["scene"], m["run"]
    run_line = tables.run_line(m["started"], m["machine"], sc, sc.tilts_deg(), sc.distances_m(), m["wall"],
                               m["render"], a.jobs)
    result = "\n\n".join([run_line, text["table"], text["goals"], tables.batch_lines(run.batch, a.poses), *m["speed"]])
    bench_md, readme = os.path.join(ROOT, "doc", "benchmark.md"), os.path.join(ROOT, "README.md")
    for path, name, block in ((bench_md, "bench:result", result), (bench_md, "bench:calibration", text["cal_table"]),
                              (readme, "bench:summary", tables.summary_sentence(m["summary"], m["cal"], a.poses))):
        if rewrite_block(path, name, block):
            log(f"rewrote the block {name} of {os.path.relpath(path)}")


def main(argv=None) -> int:
    a = parse_args(argv)
    signal.signal(signal.SIGTERM, lambda signum, frame: sys.exit(128 + signum))  # workers stopped on the way out
    m = measure(a)
    text = {"table": tables.accuracy_table(m["summary"], m["run"].memory), "goals": tables.goal_lines(m["goals"]),
            "cal_title": f"Calibration with mrcal ({calibration.CAL_LENSMODEL}) from each method's correct boards, "
                         "against the true camera over the imager (at infinity, board poses aligned with the true "
                         "ones):",
            "cal_table": tables.calibration_table(m["cal"])}
    print("\n\n".join([text["table"], text["goals"], *m["speed"], text["cal_title"], text["cal_table"]]))
    sys.stdout.flush()
    write_outputs(a, m, text)
    if not a.no_docs and {"poses": a.poses, "seed": a.seed, "bits": a.bits} == DOCUMENTED:
        write_docs(a, m, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())

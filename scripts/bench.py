#!/usr/bin/env python3
"""make bench: corner accuracy and speed of rotstar against OpenCV and mrgingham, and partial views

SYNOPSIS

    python scripts/bench.py                 # 20 poses, 16-bit, 234 partial views; results in bench-out/
    python scripts/bench.py --quick         # 4 poses, 9 partial views: a smoke run
    python scripts/bench.py --poses 40 --bits 8 --jobs 2 --out /tmp/b
    python scripts/bench.py --partial 0 --whole 0       # without the partial views
    python scripts/bench.py --poses 0 --partial 0 --whole 0 --failures 2    # the failure modes only

Prints the Markdown tables (stdout) with the goals evaluated beneath them;
writes bench.json, bench.md and error-cdf.png into --out. Progress goes to
stderr. A run with the documented settings (20 poses, seed 0, 16-bit, 34
hanging views per lens and condition, 10 whole boards per condition) also
rewrites the marked blocks of --doc (doc/benchmark.md; '' for none) and
README.md.

The scene, the methods, the scoring, the timing and the memory are the
package's; this script only strings them together:

    rotstar_mrcal.peers.registry          the corner methods (one registry)
    rotstar_lab.benchmark.scene        camera, layouts, poses; the rendered images of a pose
    rotstar_lab.benchmark.detection    every method on every pose, timed on one CPU, scored
    rotstar_lab.benchmark.scoring      a board against the truth, per-pose rows, summaries, goals
    rotstar_lab.benchmark.timing       one pinned CPU, CPU and wall time of a call
    rotstar_lab.benchmark.memory       the peak memory of one call, in a fresh process
    rotstar_lab.benchmark.calibration  each method's boards calibrated with mrcal, against the truth
    rotstar_lab.benchmark.speed        decode and detect time per pose, start-up, mrgingham, profile
    rotstar_lab.benchmark.tables       the Markdown tables, bench.json, README's sentence
    rotstar_lab.benchmark.plots        the corner error CDF
    rotstar_lab.benchmark.partial      partial views: boards over the image's edges, rotstar against ChArUco
    rotstar_lab.benchmark.failures     each method's failure modes: saturation, gamma mismatch, tilt and roll, noise

See doc/benchmark.md.
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

from rotstar_lab.benchmark import calibration, detection, failures, partial, scene as scenes, scoring, tables  # noqa: E402
from rotstar_lab.benchmark.plots import plot_cdf  # noqa: E402
from rotstar_lab.docblock import rewrite_block  # noqa: E402
from rotstar_lab.benchmark import speed  # noqa: E402
from rotstar_mrcal.peers.registry import METHODS  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOCUMENTED = {"poses": 20, "seed": 0, "bits": 16, "partial": 34, "whole": 10}  # the run doc/benchmark.md shows
DOCUMENTED_FAILURES = {"failures": 2, "seed": 0}  # the failure-mode run it shows (its own block)


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--poses", type=int, default=20,
                   help="random poses (default 20; 0: no accuracy benchmark, only the failure modes)")
    p.add_argument("--quick", action="store_true", help="smoke run: 4 poses, --partial 1 --whole 1 --failures 1")
    p.add_argument("--partial", type=int, default=34,
                   help="partial views: boards hanging over the image's edges, per lens (2) and condition (3) "
                        "(default 34: 204 views; 0: none)")
    p.add_argument("--whole", type=int, default=10,
                   help="partial views' whole boards on the wide-angle lens at 30-65 degrees, per condition "
                        "(default 10)")
    p.add_argument("--failures", type=int, default=2,
                   help="failure modes: poses per condition (phase under saturation and display gamma mismatch, "
                        "the star under tilt and roll, noise; the same images for every method) "
                        "(default 2: 38 renders; 0: none)")
    p.add_argument("--seed", type=int, default=0, help="poses and noise (default 0)")
    p.add_argument("--bits", type=int, choices=(8, 16), default=16, help="image depth (default 16)")
    p.add_argument("--jobs", type=int, default=os.cpu_count() or 1,
                   help="processes for rendering (and the partial views' detection); the benchmark's detectors are "
                        "always timed on one core (default: all cores)")
    p.add_argument("--out", default="bench-out", help="folder for bench.json, bench.md, error-cdf.png")
    p.add_argument("--doc", default=os.path.join(ROOT, "doc", "benchmark.md"),
                   help="with the documented settings, rewrite the marked blocks of this file (results, "
                        "calibration, speed) and README.md's summary (default: doc/benchmark.md; '' for none)")
    a = p.parse_args(argv)
    if a.quick:
        a.poses, a.partial, a.whole, a.failures = 4, 1, 1, 1
    if a.poses < 0 or a.failures < 0:
        p.error("--poses and --failures must be at least 0")
    if a.partial < 0 or a.whole < 0:
        p.error("--partial and --whole must be at least 0")
    if a.poses == 0 and (a.partial or a.whole or not a.failures):
        p.error("--poses 0 runs the failure modes only: give --partial 0 --whole 0 and --failures N")
    return a


def measure_partial(a) -> dict | None:
    """The partial views (in --jobs processes, before the detectors are pinned to one CPU), or None"""
    if not (a.partial or a.whole):
        return None
    t0 = time.perf_counter()
    views = partial.make_views(a.partial, a.whole, a.seed)
    log(f"partial views: {len(views)} views, each rendered, exposed and detected by rotstar and ChArUco "
        f"({a.jobs} process(es)) ...")
    res = partial.run_views(views, a.seed, max(1, a.jobs), log=log)
    s = partial.summarize(res)
    log(f"partial views: {time.perf_counter() - t0:.0f} s")
    return {"results": res, "summary": s, "wall": time.perf_counter() - t0}


def partial_text(a, part: dict) -> str:
    """The partial-view section: set-up, the two tables, the goals, notes"""
    s = part["summary"]
    return "\n\n".join([partial.setup_line(a.partial, a.whole, a.seed),
                         "Boards hanging over the image's edges (in view: the corner's refinement window inside the "
                         "image; doc/benchmark.md, *Partial views*):",
                         partial.hanging_table(s), "Whole boards:", partial.whole_table(s), partial.goal_lines(s),
                         partial.notes(s)])


def measure(a) -> dict:
    """Render, detect, calibrate, score: everything the outputs are made of

    wall and render: the main benchmark's seconds, after the partial views (whose own are part['wall']).
    """
    started = datetime.datetime.now().astimezone()
    part = measure_partial(a)
    t0 = time.perf_counter()
    if shutil.which("mrgingham") is None:
        log("note: mrgingham is not installed (Debian package 'mrgingham'); its rows are skipped")
    scene = scenes.make_scene(a.poses, a.seed, a.bits)
    poses = scenes.render_all(scene, max(1, a.jobs), log)
    t_render = time.perf_counter() - t0
    with tempfile.TemporaryDirectory(prefix="rotstar-bench-") as tmp:
        run = detection.detect_all(scene, poses, tmp, log)
        log("calibrating with mrcal from each method's boards")
        cal = calibration.calibrate_all(scene, run.labelled, run.weights, tmp, log)
        speed_md, speed_run = speed.bench_speed(os.path.join(tmp, "speed-seq"), scene.layout,
                                                [(p.rotstar, p.checker, p.identity) for p in poses], a.bits, log=log)
    layouts = {k: scene.layout_for(METHODS[k].needs) for k in run.results}
    summary = {k: scoring.summarize(rows, layouts[k].nx * layouts[k].ny) for k, rows in run.results.items()}
    g = scoring.goals(summary, run.results, {k: m.title for k, m in METHODS.items()},
                      {k for k, m in METHODS.items() if m.start == "own"})
    return dict(scene=scene, run=run, cal=cal, summary=summary, goals=g, speed=[speed_md] if speed_md else [],
                speed_run=speed_run, started=started, partial=part,
                render=t_render, wall=time.perf_counter() - t0, machine=tables.machine())


def write_outputs(a, m: dict, text: dict) -> None:
    """bench.md, bench.json, error-cdf.png into a.out"""
    sc, run = m["scene"], m["run"]
    os.makedirs(a.out, exist_ok=True)
    when = (f"{m['started']:%Y-%m-%d %H:%M %Z}, {m['machine']['cpu']}, {m['machine']['cores']} cores; wall time "
            f"{m['wall']:.0f} s (rendering {m['render']:.0f} s with {a.jobs} process(es))")
    md = ["# rotstar-mrcal benchmark", tables.setup_line(sc, sc.tilts_deg(), sc.distances_m(), scenes.CAPTURES), when,
          text["table"], text["goals"], text["cal_title"], text["cal_table"],
          "Poses a method did not get complete and right:\n\n" + tables.failures(run.results),
          tables.notes(run.memory_pose, run.batch, a.poses, "mrgingham" in run.results), *m["speed"]]
    if m["partial"]:
        md += ["## Partial views", text["partial"]]
    with open(os.path.join(a.out, "bench.md"), "w") as f:
        f.write("\n\n".join(md) + "\n")
    doc = tables.bench_json(m["started"], m["machine"], m["wall"], m["render"], a.jobs, sc, run, m["summary"],
                            m["goals"], m["cal"], calibration.CAL_LENSMODEL, scenes.CAPTURES)
    if m["speed_run"] is not None:
        doc["speed"] = m["speed_run"]
    if m["partial"]:
        doc["partial"] = partial.to_dict(m["partial"]["results"], m["partial"]["summary"]) | {
            "settings": {"partial": a.partial, "whole": a.whole, "seed": a.seed}, "wall_s": m["partial"]["wall"]}
    with open(os.path.join(a.out, "bench.json"), "w") as f:
        json.dump(doc, f, indent=1)
        f.write("\n")
    plot_cdf(run.results, {k: v.title for k, v in METHODS.items()}, os.path.join(a.out, "error-cdf.png"))
    log(f"wrote {a.out}/bench.json, bench.md, error-cdf.png; wall time {m['wall']:.0f} s")


def write_docs(a, m: dict, text: dict) -> None:
    """The marked blocks of --doc (result, calibration, speed) and README.md (summary)"""
    sc, run = m["scene"], m["run"]
    tilts, dist = sc.tilts_deg(), sc.distances_m()
    run_line = tables.run_line(m["started"], m["machine"], sc, tilts, dist, m["wall"], m["render"], a.jobs)
    result = "\n\n".join([run_line, text["table"], text["goals"], tables.batch_lines(run.batch, a.poses)])
    blocks = [(a.doc, "bench:result", result), (a.doc, "bench:calibration", text["cal_table"]),
              (os.path.join(ROOT, "README.md"), "bench:summary", tables.summary_sentence(m["summary"], m["cal"],
                                                                                          a.poses))]
    if m["partial"]:
        when = f"{m['started']:%Y-%m-%d %H:%M %Z}, {m['machine']['cpu']}, {m['machine']['cores']} cores"
        blocks += [(a.doc, "bench:partial", f"{when}; wall time {m['partial']['wall']:.0f} s with {a.jobs} "
                                            f"process(es).\n\n{text['partial']}"),
                   (os.path.join(ROOT, "README.md"), "bench:partial",
                    partial.summary_sentence(m["partial"]["summary"]))]
    if m["speed"]:
        when = f"{m['started']:%Y-%m-%d %H:%M %Z}, {m['machine']['cpu']}, {m['machine']['cores']} cores"
        setup = tables.setup_line(sc, tilts, dist, scenes.CAPTURES)
        blocks.append((a.doc, "speed", f"{setup}.\n\n{when}.\n\n{m['speed'][0]}"))
    for path, name, block in blocks:
        if rewrite_block(path, name, block):
            log(f"rewrote the block {name} of {os.path.relpath(path)}")


def measure_failures(a) -> dict | None:
    """The failure modes (in --jobs processes, before the detectors are pinned to one CPU), or None"""
    if not a.failures:
        return None
    t0 = time.perf_counter()
    started = datetime.datetime.now().astimezone()
    units = failures.make_units(a.failures, a.seed)
    log(f"failure modes: {len(units)} renders of the paper's sequence through make demo's lens, each exposed and "
        f"detected by every method of its table ({a.jobs} process(es)) ...")
    s = failures.summarize(failures.run_units(units, max(1, a.jobs), a.seed, log=log))
    wall = time.perf_counter() - t0
    log(f"failure modes: {wall:.0f} s")
    return {"summary": s, "wall": wall, "started": started, "machine": tables.machine(),
            "text": failures.text(s, a.failures, a.seed)}


def write_failures(a, f: dict) -> None:
    """failures.md and failures.json into a.out; with the documented settings, the blocks bench:failures"""
    os.makedirs(a.out, exist_ok=True)
    when = (f"{f['started']:%Y-%m-%d %H:%M %Z}, {f['machine']['cpu']}, {f['machine']['cores']} cores; wall time "
            f"{f['wall']:.0f} s with {a.jobs} process(es).")
    with open(os.path.join(a.out, "failures.md"), "w") as fh:
        fh.write(f"# Failure modes\n\n{when}\n\n{f['text']}\n")
    with open(os.path.join(a.out, "failures.json"), "w") as fh:
        json.dump({"settings": {"failures": a.failures, "seed": a.seed}, "wall_s": f["wall"], "jobs": a.jobs,
                   "summary": f["summary"]}, fh, indent=1)
        fh.write("\n")
    log(f"wrote {a.out}/failures.md, failures.json")
    if a.doc and {"failures": a.failures, "seed": a.seed} == DOCUMENTED_FAILURES:
        for path, name, block in ((a.doc, "bench:failures", f"{when}\n\n{f['text']}"),
                                  (os.path.join(ROOT, "README.md"), "bench:failures",
                                   failures.readme_line(f["summary"]))):
            if rewrite_block(path, name, block):
                log(f"rewrote the block {name} of {os.path.relpath(path)}")


def main(argv=None) -> int:
    a = parse_args(argv)
    signal.signal(signal.SIGTERM, lambda signum, frame: sys.exit(128 + signum))  # workers stopped on the way out
    fails = measure_failures(a)
    if fails:
        print(f"## Failure modes\n\n{fails['text']}\n")
        sys.stdout.flush()
        write_failures(a, fails)
    if not a.poses:
        return 0
    m = measure(a)
    text = {"table": tables.accuracy_table(m["summary"], m["run"].memory), "goals": tables.goal_lines(m["goals"]),
            "partial": partial_text(a, m["partial"]) if m["partial"] else "",
            "cal_title": f"Calibration with mrcal ({calibration.CAL_LENSMODEL}) from each method's correct boards, "
                         "against the true camera over the imager (at infinity, board poses aligned with the true "
                         "ones):",
            "cal_table": tables.calibration_table(m["cal"])}
    print("\n\n".join([text["table"], text["goals"], text["cal_title"], text["cal_table"], *m["speed"],
                       *(["## Partial views", text["partial"]] if m["partial"] else [])]))
    sys.stdout.flush()
    write_outputs(a, m, text)
    settings = {"poses": a.poses, "seed": a.seed, "bits": a.bits, "partial": a.partial, "whole": a.whole}
    if a.doc and settings == DOCUMENTED:
        write_docs(a, m, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())

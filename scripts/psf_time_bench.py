#!/usr/bin/env python3
"""Time per pose of rotstar-detect with --refine psf-sim against the symmetric fit (issue 24's 1.5 x)

SYNOPSIS

    python scripts/psf_time_bench.py blur-map-out/seq                 # 5 runs of each, alternating
    python scripts/psf_time_bench.py SEQ --runs 3 --doc doc/blur-map.md

Runs the whole command a user runs (`rotstar-detect SEQ -o FILE --jobs 1
--refine symmetric`, and the same with `--refine psf-sim`, the default) as
child processes pinned to one CPU with one BLAS thread, alternating the two
so that a slow spell of the machine falls on both; reads each child's CPU time (user + system,
getrusage) and prints a Markdown table: per method the median and the
least CPU seconds per pose, and the ratio of the medians. Every run starts
cold (psf-sim's kernels are computed in each run, as a user's are); the
interpreter's start-up and imports are in both. --doc rewrites the block
psf-time-bench of that file (make blur-map-doc does).
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

from rotstar_lab.docblock import rewrite_block

METHODS = (("rotstar-detect --refine symmetric (the paper's fit; the default before)", ["--refine", "symmetric"]),
           ("rotstar-detect --refine psf-sim (the default)", ["--refine", "psf-sim"]))


def child_cpu(cmd: list[str], env: dict) -> float:
    """CPU seconds (user + system) of one child run of cmd; raises with its stderr if it fails"""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    r = subprocess.run(cmd, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                       text=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode:
        raise RuntimeError(f"{' '.join(cmd)} exited {r.returncode}: {r.stderr.strip().splitlines()[-1:]}")
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def poses_in(seq: str) -> int:
    return sum(1 for d in os.listdir(seq) if os.path.isdir(os.path.join(seq, d)) and d.startswith("pose"))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("seq", help="a recording (rotstar-simulate's or rotstar-capture's folder)")
    p.add_argument("--runs", type=int, default=5, help="runs of each method (default 5)")
    p.add_argument("--cpu", type=int, default=None, help="the CPU to pin the runs to (default: the last one)")
    p.add_argument("--doc", default="", help="rewrite the psf-time-bench block of this Markdown file")
    a = p.parse_args(argv)
    if not os.path.isdir(a.seq) or not poses_in(a.seq):
        print(f"psf_time_bench: {a.seq}: not a recording (no pose folders)", file=sys.stderr)
        return 2
    n = poses_in(a.seq)
    exe = os.path.join(os.path.dirname(sys.executable), "rotstar-detect")
    cmd0 = [exe] if os.path.exists(exe) else [sys.executable, "-m", "rotstar_mrcal.cli.detect"]
    cpus = sorted(os.sched_getaffinity(0))
    cpu = cpus[-1] if a.cpu is None else a.cpu
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    pin = ["taskset", "-c", str(cpu)] if shutil.which("taskset") else []
    times: dict[str, list[float]] = {m: [] for m, _ in METHODS}
    t0 = time.monotonic()
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "corners.vnl")
        for r in range(a.runs):
            for m, extra in (METHODS if r % 2 == 0 else METHODS[::-1]):
                times[m].append(child_cpu(pin + cmd0 + [a.seq, "-o", out, "--jobs", "1"] + extra, env) / n)
            done = (r + 1) / a.runs
            el = time.monotonic() - t0
            print(f"psf_time_bench: run {r + 1}/{a.runs}, {el:.0f} s, about {el / done - el:.0f} s left",
                  file=sys.stderr)
    med = {m: statistics.median(v) for m, v in times.items()}
    base = med[METHODS[0][0]]
    lines = [f"CPU seconds per pose (user + system, one CPU, one BLAS thread; the whole command, start-up "
             f"included), {n} poses of `{os.path.basename(os.path.normpath(a.seq))}`, {a.runs} runs of each "
             f"(`python scripts/psf_time_bench.py SEQ --runs {a.runs}`):", "",
             "| command | median s per pose | least s per pose | median vs the symmetric fit |", "|---|---|---|---|"]
    for m, _ in METHODS:
        lines.append(f"| `{m}` | {med[m]:.3f} | {min(times[m]):.3f} | {med[m] / base:.2f} x |")
    text = "\n".join(lines)
    print(text)
    if a.doc:
        rewrite_block(a.doc, "psf-time-bench", text)
        print(f"psf_time_bench: rewrote the psf-time-bench block of {a.doc}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The peak memory of one call of a method, in a fresh process

SYNOPSIS

    mem = measure_memory({name: PoseImages(...), ...}, tmp)   # {method: {"mb": ..., ...}}

    python -m rotstar_lab.benchmark.memory METHOD INPUT.pickle  # the probe, one JSON line

For each method that runs in Python, a fresh process loads one pose, calls
the method once (warm-up), resets the peak-RSS mark (/proc/self/clear_refs)
and calls it again: peak RSS minus RSS before the call is the working memory
of one call, native (OpenCV) allocations included. glibc's mmap threshold is
fixed at 64 kB in that process (MALLOC_MMAP_THRESHOLD_) so that freed
buffers go back to the system and a call cannot hide in memory an earlier
call left behind. For a method that is a program (mrgingham): the peak RSS
of its whole process, from GNU time (/usr/bin/time -f %M); not os.wait4 on a
child of this process: a child forked from a big process starts with its
RSS, and ru_maxrss keeps that across exec.
"""

from __future__ import annotations

import json
import os
import pickle
import re
import shutil
import subprocess
import sys

from rotstar_lab.benchmark.timing import pin_one_cpu
from rotstar_mrcal.peers.registry import METHODS, PoseImages
from rotstar_mrcal.programs import run_tool

LAB_PATH = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
"""scripts/, where the probe's process finds rotstar_lab (the lab is not installed)"""


def proc_status_kb(key: str) -> int:
    with open("/proc/self/status") as f:
        return int(re.search(rf"^{key}:\s+(\d+)", f.read(), re.M).group(1))


def memory_probe(name: str, data: str) -> dict:
    """In this (fresh) process: the peak RSS one call of a method adds, after a warm-up call

    data: a pickle of the method's PoseImages (rotstar caches its detection in
    a PoseImages, so every call gets a fresh copy).
    """
    with open(data, "rb") as f:
        blob = f.read()
    m = METHODS[name]
    pin_one_cpu()
    m(pickle.loads(blob))
    p = pickle.loads(blob)
    before = proc_status_kb("VmRSS")
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")  # VmHWM := VmRSS
    m(p)
    peak = proc_status_kb("VmHWM")
    return {"rss_before_kb": before, "peak_kb": peak, "added_kb": peak - before}


def program_maxrss_kb(png: str, gridn: int, args: tuple, tmp: str) -> int | None:
    """Peak RSS of one mrgingham run, from GNU time (None if /usr/bin/time is missing)"""
    gnu_time = "/usr/bin/time"
    if not os.access(gnu_time, os.X_OK):
        return None
    fn = os.path.join(tmp, "maxrss.txt")
    r = run_tool([gnu_time, "-f", "%M", "-o", fn, shutil.which("mrgingham"), "--jobs", "1", "--gridn",
                        str(gridn), *args, png], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        with open(fn) as f:
            return int(f.read().split()[-1]) if r.returncode == 0 else None
    except (OSError, ValueError, IndexError):
        return None


def measure_memory(inputs: dict[str, PoseImages], tmp: str, log=None) -> dict:
    """Peak memory of every method on its input of one pose ({method: PoseImages}, see the module doc)"""
    env = dict(os.environ, MALLOC_MMAP_THRESHOLD_="65536", MALLOC_TRIM_THRESHOLD_="65536",
               PYTHONPATH=os.pathsep.join([LAB_PATH] + [v for v in [os.environ.get("PYTHONPATH")] if v]))
    out = {}
    for name, p in inputs.items():
        m = METHODS[name]
        if m.needs == "square":
            kb = program_maxrss_kb(p.png, p.layout.nx, m.args, tmp) if p.png else None
            if kb is not None:
                out[name] = {"how": "ru_maxrss of the mrgingham process (GNU time %M)", "mb": kb / 1024}
            continue
        if m.start == "rotstar" and p.start is None:
            continue
        data = os.path.join(tmp, f"memory-{name}.pickle")
        with open(data, "wb") as f:
            pickle.dump(p, f)
        r = run_tool([sys.executable, "-m", __name__, name, data], env=env, capture_output=True, text=True)
        if r.returncode != 0:
            if log:
                log(f"  memory probe of {name} failed: {r.stderr.strip()[-500:]}")
            continue
        d = json.loads(r.stdout)
        out[name] = {"how": "peak RSS added by one call (fresh process, after a warm-up call)",
                     "mb": d["added_kb"] / 1024, **d}
    return out


if __name__ == "__main__":  # one BLAS thread: the parent's environment (scripts/bench.py) says so
    print(json.dumps(memory_probe(*sys.argv[1:3])))

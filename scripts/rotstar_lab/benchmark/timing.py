"""CPU and wall time of one call, on one pinned CPU

SYNOPSIS

    >>> from rotstar_lab.benchmark.timing import timed
    >>> out, cpu, wall = timed(sum, range(1000))
    >>> out, cpu >= 0, wall >= 0
    (499500, True, True)

    pin_one_cpu()       # this process on one CPU, one OpenCV thread (BLAS: set
                        # OPENBLAS_NUM_THREADS=1 etc. before numpy loads)

On one pinned CPU and one thread, CPU time is the work of the call; the wall
time also holds whatever else the machine made this CPU do. cpu_seconds()
counts the finished child processes too (mrgingham, its start included).
"""

from __future__ import annotations

import os
import resource
import time
import cv2


def pin_one_cpu() -> int:
    """Run this process on one CPU, with one OpenCV thread; returns the CPU"""
    cpu = min(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {cpu})
    cv2.setNumThreads(1)
    return cpu


def cpu_seconds() -> float:
    """CPU time of this process and of its finished children (mrgingham), user + system"""
    ch = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + ch.ru_utime + ch.ru_stime


def timed(fn, *args):
    """(fn(*args), CPU seconds, wall seconds)"""
    c0, w0 = cpu_seconds(), time.perf_counter()
    out = fn(*args)
    return out, cpu_seconds() - c0, time.perf_counter() - w0

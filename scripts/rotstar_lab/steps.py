"""The drivers' steps (scripts/demo.py, scripts/stereo.py): each printed, timed, stopped on failure, with the time left

SYNOPSIS

    >>> import sys
    >>> from rotstar_lab.steps import run_step, short_path
    >>> short_path("out/seq")
    'out/seq'
    >>> r = run_step([sys.executable, "-c", "print(6 * 7)"], "demo", capture_output=True, text=True)
    >>> r.stdout
    '42\\n'

Every step runs through rotstar_mrcal.programs.run_tool (a closed standard input).

run_step prints "$ <command>" before and "  (<seconds> s)" after to stderr,
and exits with "<who>: step failed (<program>, exit <status>)" when the
command fails. With a Clock started (start_clock), the line after also gives
the time so far and an estimate of the time left, from the step times of the
last complete run, which the clock keeps in the output folder:

    >>> time_left([10, 20, 30], [20])       # this run was twice as slow so far
    100.0
    >>> time_left([10, 20, 30], [10, 20, 30])
    0.0
    >>> time_left([], [5]) is None           # no earlier run: no estimate
    True
    >>> duration(3725)
    '1 h 2 min'
"""

from __future__ import annotations

import json
import os
import shlex
import subprocess
import sys
import time

from rotstar_mrcal.programs import run_tool
from rotstar_mrcal.atomic import atomic_write


def log(msg: str) -> None:
    """One line of progress on stderr"""
    print(msg, file=sys.stderr, flush=True)


def short_path(p: str) -> str:
    """p relative to the working directory if it lies below it, else absolute (for printed commands)"""
    r = os.path.relpath(p)
    return os.path.abspath(p) if r.startswith("..") else r


def time_left(last: list[float], done: list[float]) -> float | None:
    """Seconds left: the last run's steps after those done so far, scaled by how much slower (or
    faster) this run was than the last on the steps done; None without a last run to go by"""
    k = len(done)
    if not last or k > len(last) or sum(last[:k]) <= 0:
        return None
    return sum(last[k:]) * sum(done) / sum(last[:k])


def duration(seconds: float) -> str:
    """A duration for people: '45 s', '12 min', '1 h 2 min'"""
    m = round(seconds / 60)
    return f"{seconds:.0f} s" if seconds < 90 else f"{m} min" if m < 60 else f"{m // 60} h {m % 60} min"


class Clock:
    """The steps' times of this run and of the last complete one (path: a JSON file in the output
    folder); each step's line gives the time so far and the estimated time left"""

    def __init__(self, path: str):
        self.path, self.t0, self.names, self.times = path, time.monotonic(), [], []
        try:
            with open(path) as f:
                last = json.load(f)
            self.last = [(str(n), float(t)) for n, t in last["steps"]]
        except (OSError, ValueError, KeyError, TypeError):
            self.last = []

    def step_done(self, name: str, seconds: float) -> str:
        """Record a step; the progress text: '12 s; 1 min so far, about 3 min left'"""
        self.names.append(name)
        self.times.append(seconds)
        same = [n for n, _ in self.last[:len(self.names)]] == self.names  # (the same steps as last time)
        left = time_left([t for _, t in self.last], self.times) if same else None
        text = f"{seconds:.0f} s; {duration(self.elapsed())} so far"
        return text + (f", about {duration(left)} left (from the last run)" if left is not None else "")

    def elapsed(self) -> float:
        return time.monotonic() - self.t0

    def finish(self) -> None:
        """This run, complete, becomes the one the next run's estimates go by"""
        with atomic_write(self.path) as f:
            json.dump({"steps": list(zip(self.names, self.times)), "wall_s": self.elapsed(),
                       "cores": os.cpu_count()}, f)


_clock: Clock | None = None


def start_clock(path: str) -> Clock:
    """From now on run_step reports the time so far and the time left (see Clock)"""
    global _clock
    _clock = Clock(path)
    return _clock


def run_step(cmd, who: str, **kw) -> subprocess.CompletedProcess:
    """run_tool(cmd, **kw), printed and timed; sys.exit naming `who` if it fails"""
    log("$ " + shlex.join(cmd))
    t = time.monotonic()
    r = run_tool(cmd, **kw)
    if r.returncode != 0:
        sys.exit(f"{who}: step failed ({cmd[0]}, exit {r.returncode})")
    dt = time.monotonic() - t
    log(f"  ({_clock.step_done(os.path.basename(cmd[0]), dt) if _clock else f'{dt:.0f} s'})")
    return r


def wall_time_note(seconds: float, cores: int) -> str:
    """The line the drivers write into README.md: the wall time they measured, on how many cores

    >>> wall_time_note(612, 2)
    'Its last full run took 10 min of wall time on 2 cores (it depends on the machine and its load).'
    """
    return f"Its last full run took {duration(seconds)} of wall time on {cores} cores (it depends on the machine and its load)."

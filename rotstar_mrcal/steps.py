"""The drivers' steps (scripts/demo.py, scripts/stereo.py): each command printed, timed, stopped on failure

SYNOPSIS

    >>> import sys
    >>> from rotstar_mrcal.steps import run_step, short_path
    >>> short_path("out/seq")
    'out/seq'
    >>> r = run_step([sys.executable, "-c", "print(6 * 7)"], "demo", capture_output=True, text=True)
    >>> r.stdout
    '42\\n'

run_step prints "$ <command>" before and "  (<seconds> s)" after to stderr,
and exits with "<who>: step failed (<program>, exit <status>)" when the
command fails.
"""

from __future__ import annotations

import os
import shlex
import subprocess
import sys
import time


def log(msg: str) -> None:
    """One line of progress on stderr"""
    print(msg, file=sys.stderr, flush=True)


def short_path(p: str) -> str:
    """p relative to the working directory if it lies below it, else absolute (for printed commands)"""
    r = os.path.relpath(p)
    return os.path.abspath(p) if r.startswith("..") else r


def run_step(cmd, who: str, **kw) -> subprocess.CompletedProcess:
    """subprocess.run(cmd, **kw), printed and timed; sys.exit naming `who` if it fails"""
    log("$ " + shlex.join(cmd))
    t = time.monotonic()
    r = subprocess.run(cmd, **kw)
    if r.returncode != 0:
        sys.exit(f"{who}: step failed ({cmd[0]}, exit {r.returncode})")
    log(f"  ({time.monotonic() - t:.0f} s)")
    return r

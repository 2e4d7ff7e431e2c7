"""The programs the tools start: never on a terminal's input; the drivers' steps (scripts/demo.py,
scripts/stereo.py) each printed, timed, stopped on failure

SYNOPSIS

    >>> import sys
    >>> from rotstar_mrcal.steps import run_step, run_tool, short_path
    >>> short_path("out/seq")
    'out/seq'
    >>> r = run_step([sys.executable, "-c", "print(6 * 7)"], "demo", capture_output=True, text=True)
    >>> r.stdout
    '42\\n'
    >>> run_tool([sys.executable, "-c", "import sys; print(repr(sys.stdin.read()))"], capture_output=True,
    ...          text=True).stdout            # a closed standard input: never waits on a terminal
    "''\\n"

run_tool is subprocess.run with the standard input closed (/dev/null)
unless the data it needs is given (input=...) or a stdin= is: every program
the tools start goes through it, so that none waits on a terminal.

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


def run_tool(cmd, **kw) -> subprocess.CompletedProcess:
    """subprocess.run(cmd, **kw) with stdin=subprocess.DEVNULL unless input= or stdin= is given"""
    if "input" not in kw:
        kw.setdefault("stdin", subprocess.DEVNULL)
    return subprocess.run(cmd, **kw)


def run_step(cmd, who: str, **kw) -> subprocess.CompletedProcess:
    """run_tool(cmd, **kw), printed and timed; sys.exit naming `who` if it fails"""
    log("$ " + shlex.join(cmd))
    t = time.monotonic()
    r = run_tool(cmd, **kw)
    if r.returncode != 0:
        sys.exit(f"{who}: step failed ({cmd[0]}, exit {r.returncode})")
    log(f"  ({time.monotonic() - t:.0f} s)")
    return r

"""The programs the tools start (mrcal's, mrgingham, gnuplot): never on a terminal's input

SYNOPSIS

    >>> import sys
    >>> from rotstar_mrcal.programs import run_tool
    >>> run_tool([sys.executable, "-c", "import sys; print(repr(sys.stdin.read()))"], capture_output=True,
    ...          text=True).stdout            # a closed standard input: never waits on a terminal
    "''\\n"

run_tool is subprocess.run with the standard input closed (/dev/null)
unless the data it needs is given (input=...) or a stdin= is: every program
the tools start goes through it, so that none waits on a terminal (mrcal's
tools read points from standard input with --points).
"""

from __future__ import annotations

import subprocess


def run_tool(cmd, **kw) -> subprocess.CompletedProcess:
    """subprocess.run(cmd, **kw) with stdin=subprocess.DEVNULL unless input= or stdin= is given"""
    if "input" not in kw:
        kw.setdefault("stdin", subprocess.DEVNULL)
    return subprocess.run(cmd, **kw)

"""Helpers shared by the command-line tools: messages on stderr, progress, argument types"""

from __future__ import annotations

import argparse
import contextlib
import io
import math
import os
import signal
import sys
import textwrap
import threading
import time
from typing import NoReturn

from rotstar_mrcal.cli import interrupted_while_starting
from rotstar_mrcal.atomic import atomic_path, atomic_write  # noqa: F401  (re-exported: the commands write through these)


def say(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def out_line(line: str) -> None:
    """One line of a command's result on stdout, flushed; a stdout that cannot take it (a full disk, a
    closed pipe) stops the command with 'stdout: reason' (exit 1) instead of a traceback"""
    try:
        print(line, flush=True)
    except OSError as e:
        try:  # (nothing left for the interpreter to flush at exit, which would say it again)
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        except (OSError, ValueError):
            pass
        fail(f"stdout: {e.strerror or e}", EXIT_FAILED)


class Progress:
    """'[k/n] label: message' lines on stderr, with a rate once it is slow"""

    def __init__(self, n: int, quiet: bool = False):
        self.n, self.k, self.quiet, self.t0 = n, 0, quiet, time.monotonic()

    def step(self, label: str, msg: str, important: bool = False) -> None:
        """One line per item; with quiet, only the important ones (failures)"""
        self.k += 1
        if not self.quiet or important:
            el = time.monotonic() - self.t0
            eta = el / self.k * (self.n - self.k)
            tail = f"  ({el:.0f} s, ~{eta:.0f} s left)" if self.n > 3 and el > 2 else ""
            say(f"[{self.k}/{self.n}] {label}: {msg}{tail}")


def size_arg(s: str) -> tuple[int, int]:
    """argparse type for WIDTHxHEIGHT, e.g. 2360x1640 -> (2360, 1640)"""
    try:
        w, h = s.lower().split("x")
        w, h = int(w), int(h)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{s!r}: expected WIDTHxHEIGHT, e.g. 2360x1640") from None
    if w < 1 or h < 1:
        raise argparse.ArgumentTypeError(f"{s!r}: width and height must be positive")
    return w, h


def number_arg(kind=float, lo: float | None = None, hi: float | None = None, lo_open: bool = False):
    """argparse type: a finite int or float in [lo, hi] ((lo, hi] with lo_open), with a clear message

    SYNOPSIS

        >>> number_arg(float, 2)("10")
        10.0
        >>> number_arg(float, 2)("nan")
        Traceback (most recent call last):
        argparse.ArgumentTypeError: 'nan': must be a finite number >= 2
    """
    want = ("an integer" if kind is int else "a finite number") + (
        f" {'>' if lo_open else '>='} {lo:g}" if lo is not None else "") + (f" and <= {hi:g}" if hi is not None else "")

    def parse(s: str):
        try:
            v = kind(s)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{s!r}: must be {want}") from None
        if not math.isfinite(v) or (lo is not None and (v <= lo if lo_open else v < lo)) or (hi is not None and v > hi):
            raise argparse.ArgumentTypeError(f"{s!r}: must be {want}")
        return v

    parse.__name__ = "int" if kind is int else "number"  # argparse's "invalid <name> value" fallback
    return parse


# ---- exit codes, one-line errors, interrupts ----------------------------------------------
EXIT_OK = 0  # done
EXIT_FAILED = 1  # the job ran but failed, or its result is partial
EXIT_BAD_INPUT = 2  # bad input or arguments (argparse's own code)
EXIT_INTERRUPTED = 130  # Ctrl-C or SIGTERM (128 + SIGINT, as a shell reports it)



def exit_status_help(done: str = "done", failed: str = "the job ran but failed or its result is partial",
                     bad: str = "") -> str:
    """The 'exit status:' paragraph of a command's --help (its epilog): the codes run() gives
    (1 also when an output cannot be written, 2 for bad input, 130 when interrupted), each with
    what it means for this command; wrapped as argparse would

    SYNOPSIS

        >>> print(exit_status_help("written", bad="an unreadable results.json"))
        exit status: 0 written; 1 the job ran but failed or its result is partial, or
        an output cannot be written; 2 bad input or arguments (an unreadable
        results.json); 130 interrupted (Ctrl-C, SIGTERM)
    """
    text = (f"exit status: 0 {done}; 1 {failed}, or an output cannot be written; "
            f"2 bad input or arguments{f' ({bad})' if bad else ''}; 130 interrupted (Ctrl-C, SIGTERM)")
    return textwrap.fill(text, 78)


EXIT_CODES_HELP = exit_status_help()


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Every command's --help: description and epilog as written; an option's default shown
    as '(default: X)' only where it says something (not None, not a flag's False, not when the
    help text gives it already)

    SYNOPSIS

        >>> p = argparse.ArgumentParser(prog="x", formatter_class=HelpFormatter)
        >>> _ = p.add_argument("--n", type=int, default=3, help="count")
        >>> _ = p.add_argument("--out", help="output file")
        >>> _ = p.add_argument("--quick", action="store_true", help="fewer cases")
        >>> _ = p.add_argument("--perturb", type=float, default=0.0, help="px")
        >>> h = p.format_help()
        >>> "count (default: 3)" in h, "px (default: 0.0)" in h, "default: None" in h, "default: False" in h
        (True, True, False, False)
    """

    def _get_help_string(self, action):
        h = action.help or ""
        if ("default" in h.lower() or any(action.default is v for v in (None, False, True, argparse.SUPPRESS))
                or not action.option_strings or action.default == [] or action.required or action.nargs == 0):
            return h
        return h + " (default: %(default)s)"


class Failure(Exception):
    """A one-line message for the user and the exit code; raised by fail(), printed by run()"""

    def __init__(self, msg: str, code: int = EXIT_BAD_INPUT):
        super().__init__(msg)
        self.code = code


def fail(msg: str, code: int = EXIT_BAD_INPUT) -> NoReturn:
    """Stop the command: run() prints 'prog: msg' on stderr and exits with code"""
    raise Failure(msg, code)


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread like Ctrl-C so that the same clean-up runs"""


def _on_sigterm(signum, frame):
    raise Terminated()


def run(prog: str, main_fn, argv=None) -> int:
    """Run main_fn(argv) as command prog: Failure -> 'prog: msg' and its code; Ctrl-C or
    SIGTERM -> 'prog: interrupted' and 130 (no traceback; atomic_write removes partial files)

    SYNOPSIS

        >>> run("rotstar-x", lambda argv: fail("seq/pattern.json: grid.nx is 0"))  # stderr: the message
        2
    """
    main_thread = threading.current_thread() is threading.main_thread()  # (signal handlers live there)
    if main_thread and signal.getsignal(signal.SIGINT) is interrupted_while_starting:
        signal.signal(signal.SIGINT, signal.default_int_handler)  # started: KeyboardInterrupt, caught below
    old = signal.signal(signal.SIGTERM, _on_sigterm) if main_thread else None
    real_stdout, sys.stdout = sys.stdout, _NamedStdout(sys.stdout)
    try:
        code = main_fn(argv)
        sys.stdout.flush()  # a write to stdout that fails (a full disk, a closed pipe) fails here, not at exit
        return code
    except Failure as e:
        say(f"{prog}: {e}")
        return e.code
    except KeyboardInterrupt:
        say(f"{prog}: interrupted")
        return EXIT_INTERRUPTED
    except OSError as e:  # a write (or a read) the command did not expect to fail
        say(f"{prog}: {os_error_line(e)}")
        if e.filename == STDOUT:
            _silence_stdout()
        return EXIT_FAILED
    finally:
        sys.stdout = real_stdout
        if main_thread:
            signal.signal(signal.SIGTERM, old)


STDOUT = "standard output"


def os_error_line(e: OSError) -> str:
    """'file: reason' for an OSError ('standard output: reason' for a write to stdout that failed)

    SYNOPSIS

        >>> os_error_line(OSError(28, "No space left on device", "cal/calibration.json"))
        'cal/calibration.json: No space left on device'
    """
    return f"{e.filename}: {e.strerror or e}" if e.filename is not None else str(e.strerror or e)


class _NamedStdout:
    """sys.stdout during run(): a write or flush that fails raises an OSError named 'standard output'"""

    def __init__(self, f):
        self._f = f

    def _named(self, fn, *args):
        try:
            return fn(*args)
        except OSError as e:
            raise OSError(e.errno, e.strerror or str(e), STDOUT) from e

    def write(self, s):
        return self._named(self._f.write, s)

    def writelines(self, lines):
        return self._named(self._f.writelines, lines)

    def flush(self):
        return self._named(self._f.flush)

    def __getattr__(self, name):
        return getattr(self._f, name)


def _silence_stdout() -> None:
    """stdout to /dev/null, so that Python's own flush at exit does not fail again on what is left"""
    with contextlib.suppress(OSError, ValueError, AttributeError, io.UnsupportedOperation):  # (a test's capture)
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, sys.stdout.fileno())
        os.close(null)


# ---- output paths --------------------------------------------------------------------------
def make_folder(path: str, what: str = "--outdir") -> str:
    """Create an output folder and its parents; fail() with one line naming it when it cannot be"""
    try:
        os.makedirs(path, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        fail(f"{what} {path}: a file is in the way (not a folder)")
    except OSError as e:
        fail(f"{what} {path}: {e.strerror}")
    return path


def _inside(path: str, folder: str) -> bool:
    path, folder = os.path.realpath(path), os.path.realpath(folder)
    return path == folder or path.startswith(folder.rstrip(os.sep) + os.sep)


def check_output_path(path: str, inputs=(), folder: bool = False) -> str:
    """Check, before any work, that path can be written; fail() with 'path: reason' if not

    A file (folder=False) needs an existing, writable parent folder and must not
    be a folder itself; a folder (folder=True) is created with its parents later,
    so nothing on the way may be a file. Neither may be one of the inputs: a file
    in inputs, or anything inside a folder in inputs (a pose folder). Returns path.
    """
    if not path:
        fail("empty output path")
    for inp in inputs:
        if _inside(path, inp):
            where = "is the input" if os.path.realpath(path) == os.path.realpath(inp) else "is inside the input folder"
            fail(f"{path}: {where} {inp}; write the output elsewhere")
    if folder:
        if os.path.exists(path) and not os.path.isdir(path):
            fail(f"{path}: exists and is not a folder")
        up = os.path.dirname(os.path.normpath(path)) or "."
        while not os.path.exists(up):
            up = os.path.dirname(up) or "."
        if not os.path.isdir(up):
            fail(f"{path}: cannot create the folder, {up} is a file")
        if not os.access(up, os.W_OK | os.X_OK):
            fail(f"{path}: cannot create the folder, {up} is not writable")
        return path
    if os.path.isdir(path):
        fail(f"{path}: is a folder; give a file name")
    parent = os.path.dirname(os.path.abspath(path))
    if not os.path.exists(parent):
        fail(f"{path}: no such folder {os.path.dirname(path) or '.'}")
    if not os.path.isdir(parent):
        fail(f"{path}: {os.path.dirname(path)} is a file, not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        fail(f"{path}: folder {os.path.dirname(path) or '.'} is not writable")
    if os.path.exists(path) and not os.path.isfile(path):
        fail(f"{path}: not a regular file")
    return path


def hold_arg(s: str) -> int | None:
    """--hold: refreshes for every frame kind, or 'short' (None: pattern.loop.SHORT_HOLDS, per kind)

    >>> hold_arg("30"), hold_arg("short")
    (30, None)
    """
    if s == "short":
        return None
    try:
        v = int(s)
    except ValueError:
        v = 0
    if v < 1:
        raise argparse.ArgumentTypeError(f"{s!r}: a number of refreshes >= 1, or 'short'")
    return v


HOLD_HELP = ("the player's hold, display refreshes per frame; 'short' holds each frame kind for its own time "
             "(the rotating star 11, the identity frames and the checkerboard 6, the start marker 3: "
             "pattern.loop.SHORT_HOLDS, a 2.9 s loop of the default sequence at 60 Hz)")

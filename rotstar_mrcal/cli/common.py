"""Helpers shared by the command-line tools: messages on stderr, progress, argument types"""

from __future__ import annotations

import argparse
import sys
import time


def say(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


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
        return int(w), int(h)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{s!r}: expected WIDTHxHEIGHT, e.g. 2360x1640") from None

"""The segmentation options that rotstar-segment and rotstar-capture share (not a command)"""

from __future__ import annotations

import argparse

from rotstar_mrcal.capture.segment import Options


def _scale(s: str):
    if s == "auto":
        return s
    try:
        return float(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{s!r}: 'auto' or a number") from None


def add_segment_options(p: argparse.ArgumentParser) -> None:
    """The options segmentation shares with rotstar-capture"""
    d = Options()
    g = p.add_argument_group("segmentation")
    g.add_argument("--average", type=int, default=d.average,
                   help=f"middle frames of each stretch averaged (default {d.average}, as the paper)")
    g.add_argument("--guard", type=int, default=d.guard,
                   help=f"frames dropped at each end of a stretch (default {d.guard})")
    g.add_argument("--min-len", type=int, default=d.min_len,
                   help=f"camera frames in the shortest stable stretch (default {d.min_len})")
    g.add_argument("--threshold-k", type=float, default=d.k,
                   help=f"change threshold: median + K robust sigmas of the difference signal (default {d.k:g})")
    g.add_argument("--max-motion", type=float, default=d.max_motion,
                   help=f"reject a loop over which the image drifts more than this many pixels (default {d.max_motion:g})")
    g.add_argument("--max-jitter", type=float, default=d.max_jitter,
                   help=f"frames between the player's changes may differ by this many times the sensor noise "
                        f"(default {d.max_jitter:g}; raise it for a screen whose brightness flickers)")
    g.add_argument("--scale", type=_scale, default="auto",
                   help="multiply 16-bit values before writing: 'auto' scales data that only reaches 10 or 12 "
                        "bits up to 16 (default), 1 keeps them")


def options_from(a) -> Options:
    return Options(average=a.average, guard=a.guard, min_len=a.min_len, k=a.threshold_k, max_motion=a.max_motion,
                   max_jitter=a.max_jitter)

"""rotstar-pattern: the display sequence (frame PNGs and pattern.json) for a screen"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys

import cv2

from rotstar_mrcal.pattern.player import DEFAULT_HOLD, hold_text, write_player
from rotstar_mrcal.cli.common import HOLD_HELP, hold_arg
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.pattern.render import encode_display, render_frame
from rotstar_mrcal.cli.common import (
    EXIT_FAILED, HelpFormatter, atomic_path, atomic_write, check_output_path, exit_status_help, fail,
    make_folder, number_arg, run, say, size_arg,
)

DESCRIPTION = """\
Write the rotating-star display sequence for one screen: NFRAMES frames in
which every grid corner is the centre of a checkerboard corner turned by
k*STEP in frame k, framed by border bands that are white in even frames and
black in odd ones; then the identity frames, in which every element's square
is white or black by one bit of its grid index (a constant-weight code: 13
frames for 14x9 corners); then one plain checkerboard frame whose inner
corners are the same screen points (the baseline). --paper-sequence adds the
other frames of the paper's real-world experiment: after the identity frames,
4-step phase shifts along x and along y (sinusoidal fringes, phase 0 on every
corner with the default period), and after the checkerboard the 16-segment
star of Schops et al. on every corner. Also writes pattern.json,
which rotstar-detect needs beside the recorded poses, and player.html, and
prints the mrcal object arguments on stderr.

Show the PNGs at exactly one image pixel per display pixel (no scaling, no
smoothing). The defaults fit a 10.9-inch iPad Air or iPad 10 (2360x1640, 264 ppi, the paper's screen) filmed by
a D435-class camera (1280x800, ~90 degrees) at 0.3-0.6 m.
"""


def _angle(s: str) -> float:
    """argparse type: radians or pi/N, finite and not 0"""
    t = s.strip().lower().replace(" ", "")
    try:
        v = math.pi / float(t[3:]) if t.startswith("pi/") else float(t)
    except (ValueError, ZeroDivisionError):
        raise argparse.ArgumentTypeError(f"{s!r}: expected radians or pi/N, e.g. pi/16") from None
    if not math.isfinite(v) or v == 0:
        raise argparse.ArgumentTypeError(f"{s!r}: the rotation per frame must be finite and not 0")
    return v


def parse_args(argv=None):
    p = argparse.ArgumentParser(prog="rotstar-pattern", description=DESCRIPTION, epilog=exit_status_help("written", failed="a frame cannot be written"),
                                formatter_class=HelpFormatter)
    p.add_argument("--out", "-o", default="pattern", help="output folder (default ./pattern)")
    p.add_argument("--hold", type=hold_arg, default=DEFAULT_HOLD, help=f"player.html's {HOLD_HELP} (default "
                   f"{hold_text(DEFAULT_HOLD)}; the page's #hold=N changes it)")
    p.add_argument("--screen", type=size_arg, default=(2360, 1640), help="screen size in display pixels (default 2360x1640)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--ppi", type=number_arg(float, 0, lo_open=True), default=264.0, help="display pixels per inch (default 264)")
    g.add_argument("--pixel-pitch-mm", type=number_arg(float, 0, lo_open=True), help="display pixel pitch in millimetres (instead of --ppi)")
    p.add_argument("--pitch", type=number_arg(int, 2), default=150, help="grid pitch: display pixels between corners, even (default 150)")
    p.add_argument("--band", type=number_arg(int, 2), default=40,
                   help="border-band width in display pixels, even; about 0.25-0.3 of the pitch (default 40)")
    p.add_argument("--nx", type=number_arg(int, 3), help="corners across (default: as many as fit)")
    p.add_argument("--ny", type=number_arg(int, 3), help="corners down (default: as many as fit)")
    p.add_argument("--frames", type=number_arg(int, 2, 64), default=8,
                   help="rotating-star frames, at least 2: the corners are where the turned frames agree (default 8)")
    p.add_argument("--step", type=_angle, default=math.pi / 16, help="rotation per frame, radians or pi/N (default pi/16)")
    p.add_argument("--no-identity", dest="identity", action="store_false",
                   help="leave out the identity frames. They let every corner name itself, so a board partly out "
                        "of view (no orientation marker or outer band in sight) still gives correctly labelled "
                        "corners; without them the whole board must be in view. They lengthen the sequence "
                        "(13 more frames for 14x9 corners)")
    _sequence_arguments(p)
    a = p.parse_args(argv)
    if not a.paper_sequence and (a.phase_period is not None or a.star_segments != 16):
        p.error("--phase-period and --star-segments need --paper-sequence")
    if a.star_segments % 4:
        p.error(f"--star-segments {a.star_segments}: must be a multiple of 4")
    if (a.frames - 1) * abs(a.step) >= math.pi:
        p.error(f"--frames {a.frames} turned by --step {a.step:g} reach pi, where the frames repeat; "
                f"use a smaller step (at most pi/{a.frames})")
    return a


def _sequence_arguments(p) -> None:
    """What else the sequence shows (the paper's phase shifts and star) and how the PNGs are encoded"""
    p.add_argument("--paper-sequence", action="store_true",
                   help="the paper's whole sequence: also the phase-shift frames (4 along x, 4 along y) after the "
                        "identity frames and a star frame after the checkerboard (rotstar-detect --method phase, star)")
    p.add_argument("--phase-period", type=number_arg(float, 4), default=None,
                   help="with --paper-sequence: fringe period in display pixels (default: the pitch, so that every "
                        "corner has phase 0)")
    p.add_argument("--star-segments", type=number_arg(int, 4, 64), default=16,
                   help="with --paper-sequence: the star's black and white segments, a multiple of 4 (default 16)")
    p.add_argument("--gamma", type=number_arg(float, 0.1, 10), default=2.2,
                   help="display gamma applied to the PNG values so that anti-aliased pixels emit the "
                        "right amount of light (default 2.2; 1 writes linear values)")


def main(argv=None) -> int:
    return run("rotstar-pattern", _main, argv)


def _main(argv=None) -> int:
    a = parse_args(argv)
    pitch_m = a.pixel_pitch_mm / 1000 if a.pixel_pitch_mm else 0.0254 / a.ppi
    try:
        layout = make_layout(screen=a.screen, pixel_pitch_m=pitch_m, pitch=a.pitch, band=a.band,
                             nframes=a.frames, step=a.step, nx=a.nx, ny=a.ny, identity=a.identity,
                             phase_period=(a.phase_period or a.pitch) if a.paper_sequence else 0,
                             star_segments=a.star_segments if a.paper_sequence else 0)
    except ValueError as e:
        fail(str(e).replace("leave the identity frames out", "add --no-identity"))
    check_output_path(a.out, folder=True)
    make_folder(a.out, "--out")
    frames = layout.frames()
    for k, f in enumerate(frames):
        fn = os.path.join(a.out, f["file"])
        with atomic_path(fn) as tmp:
            if not cv2.imwrite(tmp, encode_display(render_frame(layout, f), a.gamma)):
                fail(f"{fn}: cannot write", EXIT_FAILED)
        say(f"[{k + 1}/{len(frames)}] {fn}")
    d = layout.to_dict()
    d["display_gamma"] = a.gamma
    with atomic_write(os.path.join(a.out, "pattern.json")) as fh:
        json.dump(d, fh, indent=2)
        fh.write("\n")
    say(f"wrote {write_player(a.out, a.hold)}: open it on the screen, full screen (doc/capture.md)")
    code = layout.identity_code
    say(f"{layout.nx}x{layout.ny} corners, pitch {layout.pitch} px = {layout.spacing_m * 1000:.4f} mm, "
        f"marker element {layout.marker}; {layout.nframes} rotating-star frames, "
        + (f"{code.nframes} identity frames, " if code else "no identity frames, ")
        + (f"8 phase-shift frames (period {layout.phase_period:g} px), " if layout.phase else "")
        + "the checkerboard"
        + (f", the {layout.star_segments}-segment star" if layout.star_segments else "")
        + f"; wrote {a.out}/pattern.json")
    say("mrcal object arguments: " + " ".join(layout.mrcal_object_args()))
    return 0


if __name__ == "__main__":
    sys.exit(main())

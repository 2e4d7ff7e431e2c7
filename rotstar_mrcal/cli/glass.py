"""rotstar-glass: a first mrcal calibration's corners corrected for the screen's cover glass, for a second run

SYNOPSIS

    rotstar-detect seq/ > corners.vnl
    mrcal-calibrate-cameras --corners-cache corners.vnl ... --outdir first/ '*/rotstar_00.png'
    rotstar-glass first/camera-0.cameramodel -o corrected.vnl
    mrcal-calibrate-cameras --corners-cache corrected.vnl ... --outdir cal/ '*/rotstar_00.png'
"""

from __future__ import annotations

import argparse
import sys

from rotstar_mrcal.calibrate.cornerset import SourceError, load_model
from rotstar_mrcal.calibrate.glass import MAX_PLAUSIBLE_MM, MIN_SIGMAS, corrected_boards, correct_glass
from rotstar_mrcal.cli.common import HelpFormatter, atomic_write, exit_status_help, number_arg, out_line, run, say
from rotstar_mrcal.optics.refraction import DEFAULT_INDEX
from rotstar_mrcal.vnl import write_corners

DESCRIPTION = f"""\
The plain mrcal path's cover-glass correction (rotstar-calibrate does the
same by itself). A screen's cover glass bends every ray by an amount that
changes with the viewing angle; a calibration puts that into the lens model.
From a first calibration (a model mrcal-calibrate-cameras wrote, with its
optimization_inputs), the glass's thickness is estimated (or --glass given),
every corner moved to where the unrefracted pixel would have been seen from
its board's solved pose, the problem solved again until the moves settle,
and the corrected corners written as a corners.vnl (a weight column; the
corners mrcal did not use left out): run mrcal-calibrate-cameras again on
it, with the same other arguments. An estimate within {MIN_SIGMAS:g} sigma of 0 (no
glass), above {MAX_PLAUSIBLE_MM:g} mm, or that the less and the more tilted boards disagree
on (another pose-dependent error, e.g. a moving entrance pupil) writes
nothing (exit 1). See doc/simulator.md, "A cover glass over the pixels".
"""

EPILOG = """\
examples:
  rotstar-glass first/camera-0.cameramodel -o corrected.vnl
  rotstar-glass first/camera-0.cameramodel -o corrected.vnl --glass 0.7 --glass-index 1.52

""" + exit_status_help("the corrected corners were written (their path on stdout)",
                       failed="no glass to take out, or not a glass (the reason on stderr); nothing written",
                       bad="a model that cannot be read or has no optimization_inputs") + "\n"


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="rotstar-glass", description=DESCRIPTION, epilog=EPILOG,
                                formatter_class=HelpFormatter)
    p.add_argument("model", help="a calibration mrcal-calibrate-cameras wrote (camera-0.cameramodel)")
    p.add_argument("-o", "--out", required=True, metavar="VNL", help="the corrected corners.vnl to write")
    p.add_argument("--glass", type=number_arg(float, 0, 5, lo_open=True), default=None, metavar="MM",
                   help="the glass's thickness, mm (0-5; default: estimated from the data)")
    p.add_argument("--glass-index", type=number_arg(float, 1), default=DEFAULT_INDEX, metavar="N",
                   help=f"its refractive index (>= 1; default {DEFAULT_INDEX})")
    return p.parse_args(argv)


def _main(argv=None) -> int:
    a = parse_args(argv)
    try:
        model = load_model(a.model, need_inputs=True)
        g = correct_glass(model, a.glass, a.glass_index)
        boards = corrected_boards(g.inputs) if g.applied else None
    except (SourceError, ValueError) as e:
        say(f"rotstar-glass: {a.model}: {e}" if isinstance(e, ValueError) else f"rotstar-glass: {e}")
        return 2
    say(f"rotstar-glass: {g.line()}")
    if boards is None:
        say("rotstar-glass: nothing written: run mrcal-calibrate-cameras on the corners as they are")
        return 1
    with atomic_write(a.out) as f:
        write_corners(f, [(p, c) for p, c, _ in boards], [w for _, _, w in boards])
    say(f"rotstar-glass: next: mrcal-calibrate-cameras --corners-cache {a.out} with the first run's other arguments")
    out_line(a.out)
    return 0


def main(argv=None) -> int:
    return run("rotstar-glass", _main, argv)


if __name__ == "__main__":
    sys.exit(main())

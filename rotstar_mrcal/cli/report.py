"""rotstar-report: rotstar-crossval results (one folder per condition) in, one report folder out"""

from __future__ import annotations

import argparse
import json
import sys

from rotstar_mrcal.report import folder as reportdir
from rotstar_mrcal.cli.common import EXIT_FAILED, HelpFormatter, exit_status_help, fail, make_folder, run, say

DESCRIPTION = """\
Build the validation report from one or more rotstar-crossval output folders
(each holds results.json; one folder per condition, e.g. per exposure, in
the order given). Writes OUT/index.md and OUT/index.html (the same page),
OUT/headline.md, OUT/results.json (all conditions) and the figures: the
summary bar charts, and each condition's per-pose plot and maps, copied.

A folder (or results.json) written by `make stereo` (scripts/stereo.py,
format rotstar-stereo/1) adds a stereo section: each calibration of a
camera pair against the true rig (per-camera error, baseline and rotation
error), the depth error at 0.5, 1 and 2 m, and the cross-validation of the
two pose groups' calibrations; it may be the only input.

Per condition it also draws mrcal's own views of the first method's
calibration on group A (mrcal-show-projection-uncertainty, -residuals,
-residuals-board-observation, -distortion-off-pinhole,
-valid-intrinsics-region, and -projection-diff against group B's), with
colour scales that fit the data, the outlier count and the valid region;
each with the mrcal-show-* command that redraws it (stderr and the page).

On simulated data (the truth gives each test pose's tilt) it also writes
OUT/paper.md with the held-out error by tilt of the test poses; make demo
(scripts/demo.py) then adds the paper's real-world claims (4.2) as verdicts
with their numbers to paper.md, the page and headline.md.

stdout: the headline table and the verdict (Markdown), for pasting;
stderr: the files written and the mrcal-show-* commands.
"""

EPILOG = exit_status_help("written", failed="a figure or page could not be made",
                          bad="an unreadable results.json, duplicate labels, an --out that cannot be a folder") + "\n"


def parse_args(argv=None):
    p = argparse.ArgumentParser(prog="rotstar-report", description=DESCRIPTION, epilog=EPILOG,
                                formatter_class=HelpFormatter)
    p.add_argument("xval", nargs="+", help="rotstar-crossval --outdir folders (or their results.json); "
                   "make stereo's stereo folder")
    p.add_argument("--out", default="report", help="report folder (default report)")
    p.add_argument("--title", default="rotstar-mrcal validation report")
    p.add_argument("--notes", help="a Markdown file whose text goes under the title (the set-up)")
    p.add_argument("--figure", action="append", default=[], metavar="PNG[:CAPTION]",
                   help="an extra figure to show after the headline; repeatable")
    p.add_argument("--no-mrcal-figures", action="store_true", help="leave out mrcal's own views (faster)")
    return p.parse_args(argv)


def main(argv=None) -> int:
    return run("rotstar-report", _main, argv)


def _main(argv=None) -> int:
    a = parse_args(argv)
    try:
        loaded = [reportdir.load_results(p) for p in a.xval]
    except (OSError, ValueError, json.JSONDecodeError) as e:
        say(f"rotstar-report: {e}")
        return 2
    notes = ""
    if a.notes:
        try:
            with open(a.notes) as f:
                notes = f.read()
        except (OSError, UnicodeDecodeError) as e:
            fail(f"--notes {a.notes}: {getattr(e, 'strerror', None) or e}")
    make_folder(a.out, "--out")
    try:
        written = reportdir.build_report([r for r, _ in loaded], [d for _, d in loaded], a.out, a.title, notes,
                                         a.figure, mrcal_figures=not a.no_mrcal_figures,
                                         log=lambda m: say(f"rotstar-report: {m}"))
    except ValueError as e:
        say(f"rotstar-report: {e}")
        return 2
    except OSError as e:  # (a full disk: the file, or at least the report folder)
        fail(f"{e.filename or a.out}: {e.strerror or e}", EXIT_FAILED)
    say(f"rotstar-report: wrote {written['index.html']} and {written['index.md']}")
    with open(written["headline.md"]) as f:
        sys.stdout.write(f.read())
    return 0


if __name__ == "__main__":
    sys.exit(main())

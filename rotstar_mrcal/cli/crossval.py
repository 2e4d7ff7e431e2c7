"""rotstar-crossval: held-out reprojection error and mrcal's cross-validation of calibrations"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile

import matplotlib.pyplot as plt
import numpy as np

from rotstar_mrcal import dataset
from rotstar_mrcal.calibrate import command as cal
from rotstar_mrcal.report import plots, page as report
from rotstar_mrcal.peers.cornersets import dataset_methods
from rotstar_mrcal.evaluate.detection import detect_dataset as _detect_dataset
from rotstar_mrcal.evaluate.detection import split_interleaved
from rotstar_mrcal.evaluate.crossval import cross_validate
from rotstar_mrcal.evaluate.groups import compare_sets, default_label
from rotstar_mrcal.report import crossval as crossval_report
from rotstar_mrcal.evaluate.heldout import heldout
from rotstar_mrcal.calibrate.cornerset import SourceError, load_corner_set, load_model
from rotstar_mrcal.cli.detect import DETECT_METHODS
from rotstar_mrcal.calibrate.glass import MAX_PLAUSIBLE_MM, MIN_SIGMAS
from rotstar_mrcal.cli.common import (
    HelpFormatter, Progress, exit_status_help, atomic_write, make_folder, number_arg, run, say,
)
from rotstar_mrcal.optics.refraction import DEFAULT_INDEX

DESCRIPTION = f"""\
Validate calibrations the way the rotating-star paper and mrcal do it.

  rotstar-crossval MODEL TEST
      The paper's metric: every board of TEST (a corners.vnl, or a dataset
      folder, which is detected first) solved with MODEL's intrinsics fixed;
      the mean reprojection error (MRE) per pose and overall.

  rotstar-crossval MODEL_A MODEL_B
      mrcal's cross-validation of two calibrations of one camera: their
      projection difference over the imager against the sum of their
      projection uncertainties (both need mrcal's optimization_inputs).

  rotstar-crossval SEQ --outdir DIR
      One recording (a dataset or a corners.vnl): its boards split into two
      interleaved groups (A: boards 0, 2, 4, ...; B: 1, 3, 5, ..., written
      as DIR/rotstar/A.vnl and B.vnl), then as for A B below.

  rotstar-crossval A B  [--methods ...] [--set NAME A_VNL B_VNL ...]
      Two pose groups of one camera (datasets or corners.vnl files):
      calibrate each, test each model on the other group (both directions),
      cross-validate the two models, and, for simulated datasets, compare
      each with the true camera. With --methods (datasets only) or --set, the
      same for several corner sets of the same poses, side by side.

A dataset is detected as rotstar-detect does by default (--refine psf-sim:
the symmetric fit less its offset under the lens's coma), as the corner set
"rotstar". With --methods the registry's names hold: "rotstar" is the
paper's symmetric fit (rotstar-detect --refine symmetric) and
"rotstar-psf-sim" rotstar-detect's default.

Commands are printed on stderr before they run. stdout gets the results
table (Markdown) or, with --json, the results. With --outdir, the models,
the figures (PNG) and results.json are written there; rotstar-report turns
one or more such folders into a report.

The lens model defaults to rotstar-calibrate's lean model
(LENSMODEL_OPENCV8, the model of rotstar-detect's printed command).

A screen's cover glass bends every ray by an amount that changes with the
viewing angle, and a plain calibration puts that into the lens model; it is
the screen's, so it is in every method's corners. --glass MM corrects each
calibration (A and B, every corner set) for a glass the user knows, as
rotstar-calibrate --glass does (calibrate.glass: each corner moved to where
the unrefracted pixel would have been seen from its board's solved pose, the
problem solved again); --glass estimate estimates the thickness from each
calibration and corrects when it is a plausible glass (over 0 by {MIN_SIGMAS:g} sigma,
at most {MAX_PLAUSIBLE_MM:g} mm; else the plain model stays and the reason is
reported). The default is no correction: the
calibrations are those of the printed mrcal-calibrate-cameras commands, which
a user can run again and get the same models. The corrected models are the
ones tested; results.json keeps, per corner set and group, the glass found
and the plain model against the truth. A corrected model's held-out corners
are corrected for the same glass from their own solved poses.
"""

EPILOG = f"""\
methods for --methods: {', '.join(dataset_methods())} (or 'all')

examples:
  rotstar-crossval cal/camera-0.cameramodel test-seq/
  rotstar-crossval seq/ --outdir xval/                    # one recording, split in two
  rotstar-crossval groupA/ groupB/ --lensmodel opencv8 --outdir xval/
  rotstar-crossval groupA/ groupB/ --methods all --outdir xval/ --label "4000 us"
  rotstar-crossval --set rotstar A/rotstar.vnl B/rotstar.vnl --set mrgingham A/mrg.vnl B/mrg.vnl
  rotstar-crossval groupA/ groupB/ --methods all --outdir xval/ --glass 0.7   # the screen's known cover glass

""" + exit_status_help("done", failed="some corner set could not be calibrated (the others are reported)",
                       bad="a missing or unreadable model, a model of another imager size than the test "
                           "corners") + "\n"


def parse_args(argv=None):
    p = argparse.ArgumentParser(prog="rotstar-crossval", description=DESCRIPTION, epilog=EPILOG,
                                formatter_class=HelpFormatter)
    p.add_argument("inputs", nargs="*", help="MODEL TEST, MODEL_A MODEL_B, SEQ, or A B (datasets or corners.vnl)")
    p.add_argument("--set", nargs=3, action="append", default=[], metavar=("NAME", "A", "B"),
                   help="a named corner set of both groups (corners.vnl files); repeatable")
    p.add_argument("--methods", help="detect these methods on the datasets A and B (comma-separated, or 'all')")
    p.add_argument("--outdir", help="write models, figures and results.json here (required for A B and SEQ; "
                   "MODEL TEST keeps the detected corners here, else in a temporary folder)")
    p.add_argument("--label", help="name of this condition in the tables (e.g. the exposure)")
    p.add_argument("--lensmodel", default="auto",
                   help=f"lens model of the calibrations: 'auto' (default: {cal.LEAN_LENSMODEL}, rotstar-calibrate's "
                        "lean model), 'splined', 'opencv5', ... or LENSMODEL_...")
    p.add_argument("--knots-x", type=int, default=cal.DEFAULT_KNOTS_X, help="splined model: knots across")
    p.add_argument("--pattern", help="pattern.json (or its folder) when a corners.vnl's dataset cannot be found")
    p.add_argument("--imagersize", type=int, nargs=2, metavar=("W", "H"),
                   help="imager size when the images cannot be read")
    p.add_argument("--distance", type=float,
                   help="compare projections at this range, metres (default: infinity, as mrcal)")
    p.add_argument("--gridn", type=int, default=40, help="grid points across the imager (default 40)")
    p.add_argument("--glass", type=glass_arg, default=0.0, metavar="MM|estimate",
                   help="the screen's cover glass over its pixels, mm (0-5), or 'estimate' (see above; default 0: "
                        "no correction)")
    p.add_argument("--glass-index", type=number_arg(float, 1), default=DEFAULT_INDEX, metavar="N",
                   help=f"refractive index of the cover glass (>= 1; default {DEFAULT_INDEX})")
    p.add_argument("--jobs", "-j", type=int, default=1, help="parallel calibrations and evaluations")
    p.add_argument("--json", action="store_true", help="print the results as JSON instead of a table")
    return p.parse_args(argv)


def glass_arg(s: str) -> float | None:
    """argparse type of --glass: a thickness in [0, 5] mm, or 'estimate' (None: calibrate.glass estimates it)

        >>> glass_arg("0.7"), glass_arg("estimate")
        (0.7, None)
    """
    return None if s == "estimate" else number_arg(float, 0, 5)(s)


def _kind(path: str) -> str:
    if path.endswith(".cameramodel"):
        return "model"
    if os.path.isdir(path):
        return "dataset"
    if os.path.exists(path):
        return "vnl"
    raise SourceError(f"{path}: no such file or folder")


def _write_json(obj, path=None):
    text = json.dumps(obj, indent=1, default=lambda o: None) + "\n"
    if path is None:
        sys.stdout.write(text)
    else:
        with atomic_write(path) as f:
            f.write(text)


DEFAULT_SET = "rotstar"  # the corner set without --methods: what rotstar-detect writes by default ...
DEFAULT_METHOD = "rotstar-psf-sim"  # ... (its default refiner, psf-sim; with --methods, "rotstar" is the paper's fit)


def detect_args(m: str) -> list[str] | None:
    """rotstar-detect's options that give method m's corners, or None (a detector of no command of ours)

    >>> detect_args("rotstar"), detect_args("rotstar-psf-sim"), detect_args("star"), detect_args("mrgingham")
    (['--refine', 'symmetric'], ['--refine', 'psf-sim'], ['--method', 'star'], None)
    """
    if m == "rotstar":
        return ["--refine", "symmetric"]
    if m == "rotstar-psf-sim":
        return ["--refine", "psf-sim"]
    return ["--method", m] if m in DETECT_METHODS else None


def detect_commands(seq: str, methods, outdir: str, side: str, folders: dict | None = None) -> list[str]:
    """The rotstar-detect commands that write the corners detect_dataset writes here, in this
    process (the methods rotstar-detect has; the other detectors have no command of ours)

    SYNOPSIS

        >>> detect_commands("seq", ["rotstar", "mrgingham"], "xval", "A")
        ['rotstar-detect seq --refine symmetric -o xval/rotstar/A.vnl']
        >>> detect_commands("seq", [DEFAULT_METHOD], "xval", "B", {DEFAULT_METHOD: DEFAULT_SET})
        ['rotstar-detect seq --refine psf-sim -o xval/rotstar/B.vnl']
    """
    return [cal.command_line(["rotstar-detect", seq, *detect_args(m), "-o",
                              os.path.join(outdir, (folders or {}).get(m, m), f"{side}.vnl")])
            for m in methods if detect_args(m) is not None]


def detect_dataset(seq: str, methods, outdir: str, side: str, jobs: int = 1,
                   folders: dict | None = None) -> dict[str, str]:
    """validate.detection.detect_dataset with progress lines on stderr, after the commands that do the same"""
    n = len(dataset.list_poses(seq))
    for c in detect_commands(seq, methods, outdir, side, folders):
        say(f"$ {c}    # (run here, in this process)")
    say(f"rotstar-crossval: detecting {', '.join(methods)} on {seq} ({n} poses)")
    progress = Progress(n)
    return _detect_dataset(seq, methods, outdir, side, jobs, progress=progress.step,
                           log=lambda line: say(f"rotstar-crossval: {line}"), folders=folders)


def detect_default(seq: str, outdir: str, side: str, jobs: int = 1) -> str:
    """The default corner set of a dataset (rotstar-detect's default output), as outdir/rotstar/<side>.vnl"""
    return detect_dataset(seq, [DEFAULT_METHOD], outdir, side, jobs, {DEFAULT_METHOD: DEFAULT_SET})[DEFAULT_METHOD]


# ---------------------------------------------------------------------------
# modes
# ---------------------------------------------------------------------------
def mode_heldout(a, model_path: str, test: str) -> int:
    model = load_model(model_path)
    tmp = None
    if _kind(test) == "dataset":
        if a.outdir is None:
            tmp = tempfile.TemporaryDirectory(prefix="rotstar-crossval-")
        vnl = detect_default(test, a.outdir or tmp.name, "test", a.jobs)
    else:
        vnl = test
    try:
        return _heldout_report(a, model, model_path, test, vnl)
    finally:
        if tmp is not None:
            tmp.cleanup()


def _heldout_report(a, model, model_path, test, vnl) -> int:
    cs = load_corner_set(vnl, a.pattern, a.imagersize, truth=False)
    if tuple(int(v) for v in model.imagersize()) != tuple(cs.imagersize):
        W, H = (int(v) for v in model.imagersize())
        raise SourceError(f"{model_path} is a {W}x{H} camera, the test corners are of "
                          f"{cs.imagersize[0]}x{cs.imagersize[1]} images: not the same camera")
    if not a.outdir and os.path.isdir(test):
        vnl = f"{test} (detected, not kept: give --outdir to keep the corners)"
    warp = model.optimization_inputs().get("calobject_warp") if model.optimization_inputs() else None
    h = heldout(model, cs.corners, cs.layout.spacing_m, calobject_warp=warp)
    if a.json:
        _write_json({"model": model_path, "test": vnl, "mean_px": h.mean, "rms_px": h.rms, "boards": h.boards,
                     "points": h.points, "per_pose": dict(zip(cs.names, h.per_pose.tolist()))})
        return 0
    print("| pose | corners | MRE, px |")
    print("|---|---|---|")
    for n, e, v in zip(cs.names, h.errors, h.per_pose):
        print(f"| {n} | {int(np.isfinite(e).sum())} | {report.fmt(v)} |")
    print(f"\nheld-out MRE of {model_path} on {vnl}: {h.mean:.4f} px mean, {h.rms:.4f} px RMS, "
          f"{h.boards} boards, {h.points} corners")
    return 0


def mode_models(a, path_a: str, path_b: str) -> int:
    ma, mb = load_model(path_a, True), load_model(path_b, True)
    cv = cross_validate(ma, mb, gridn_width=a.gridn, distance=a.distance)
    s = cv.summary()
    if a.outdir:
        make_folder(a.outdir)
        fig = plots.heatmaps(cv.q, [("|projection diff| A vs B", cv.diff), ("uncertainty A (1-sigma)", cv.u0),
                                    ("uncertainty B (1-sigma)", cv.u1)], ma.imagersize())
        fn = os.path.join(a.outdir, "crossval.png")
        fig.savefig(fn, dpi=110)
        plt.close(fig)
        say(f"rotstar-crossval: wrote {fn}")
    if a.json:
        _write_json({"A": path_a, "B": path_b, **s})
    else:
        print(f"diff median {s['diff_median_px']:.4f} px (p95 {s['diff_p95_px']:.4f}), uA+uB median "
              f"{s['unc_median_px']:.4f} px, ratio {s['ratio_median']:.2f}: {s['verdict']} "
              f"(implied rotation {s['rotation_deg']:.3f} deg)")
    return 0


def mode_sets(a, sets: dict) -> int:
    """sets: {name: (vnl A, vnl B)}"""
    progress = Progress(3 * len(sets))  # two calibrations and one evaluation per set
    c = compare_sets(sets, a.outdir, a.lensmodel, a.knots_x, a.pattern, a.imagersize, a.gridn, a.distance, a.jobs,
                     a.label, log=lambda s: say(s if s.startswith("[") else f"rotstar-crossval: {s}"),
                     progress=progress.step, glass_mm=a.glass, glass_index=a.glass_index)
    crossval_report.draw(c, a.outdir)
    _write_json(c.to_json(), os.path.join(a.outdir, "results.json"))
    say(f"rotstar-crossval: wrote {os.path.join(a.outdir, 'results.json')}")
    if a.json:
        _write_json(c.to_json())
    else:
        print(crossval_report.markdown(c))
        if c.glass is not None:
            print("\n" + crossval_report.glass_markdown(c))
    return 0 if c.failed < c.sets else 1  # a set that cannot be calibrated is a result too


def main(argv=None) -> int:
    return run("rotstar-crossval", _main, argv)


class UsageError(ValueError):
    """Inputs that do not make a mode (exit status 2); one line"""


def _main(argv=None) -> int:
    a = parse_args(argv)
    try:
        kinds = [_kind(p) for p in a.inputs]
        if len(a.inputs) == 2 and kinds[0] == "model" and kinds[1] != "model":
            return mode_heldout(a, *a.inputs)
        if len(a.inputs) == 2 and kinds == ["model", "model"]:
            return mode_models(a, *a.inputs)
        return mode_sets(a, corner_sets(a, kinds))
    except (SourceError, dataset.DatasetError, UsageError) as e:
        say(f"rotstar-crossval: {e}")
        return 2


def corner_sets(a, kinds) -> dict:
    """{name: (vnl A, vnl B)} of the inputs, datasets detected into a.outdir; UsageError when they make no sets"""
    if len(a.inputs) not in (0, 1, 2) or "model" in kinds or (not a.inputs and not a.set):
        raise UsageError("give MODEL TEST, MODEL_A MODEL_B, SEQ, A B, or --set NAME A B (see --help)")
    if not a.outdir:
        raise UsageError("comparing two groups needs --outdir for the models and figures")
    make_folder(a.outdir)
    if a.methods and a.inputs and (len(a.inputs) == 1 or kinds != ["dataset", "dataset"]):
        raise UsageError("--methods needs two dataset folders")
    sets = {}
    if len(a.inputs) == 1:
        sets["rotstar"] = split_recording(a, a.inputs[0], kinds[0])
    elif a.inputs:
        sets.update(group_sets(a, kinds))
    for name, va, vb in a.set:
        if name in sets:
            raise UsageError(f"corner set {name!r} given twice")
        sets[name] = (va, vb)
    return sets


def split_recording(a, path: str, kind: str) -> tuple[str, str]:
    """One recording (a dataset or a corners.vnl) split into two interleaved groups: their vnl files"""
    vnl = detect_default(path, a.outdir, "all", a.jobs) if kind == "dataset" else path
    va, vb = (os.path.join(a.outdir, "rotstar", f"{s}.vnl") for s in "AB")
    na, nb = split_interleaved(vnl, va, vb)
    say(f"rotstar-crossval: split {vnl} into {va} ({na} boards) and {vb} ({nb} boards), interleaved")
    a.label = a.label or default_label(path, path)  # the recording's name
    return va, vb


def group_sets(a, kinds) -> dict:
    """The corner sets of two pose groups A and B: rotstar's, or with --methods each method's"""
    if not a.methods:
        return {DEFAULT_SET: tuple(detect_default(path, a.outdir, side, a.jobs)
                                   if k == "dataset" else path for side, path, k in zip("AB", a.inputs, kinds))}
    known = dataset_methods()
    methods = known if a.methods == "all" else [m.strip() for m in a.methods.split(",")]
    bad = [m for m in methods if m not in known]
    if bad:
        raise UsageError(f"unknown methods {bad}; known: {', '.join(known)}")
    va = detect_dataset(a.inputs[0], methods, a.outdir, "A", a.jobs)
    vb = detect_dataset(a.inputs[1], methods, a.outdir, "B", a.jobs)
    return {m: (va[m], vb[m]) for m in methods}

if __name__ == "__main__":
    sys.exit(main())

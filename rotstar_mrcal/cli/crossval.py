"""rotstar-crossval: held-out reprojection error and mrcal's cross-validation of calibrations"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import json
import os
import sys

import numpy as np

from .. import dataset
from ..vnl import write_corners
from ..validate import calibrate as cal
from ..validate import compare, plots, report
from ..methods import description
from ..validate.cornersets import dataset_methods, detect_methods
from ..validate.sources import SourceError, load_corner_set
from .calibrate import calibration_argv, focal_seed, resolve_lensmodel
from .common import Progress, say

DESCRIPTION = """\
Validate calibrations the way the rotating-star paper and mrcal do it.

  rotstar-crossval MODEL TEST
      The paper's metric: every board of TEST (a corners.vnl, or a dataset
      folder, which is detected first) solved with MODEL's intrinsics fixed;
      the mean reprojection error (MRE) per pose and overall.

  rotstar-crossval MODEL_A MODEL_B
      mrcal's cross-validation of two calibrations of one camera: their
      projection difference over the imager against the sum of their
      projection uncertainties (both need mrcal's optimization_inputs).

  rotstar-crossval A B  [--methods ...] [--set NAME A_VNL B_VNL ...]
      Two pose groups of one camera (datasets or corners.vnl files):
      calibrate each, test each model on the other group (both directions),
      cross-validate the two models, and, for simulated datasets, compare
      each with the true camera. With --methods (datasets only) or --set, the
      same for several corner sets of the same poses, side by side.

Commands are printed on stderr before they run. stdout gets the results
table (Markdown) or, with --json, the results. With --outdir, the models,
the figures (PNG) and results.json are written there; rotstar-report turns
one or more such folders into a report.
"""

EPILOG = f"""\
methods for --methods: {', '.join(dataset_methods())} (or 'all')

examples:
  rotstar-crossval cal/camera-0.cameramodel test-seq/
  rotstar-crossval groupA/ groupB/ --lensmodel opencv8 --outdir xval/
  rotstar-crossval groupA/ groupB/ --methods all --outdir xval/ --label "4000 us"
  rotstar-crossval --set rotstar A/rotstar.vnl B/rotstar.vnl --set mrgingham A/mrg.vnl B/mrg.vnl
"""


def parse_args(argv=None):
    p = argparse.ArgumentParser(prog="rotstar-crossval", description=DESCRIPTION, epilog=EPILOG,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("inputs", nargs="*", help="MODEL TEST, MODEL_A MODEL_B, or A B (datasets or corners.vnl)")
    p.add_argument("--set", nargs=3, action="append", default=[], metavar=("NAME", "A", "B"),
                   help="a named corner set of both groups (corners.vnl files); repeatable")
    p.add_argument("--methods", help="detect these methods on the datasets A and B (comma-separated, or 'all')")
    p.add_argument("--outdir", help="write models, figures and results.json here (required for A B)")
    p.add_argument("--label", help="name of this condition in the tables (e.g. the exposure)")
    p.add_argument("--lensmodel", default="splined",
                   help="lens model of the calibrations: 'splined' (default), 'opencv8' or LENSMODEL_...")
    p.add_argument("--knots-x", type=int, default=cal.DEFAULT_KNOTS_X, help="splined model: knots across")
    p.add_argument("--pattern", help="pattern.json (or its folder) when a corners.vnl's dataset cannot be found")
    p.add_argument("--imagersize", type=int, nargs=2, metavar=("W", "H"),
                   help="imager size when the images cannot be read")
    p.add_argument("--distance", type=float,
                   help="compare projections at this range, metres (default: infinity, as mrcal)")
    p.add_argument("--gridn", type=int, default=40, help="grid points across the imager (default 40)")
    p.add_argument("--jobs", "-j", type=int, default=1, help="parallel calibrations and evaluations")
    p.add_argument("--json", action="store_true", help="print the results as JSON instead of a table")
    return p.parse_args(argv)


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
        with open(path, "w") as f:
            f.write(text)


# ---------------------------------------------------------------------------
# detection of datasets
# ---------------------------------------------------------------------------
def _detect_pose(seq, pose, layout, methods):
    p = dataset.load_pose(seq, pose, layout)
    cb = p.checkerboard
    found = detect_methods(p.rotstar, layout, p.full_scale, cb, methods)
    cbfile = os.path.join(seq, pose, next(f["file"] for f in layout.frames() if f["kind"] == "checkerboard"))
    return pose, p.first_file, cbfile, found


def detect_dataset(seq: str, methods, outdir: str, side: str, jobs: int = 1) -> dict[str, str]:
    """Detect every method on a dataset; write outdir/<method>/<side>.vnl; {method: vnl}"""
    _, layout = dataset.read_pattern(seq)
    poses = dataset.list_poses(seq)
    if not poses:
        raise SourceError(f"{seq}: no pose folders")
    say(f"rotstar-crossval: detecting {', '.join(methods)} on {seq} ({len(poses)} poses)")
    progress = Progress(len(poses))
    res = {}
    if jobs > 1:
        with cf.ProcessPoolExecutor(jobs) as ex:
            futs = [ex.submit(_detect_pose, seq, p, layout, methods) for p in poses]
            for f in cf.as_completed(futs):
                r = f.result()
                res[r[0]] = r
                progress.step(r[0], ", ".join(f"{m} {'ok' if v.corners is not None else 'none'}"
                                              for m, v in r[3].items()))
    else:
        for p in poses:
            r = _detect_pose(seq, p, layout, methods)
            res[p] = r
            progress.step(p, ", ".join(f"{m} {'ok' if v.corners is not None else 'none'}" for m, v in r[3].items()))
    out = {}
    for m in methods:
        boards, weights = [], []
        for p in poses:
            _, rfile, cbfile, found = res[p]
            fn = rfile if m.startswith("rotstar") else cbfile
            boards.append((fn, found[m].corners))
            weights.append(found[m].weights)
        path = os.path.join(outdir, m, f"{side}.vnl")
        os.makedirs(os.path.dirname(path), exist_ok=True)
        with open(path, "w") as f:
            write_corners(f, boards, weights if m == "rotstar-weighted" else None)
        out[m] = path
    return out


def load_model(path: str, need_inputs: bool = False):
    """mrcal.cameramodel(path), or a SourceError naming the file and the reason in one line"""
    import mrcal

    try:
        m = mrcal.cameramodel(path)
    except Exception:  # mrcal raises a plain Exception listing every parser's complaint
        raise SourceError(f"{path}: not a camera model mrcal can parse") from None
    if need_inputs and not m.optimization_inputs():
        raise SourceError(f"{path}: has no optimization_inputs (needed for the uncertainty); "
                          "use a model written by mrcal-calibrate-cameras")
    return m


# ---------------------------------------------------------------------------
# modes
# ---------------------------------------------------------------------------
def mode_heldout(a, model_path: str, test: str) -> int:
    from ..validate.heldout import heldout

    model = load_model(model_path)
    if _kind(test) == "dataset":
        outdir = a.outdir or "."
        vnl = detect_dataset(test, ["rotstar"], outdir, "test", a.jobs)["rotstar"]
    else:
        vnl = test
    cs = load_corner_set(vnl, a.pattern, a.imagersize, truth=False)
    if tuple(model.imagersize()) != tuple(cs.imagersize):
        say(f"rotstar-crossval: warning: model imager {tuple(model.imagersize())} != test {cs.imagersize}")
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
    import matplotlib.pyplot as plt

    from ..validate.crossval import cross_validate

    ma, mb = load_model(path_a, True), load_model(path_b, True)
    cv = cross_validate(ma, mb, gridn_width=a.gridn, distance=a.distance)
    s = cv.summary()
    if a.outdir:
        os.makedirs(a.outdir, exist_ok=True)
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


def _calibrate(job):
    """Worker: run one printed mrcal-calibrate-cameras command (in this process: no start-up cost)"""
    name, side, argv = job
    try:
        cal.run_calibration(argv, in_process=True)
        return name, side, None
    except cal.CalibrationError as e:
        return name, side, str(e)


def _evaluate(method, path_a, path_b, test_a, test_b, seq_a, seq_b, gridn, distance):
    """Worker: one method's evaluation from its two model files"""
    import mrcal

    from ..simulate import load_truth

    def truth(seq):
        if seq and os.path.exists(os.path.join(seq, "truth.json")):
            t = load_truth(seq)
            return compare.Truth(t.model, t.rt_cam_board)
        return None

    return compare.evaluate(method, mrcal.cameramodel(path_a), mrcal.cameramodel(path_b), test_a, test_b,
                            truth(seq_a), truth(seq_b), gridn_width=gridn, distance=distance)


def mode_sets(a, sets: dict) -> int:
    """sets: {name: (vnl A, vnl B)}"""
    import matplotlib.pyplot as plt

    outdir = a.outdir
    os.makedirs(outdir, exist_ok=True)
    loaded, failed = {}, {}
    for name, (va, vb) in sets.items():
        try:
            loaded[name] = (load_corner_set(va, a.pattern, a.imagersize),
                            load_corner_set(vb, a.pattern, a.imagersize))
            few = [f"{s}: {len(c.files)} boards" for s, c in zip("AB", loaded[name]) if len(c.files) < cal.MIN_BOARDS]
            if few:
                del loaded[name]
                raise SourceError(f"too few boards to calibrate ({', '.join(few)}; need {cal.MIN_BOARDS})")
        except SourceError as e:  # e.g. a detector that found no board in a group: a result, not a crash
            say(f"rotstar-crossval: {name}: {e}")
            failed[name] = [str(e)]
    if not loaded:
        raise SourceError("no corner set could be read")
    first = next(iter(loaded.values()))[0]
    lensmodel = resolve_lensmodel(a.lensmodel, first.imagersize, focal_seed(first), a.knots_x)
    if "SPLINED" in lensmodel and min(len(c.files) for p in loaded.values() for c in p) < cal.SPLINED_MIN_BOARDS:
        say(f"rotstar-crossval: warning: fewer than {cal.SPLINED_MIN_BOARDS} boards in a group for a splined "
            "model; consider --lensmodel opencv8")

    jobs = []
    for name, (ca, cb) in loaded.items():
        for side, cs in (("A", ca), ("B", cb)):
            jobs.append((name, side, calibration_argv(cs, os.path.join(outdir, name, side), lensmodel)))
    for name, side, argv in jobs:
        say(f"[{name} {side}] $ {cal.command_line(argv)}")

    progress = Progress(len(jobs))
    with cf.ProcessPoolExecutor(max(1, a.jobs)) as ex:
        for name, side, err in ex.map(_calibrate, jobs):
            progress.step(f"calibrate {name} {side}", "failed" if err else "done")
            if err:
                failed.setdefault(name, []).append(f"{side}: {err}")
    for name, errs in failed.items():
        if name in loaded:
            say(f"rotstar-crossval: {name}: calibration failed: " + "; ".join(errs))

    todo = [n for n in loaded if n not in failed]
    model = {n: {s: os.path.join(outdir, n, s, "camera-0.cameramodel") for s in "AB"} for n in todo}
    args = {n: (n, model[n]["A"], model[n]["B"], loaded[n][0].test_set(), loaded[n][1].test_set(),
                loaded[n][0].seq, loaded[n][1].seq, a.gridn, a.distance) for n in todo}
    evals = {}
    progress = Progress(len(todo))
    if a.jobs > 1 and len(todo) > 1:
        with cf.ProcessPoolExecutor(min(a.jobs, len(todo))) as ex:
            futs = {ex.submit(_evaluate, *args[n]): n for n in todo}
            for f in cf.as_completed(futs):
                evals[futs[f]] = f.result()
                progress.step(f"evaluate {futs[f]}", "done")
    else:
        for n in todo:
            evals[n] = _evaluate(*args[n])
            progress.step(f"evaluate {n}", "done")

    # figures: one colour scale for every method's maps, set by the best method (worse ones saturate)
    cvs = [e.crossval for e in evals.values() if e.crossval is not None]
    cbmax = plots.nice_max(max(3 * min(c.diff_median for c in cvs),
                               2 * float(np.median([c.unc_median for c in cvs])))) if cvs else None
    methods_out = []
    for n in sets:
        if n in failed:
            methods_out.append({"method": n, "description": description(n), "error": "; ".join(failed[n]),
                                "heldout": None, "crossval": None, "truth": None})
            continue
        e = evals[n]
        ca, cb = loaded[n]
        panels, points = [], []
        if e.crossval is not None:
            panels += [("|projection diff| A vs B", e.crossval.diff), ("uncertainty A (1-sigma)", e.crossval.u0),
                       ("uncertainty B (1-sigma)", e.crossval.u1)]
            points += [None, ca.corners.reshape(-1, 2), cb.corners.reshape(-1, 2)]
        for side, cs in (("A", ca), ("B", cb)):
            if side in e.truth:
                panels.append((f"calibrated on {side} vs true model", e.truth[side].error))
                points.append(cs.corners.reshape(-1, 2))
        figs = {}
        if panels:
            fig = plots.heatmaps(e.crossval.q if e.crossval is not None else e.truth["A"].q, panels,
                                 ca.imagersize, cbmax=cbmax, points=points, title=f"{n}: {a.label or ''}".rstrip(": "))
            figs["maps"] = f"{n}-maps.png"
            fig.savefig(os.path.join(outdir, figs["maps"]), dpi=100)
            plt.close(fig)
        methods_out.append({**e.summary, "description": description(n), "figures": figs,
                            "models": {s: os.path.relpath(model[n][s], outdir) for s in "AB"},
                            "corners": {"A": os.path.abspath(ca.vnl), "B": os.path.abspath(cb.vnl)}})
    per_pose = [(f"calibrated on A, tested on B ({a.label or ''})",
                 {m["method"]: m["heldout"]["A->B"]["per_pose"] for m in methods_out if m.get("heldout")}),
                (f"calibrated on B, tested on A ({a.label or ''})",
                 {m["method"]: m["heldout"]["B->A"]["per_pose"] for m in methods_out if m.get("heldout")})]
    figures = {}
    if any(p[1] for p in per_pose):
        fig = plots.per_pose(per_pose)
        figures["per_pose"] = "per-pose.png"
        fig.savefig(os.path.join(outdir, figures["per_pose"]), dpi=100)
        plt.close(fig)
    first_a, first_b = next(iter(loaded.values()))
    result = {
        "format": "rotstar-crossval/1",
        "label": a.label or f"{os.path.basename(first_a.seq or first_a.vnl)} vs {os.path.basename(first_b.seq or first_b.vnl)}",
        "groups": {"A": first_a.seq or first_a.vnl, "B": first_b.seq or first_b.vnl},
        "lensmodel": lensmodel,
        "distance_m": a.distance,
        "gridn": a.gridn,
        "methods": methods_out,
        "figures": figures,
        "commands": [cal.command_line(argv) for _, _, argv in jobs],
    }
    _write_json(result, os.path.join(outdir, "results.json"))
    say(f"rotstar-crossval: wrote {os.path.join(outdir, 'results.json')}")
    if a.json:
        _write_json(result)
    else:
        print(report.detail(result).markdown())
    return 0 if len(failed) < len(sets) else 1  # a set that cannot be calibrated is a result too


def main(argv=None) -> int:
    a = parse_args(argv)
    try:
        kinds = [_kind(p) for p in a.inputs]
        if len(a.inputs) == 2 and kinds[0] == "model" and kinds[1] != "model":
            return mode_heldout(a, *a.inputs)
        if len(a.inputs) == 2 and kinds == ["model", "model"]:
            return mode_models(a, *a.inputs)
        if len(a.inputs) not in (0, 2) or "model" in kinds or (not a.inputs and not a.set):
            say("rotstar-crossval: give MODEL TEST, MODEL_A MODEL_B, A B, or --set NAME A B (see --help)")
            return 2
        if not a.outdir:
            say("rotstar-crossval: comparing two groups needs --outdir for the models and figures")
            return 2
        sets = {}
        if a.inputs:
            if a.methods:
                if kinds != ["dataset", "dataset"]:
                    say("rotstar-crossval: --methods needs two dataset folders")
                    return 2
                known = dataset_methods()
                methods = known if a.methods == "all" else [m.strip() for m in a.methods.split(",")]
                bad = [m for m in methods if m not in known]
                if bad:
                    say(f"rotstar-crossval: unknown methods {bad}; known: {', '.join(known)}")
                    return 2
                va = detect_dataset(a.inputs[0], methods, a.outdir, "A", a.jobs)
                vb = detect_dataset(a.inputs[1], methods, a.outdir, "B", a.jobs)
                sets.update({m: (va[m], vb[m]) for m in methods})
            else:
                pair = []
                for side, (path, k) in zip("AB", zip(a.inputs, kinds)):
                    pair.append(detect_dataset(path, ["rotstar"], a.outdir, side, a.jobs)["rotstar"]
                                if k == "dataset" else path)
                sets["rotstar"] = tuple(pair)
        for name, va, vb in a.set:
            if name in sets:
                say(f"rotstar-crossval: corner set {name!r} given twice")
                return 2
            sets[name] = (va, vb)
        return mode_sets(a, sets)
    except (SourceError, dataset.DatasetError) as e:
        say(f"rotstar-crossval: {e}")
        return 2


if __name__ == "__main__":
    sys.exit(main())

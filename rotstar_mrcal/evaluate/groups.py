"""Several corner sets of two pose groups: calibrate each, test each model on the other group, cross-validate

SYNOPSIS

    from rotstar_mrcal.evaluate.groups import compare_sets
    c = compare_sets({"rotstar": ("xval/rotstar/A.vnl", "xval/rotstar/B.vnl")}, "xval", label="4000 us")
    c.to_json()                      # what rotstar-crossval writes as xval/results.json
    c.complete                       # every set calibrated
    report.crossval.draw(c, "xval")  # its figures (rotstar-crossval draws them; evaluation does not)

rotstar-crossval's comparison mode. For each named corner set (a detector's
corners of the same two pose groups A and B): mrcal-calibrate-cameras on
each group (the lean model by default, calibrate.resolve_lensmodel; the
commands run in worker processes), then compare.evaluate on the two models
(held-out error both ways, mrcal's cross-validation, and on simulated data
each model against the truth). What the heat maps and the per-pose plot
show is kept with the result (Comparison.maps, not in its JSON), for
report.crossval to draw.
The condition's label defaults to default_label's: the recording's name
when A and B are the two halves of one, else "A vs B". A set that cannot be read or
calibrated is reported in the result, not raised.

The screen's cover glass (calibrate.glass, the screen's and so every
method's): glass_mm 0 (the default) evaluates the plain mrcal calibrations;
a thickness (mm) corrects each of them for that glass, None estimates it
from each calibration as rotstar-calibrate does and corrects when the
estimate is a plausible glass (else the plain model stays, with the reason).
The corrected model (<set>/<group>/glass/camera-0.cameramodel) is then the
one evaluated; the set's "glass" entry holds, per group, what correct_glass
found and, on simulated data, the plain model against the truth. A
corrected model's held-out corners (the other group's) are corrected for
the same glass from their own solved poses (evaluate.heldout).
"""

from __future__ import annotations

import concurrent.futures as cf
import dataclasses
import multiprocessing
import os

import mrcal
import numpy as np

from rotstar_mrcal.calibrate import solve as cal
from rotstar_mrcal.calibrate.checks import SPLINED_MIN_BOARDS
from rotstar_mrcal.calibrate.glass import correct_glass, glass_line
from rotstar_mrcal.evaluate import compare
from rotstar_mrcal.evaluate.truth import truth_error, truth_poses_of
from rotstar_mrcal.calibrate.solve import calibration_argv, focal_seed, resolve_lensmodel
from rotstar_mrcal.peers.registry import description
from rotstar_mrcal.calibrate.cornerset import SourceError, load_corner_set
from rotstar_mrcal.optics.refraction import DEFAULT_INDEX, Glass
from rotstar_mrcal.simulate.dataset import load_truth

_WORKERS = multiprocessing.get_context("forkserver")
"""The calibrations' and evaluations' processes: no fork of this threaded process (OpenCV, BLAS; see parallel)"""

FORMAT = "rotstar-crossval/1"


@dataclasses.dataclass
class MapPanels:
    """What one corner set's heat-map figure shows: panels of (title, (Ny, Nx) px) on the grid q, each with
    the corners a calibration saw (or None); its file name is figures["maps"] of the set's entry"""

    method: str
    q: np.ndarray
    panels: list
    points: list
    imagersize: tuple
    title: str
    figures: dict  # the set's "figures" entry in methods, filled in when it is drawn


@dataclasses.dataclass
class Comparison:
    """The result of compare_sets; owns its JSON form (results.json, read by rotstar-report)"""

    label: str
    groups: dict
    lensmodel: str
    distance_m: float | None
    gridn: int
    methods: list  # per set: compare.evaluate's summary + description, figures, models, corners; or an error
    figures: dict
    commands: list
    failed: int = 0
    sets: int = 0
    maps: list = dataclasses.field(default_factory=list, repr=False)  # MapPanels per set, to draw
    glass: dict | None = None  # {"mm": the thickness given (None: estimated), "index": n}; None: no correction

    @property
    def complete(self) -> bool:
        return self.failed == 0

    def to_json(self) -> dict:
        return {"format": FORMAT, "label": self.label, "groups": self.groups, "lensmodel": self.lensmodel,
                "distance_m": self.distance_m, "gridn": self.gridn, "methods": self.methods,
                "figures": self.figures, "commands": self.commands, "glass": self.glass}

    @classmethod
    def from_json(cls, d: dict) -> "Comparison":
        if d.get("format") != FORMAT:
            raise ValueError("not a rotstar-crossval results file")
        return cls(d.get("label", ""), d.get("groups", {}), d.get("lensmodel", ""), d.get("distance_m"),
                   d.get("gridn", 0), d.get("methods", []), d.get("figures", {}), d.get("commands", []),
                   sum(1 for m in d.get("methods", []) if m.get("error")), len(d.get("methods", [])),
                   glass=d.get("glass"))

    def per_pose(self) -> list:
        """[(title, {method: {pose: held-out MRE}})] both ways, for the per-pose plot (empty entries: none)"""
        return [(f"calibrated on {a}, tested on {b} ({self.label})",
                 {m["method"]: m["heldout"][f"{a}->{b}"]["per_pose"] for m in self.methods if m.get("heldout")})
                for a, b in (("A", "B"), ("B", "A"))]


def default_label(a: str, b: str) -> str:
    """The name of a condition whose groups are the datasets or corners files a and b

    SYNOPSIS

        >>> default_label("lab/seq", "lab/seq")              # the two halves of one recording
        'seq'
        >>> default_label("seq/corners.vnl", "seq/corners.vnl")
        'seq'
        >>> default_label("near/", "far/corners.vnl")
        'near vs far'
    """
    def name(p):
        p = os.path.normpath(os.path.abspath(p))
        return os.path.basename(os.path.dirname(p)) if os.path.basename(p) == "corners.vnl" else os.path.basename(p)

    na, nb = name(a), name(b)
    return na if na == nb else f"{na} vs {nb}"


def _calibrate(job):
    """Worker: run one printed mrcal-calibrate-cameras command (in this process: no start-up cost), then the
    cover glass's correction (glass_mm 0: none); (name, side, error or None, the glass's JSON or None)"""
    name, side, argv, glass_mm, glass_index = job
    try:
        model = cal.run_calibration(argv, in_process=True)
    except cal.CalibrationError as e:
        return name, side, str(e), None
    if glass_mm == 0:
        return name, side, None, None
    try:
        return name, side, None, glass_correction(model, argv[argv.index("--outdir") + 1], glass_mm, glass_index)
    except (ValueError, RuntimeError, np.linalg.LinAlgError) as e:  # mrcal's solve refused: the plain model stays
        return name, side, None, {"error": f"{type(e).__name__}: {e}", "applied": False, "model": None}


def glass_correction(model: mrcal.cameramodel, outdir: str, glass_mm: float | None, index: float) -> dict:
    """correct_glass's JSON for a plain calibration written in outdir; when applied, the corrected model written
    as outdir/glass/camera-0.cameramodel (its path under "model"; else "model" is None)"""
    g = correct_glass(model, glass_mm, index)
    d = {**g.to_json(), "model": None}
    if g.applied:
        d["model"] = os.path.join(outdir, "glass", "camera-0.cameramodel")
        os.makedirs(os.path.dirname(d["model"]), exist_ok=True)
        g.model.write(d["model"])
    return d


def _true_camera(seq):
    if seq and os.path.exists(os.path.join(seq, "truth.json")):
        t = load_truth(seq)
        return compare.TrueCamera(t.model, t.rt_cam_board)
    return None


def _evaluate(method, path_a, path_b, test_a, test_b, seq_a, seq_b, gridn, distance, plain=None, glass=None):
    """Worker: one method's evaluation from its two model files; and {side: the plain model's truth error
    summary} for the sides whose plain model (plain: {side: path}) was corrected for a cover glass
    (glass: {side: its Glass}, what its held-out corners are corrected for)"""
    truth = {"A": _true_camera(seq_a), "B": _true_camera(seq_b)}
    glass = glass or {}
    e = compare.evaluate(method, mrcal.cameramodel(path_a), mrcal.cameramodel(path_b), test_a, test_b,
                         truth["A"], truth["B"], gridn_width=gridn, distance=distance, glass_a=glass.get("A"),
                         glass_b=glass.get("B"))
    before = {}
    for side, path in (plain or {}).items():
        t = truth[side]
        if t is not None:
            m = mrcal.cameramodel(path)
            before[side] = truth_error(m, t.model, truth_poses_of(m, t.rt_cam_board), gridn_width=gridn,
                                       distance=distance).summary()
    return e, before


def compare_sets(sets: dict, outdir: str, lensmodel: str = "auto", knots_x: int = cal.DEFAULT_KNOTS_X,
                 pattern: str | None = None, imagersize=None, gridn: int = 40, distance: float | None = None,
                 jobs: int = 1, label: str | None = None, log=None, progress=None, glass_mm: float | None = 0.0,
                 glass_index: float = DEFAULT_INDEX) -> "Comparison":
    """sets: {name: (vnl A, vnl B)}; calibrate, test, cross-validate, draw; the Comparison (module doc)

    log(line): messages (commands, failures, the cover glass); progress(label,
    message): one per calibration and evaluation. glass_mm: the screen's
    cover glass (module doc; 0 none, None estimated). Raises SourceError when
    no set can be read.
    """
    log = log or (lambda s: None)
    step = progress or (lambda lbl, msg: None)
    os.makedirs(outdir, exist_ok=True)
    loaded, failed = {}, {}
    for name, (va, vb) in sets.items():
        try:
            loaded[name] = (load_corner_set(va, pattern, imagersize),
                            load_corner_set(vb, pattern, imagersize))
            few = [f"{s}: {len(c.files)} boards" for s, c in zip("AB", loaded[name]) if len(c.files) < cal.MIN_BOARDS]
            if few:
                del loaded[name]
                raise SourceError(f"too few boards to calibrate ({', '.join(few)}; need {cal.MIN_BOARDS})")
        except SourceError as e:  # e.g. a detector that found no board in a group: a result, not a crash
            log(f"{name}: {e}")
            failed[name] = [str(e)]
    if not loaded:
        raise SourceError("no corner set could be read")
    first = next(iter(loaded.values()))[0]
    lensmodel = resolve_lensmodel(lensmodel, first.imagersize, focal_seed(first, check=False), knots_x)
    if "SPLINED" in lensmodel and min(len(c.files) for p in loaded.values() for c in p) < SPLINED_MIN_BOARDS:
        log(f"warning: fewer than {SPLINED_MIN_BOARDS} boards in a group for a splined model; "
            "consider the default (lean) model")

    cjobs = []
    for name, (ca, cb) in loaded.items():
        for side, cs in (("A", ca), ("B", cb)):
            cjobs.append((name, side, calibration_argv(cs, os.path.join(outdir, name, side), lensmodel),
                          glass_mm, glass_index))
    for name, side, argv, _, _ in cjobs:
        log(f"[{name} {side}] $ {cal.command_line(argv)}")
    if glass_mm != 0:
        log("cover glass: " + ("estimated from each calibration and taken out when plausible" if glass_mm is None
                               else f"each calibration corrected for {glass_mm:g} mm (index {glass_index:g})"))

    glass = {}
    with cf.ProcessPoolExecutor(max(1, jobs), mp_context=_WORKERS) as ex:
        for name, side, err, g in ex.map(_calibrate, cjobs):
            step(f"calibrate {name} {side}", "failed" if err else "done")
            if err:
                failed.setdefault(name, []).append(f"{side}: {err}")
            if g is not None:
                glass.setdefault(name, {})[side] = g
                log(f"[{name} {side}] " + (f"cover glass: not corrected: {g['error']}" if "error" in g
                                           else glass_line(g)))
    for name, errs in failed.items():
        if name in loaded:
            log(f"{name}: calibration failed: " + "; ".join(errs))

    todo = [n for n in loaded if n not in failed]
    plain = {n: {s: os.path.join(outdir, n, s, "camera-0.cameramodel") for s in "AB"} for n in todo}
    model = {n: {s: glass.get(n, {}).get(s, {}).get("model") or plain[n][s] for s in "AB"} for n in todo}
    args = {n: (n, model[n]["A"], model[n]["B"], loaded[n][0].test_set(), loaded[n][1].test_set(),
                loaded[n][0].seq, loaded[n][1].seq, gridn, distance,
                {s: plain[n][s] for s in "AB" if model[n][s] != plain[n][s]},
                {s: Glass.mm(g["thickness_mm"], g["index"]) for s, g in glass.get(n, {}).items() if g.get("applied")})
            for n in todo}
    evals = {}
    if jobs > 1 and len(todo) > 1:
        with cf.ProcessPoolExecutor(min(jobs, len(todo)), mp_context=_WORKERS) as ex:
            futs = {ex.submit(_evaluate, *args[n]): n for n in todo}
            for f in cf.as_completed(futs):
                evals[futs[f]] = f.result()
                step(f"evaluate {futs[f]}", "done")
    else:
        for n in todo:
            evals[n] = _evaluate(*args[n])
            step(f"evaluate {n}", "done")

    first_a, first_b = next(iter(loaded.values()))
    label = label or default_label(first_a.seq or first_a.vnl, first_b.seq or first_b.vnl)
    methods_out, maps = [], []
    for n in sets:
        if n in failed:
            methods_out.append({"method": n, "description": description(n), "error": "; ".join(failed[n]),
                                "heldout": None, "crossval": None, "truth": None})
            continue
        e, before = evals[n]
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
            maps.append(MapPanels(n, e.crossval.q if e.crossval is not None else e.truth["A"].q, panels, points,
                                  ca.imagersize, f"{n}: {label}", figs))
        methods_out.append({**e.summary, "description": description(n), "figures": figs,
                            "models": {s: os.path.relpath(model[n][s], outdir) for s in "AB"},
                            "corners": {"A": os.path.abspath(ca.vnl), "B": os.path.abspath(cb.vnl)},
                            "glass": _glass_entry(glass.get(n), before, plain[n], outdir)})
    return Comparison(
        label=label,
        groups={"A": first_a.seq or first_a.vnl, "B": first_b.seq or first_b.vnl},
        lensmodel=lensmodel, distance_m=distance, gridn=gridn, methods=methods_out, figures={},
        commands=[cal.command_line(argv) for _, _, argv, _, _ in cjobs], failed=len(failed), sets=len(sets),
        maps=maps, glass=None if glass_mm == 0 else {"mm": glass_mm, "index": glass_index})


def _glass_entry(found: dict | None, before: dict, plain: dict, outdir: str) -> dict | None:
    """A set's "glass" entry: per group what correct_glass found, the paths (relative to outdir) of its
    corrected model (None when not applied) and of the plain one, and the plain model against the truth
    ("truth_plain", simulated data; None when not corrected: the set's "truth" is the plain model's)"""
    if not found:
        return None
    return {s: {**g, "model": g.get("model") and os.path.relpath(g["model"], outdir),
                "plain_model": os.path.relpath(plain[s], outdir), "truth_plain": before.get(s)}
            for s, g in found.items()}

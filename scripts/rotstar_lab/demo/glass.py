"""make demo's cover glass: every method's calibrations plain and corrected for the known glass, and the estimate

SYNOPSIS

    from rotstar_lab.demo import glass
    res = json.load(open("demo-out/e4000/xval/results.json"))    # rotstar-crossval --glass 0.7 wrote it
    est = glass.estimates(res, "demo-out/e4000/xval")            # {method: {group: estimate's JSON}}
    t = glass.table(res, est)                                     # report.table.Table
    print(t.markdown(), glass.summary(res, est))

The demo's screen has GLASS_MM of cover glass (scene.GLASS_MM). rotstar-crossval
--glass corrects each calibration for it (calibrate.glass.correct_glass with
the thickness given) and keeps the plain model's error against the truth
beside the corrected one's. Here, for one exposure, each plain model's
thickness is also estimated from its own data (correct_glass without a
thickness, what rotstar-calibrate does by default): the estimate, its sigma,
whether it was applied (a plausible glass: over 0 by MIN_SIGMAS sigma, at most
MAX_PLAUSIBLE_MM) and, when applied, the re-solved model against the truth.
Under the demo's coma, a method whose corners carry a tilt-dependent error
(issue 24) gets an estimate that is not the glass; it is reported, not applied.
"""

from __future__ import annotations

import os

import mrcal
import numpy as np

from rotstar_mrcal.calibrate.glass import correct_glass
from rotstar_mrcal.evaluate.truth import truth_error, truth_poses_of
from rotstar_mrcal.report.table import Table, fmt, get
from rotstar_mrcal.simulate.dataset import load_truth


def estimate(plain_model: str, seq: str | None, index: float) -> dict:
    """correct_glass's estimate on one plain model; with the truth (seq/truth.json), "truth": the model it
    leaves (re-solved when applied, else the plain one) against the true camera (TruthError.summary())"""
    model = mrcal.cameramodel(plain_model)
    g = correct_glass(model, None, index)
    out = g.to_json()
    if seq and os.path.exists(os.path.join(seq, "truth.json")):
        t = load_truth(seq)
        out["truth"] = truth_error(g.model, t.model, truth_poses_of(g.model, t.rt_cam_board)).summary()
    return out


def estimates(result: dict, xdir: str, log=None) -> dict:
    """{method: {group: estimate(...)}} over the methods of a rotstar-crossval --glass results.json in xdir"""
    out = {}
    index = get(result, "glass", "index") or 1.5
    for m in result["methods"]:
        for s in "AB":
            path = get(m, "glass", s, "plain_model")
            if path is None:
                continue
            seq = os.path.dirname(m["corners"][s])  # the group's folder: its truth.json (sets.write_group)
            out.setdefault(m["method"], {})[s] = e = estimate(os.path.join(xdir, path), seq, index)
            if log:
                log(f"  {m['method']} {s}: {e['thickness_mm'] if e['thickness_mm'] is not None else float('nan'):.3f}"
                    f" +- {e['sigma_mm'] if e['sigma_mm'] is not None else float('nan'):.3f} mm, "
                    f"{'applied' if e['applied'] else 'not applied'}")
    return out


def _pair(values) -> str:
    return " / ".join(fmt(v) for v in values)


def _estimated(e: dict | None) -> str:
    """'0.71 +- 0.05' ('-' none)"""
    if not e or e.get("thickness_mm") is None:
        return "-"
    return f"{fmt(e['thickness_mm'], 2)} +- {fmt(e.get('sigma_mm'), 2)}"


def table(result: dict, est: dict) -> Table:
    """Per method: vs truth (median over the imager, calibrated on A / on B) plain, corrected for the known
    glass, and with the estimate; the estimates and whether they were applied"""
    mm = get(result, "glass", "mm")
    header = ["method", "plain: vs truth A / B, px", f"corrected for {mm:g} mm: vs truth A / B, px",
              "glass estimated A / B, mm", "estimate applied A / B", "with the estimate: vs truth A / B, px"]
    rows, bold = [], set()
    for m in result["methods"]:
        g, e = m.get("glass") or {}, est.get(m["method"], {})
        if not g:
            continue
        rows.append([m["method"], _pair(get(g, s, "truth_plain", "median_px") for s in "AB"),
                     _pair(get(m, "truth", s, "median_px") for s in "AB"),
                     " / ".join(_estimated(e.get(s)) for s in "AB"),
                     " / ".join("-" if s not in e else "yes" if e[s]["applied"] else "no" for s in "AB"),
                     _pair(get(e, s, "truth", "median_px") for s in "AB")])
    for j in (2, 5):
        v = [np.nanmean([float(x) if x != "-" else np.nan for x in r[j].split(" / ")]) for r in rows]
        if v and np.isfinite(np.nanmin(v)):
            bold.add((int(np.nanargmin(v)), j))
    cap = (f"{result['label']}: the screen under {mm:g} mm of cover glass (index {get(result, 'glass', 'index'):g}). "
           "Each method's calibrations against the true camera (median projection error over the imager, "
           "calibrated on group A / on group B): plain (mrcal-calibrate-cameras on the corners as detected), "
           f"corrected for the known {mm:g} mm (rotstar-crossval --glass {mm:g}, the models the tables above "
           "test), and with the thickness each plain calibration estimates from its own data (+- 1 sigma; "
           "applied only when a plausible glass, else the plain model stays). Bold: best in its column "
           "(mean of A and B).")
    return Table(header, rows, cap, bold)


def summary(result: dict, est: dict, method: str = "rotstar") -> str:
    """One sentence on a method: its error against the truth plain -> corrected, and its estimates"""
    m = next((x for x in result["methods"] if x["method"] == method and x.get("glass")), None)
    if m is None:
        return ""
    before = [get(m, "glass", s, "truth_plain", "median_px") for s in "AB"]
    after = [get(m, "truth", s, "median_px") for s in "AB"]
    e = est.get(method, {})
    said = "; ".join(f"{s}: {_estimated(e.get(s))} mm, {'applied' if e[s]['applied'] else 'not applied'}: "
                     f"{e[s]['reason']}" for s in "AB" if s in e)
    return (f"{method} at {result['label']}: {_pair(before)} px from the true camera plain, {_pair(after)} px "
            f"corrected for the known {get(result, 'glass', 'mm'):g} mm (A / B, median over the imager). "
            f"Estimated from the data: {said or '-'}.")

"""The stereo section of the report: a pair's calibrations against the truth, cross-validated, in depth terms

SYNOPSIS

    >>> from rotstar_mrcal.report.stereo import headline, depth_table, section
    >>> def cam(px): return {"median_px": px}
    >>> def g(c0, c1, db, dr, d):
    ...     return {"cameras": [cam(c0), cam(c1)],
    ...             "extrinsics": {"baseline_error_mm": db, "rotation_error_deg": dr},
    ...             "depth": {"depths": {"1": {"rms_mm": d, "p95_mm": 2 * d, "mean_mm": d, "rms_pct": d / 10}}}}
    >>> result = {"format": "rotstar-stereo/1", "label": "D435", "distances": [1.0], "methods": [
    ...     {"method": "rotstar", "truth": {"A": g(0.01, 0.02, 0.05, 0.001, 0.3), "B": g(0.01, 0.02, -0.04, 0.002, 0.4)}},
    ...     {"method": "saddle", "truth": {"A": g(0.03, 0.04, 0.2, 0.004, 1.2), "B": g(0.03, 0.05, 0.1, 0.003, 0.9)}}]}
    >>> print(headline(result).markdown())
    | method | camera 0 vs truth, px | camera 1 vs truth, px | baseline error, mm | rotation error, deg | depth RMS at 1 m, mm |
    |---|---|---|---|---|---|
    | rotstar | **0.01 / 0.01** | **0.02 / 0.02** | **0.05 / -0.04** | **0.001 / 0.002** | **0.3 / 0.4** |
    | saddle | 0.03 / 0.03 | 0.04 / 0.05 | 0.2 / 0.1 | 0.004 / 0.003 | 1.2 / 0.9 |

Input: the results.json of scripts/stereo.py (`make stereo`), format
"rotstar-stereo/1": {"label", "distances", "setup" (Markdown),
"methods": [validate.stereo.evaluate summaries, plus "corner_rms_px"]}.
Cells "a / b" are the calibrations on pose groups A and B; bold marks the
best (smallest magnitude, mean of A and B) in its column.
"""

from __future__ import annotations

import html as _html

import numpy as np

from rotstar_mrcal.report.table import Table, fmt, get

FORMAT = "rotstar-stereo/1"


def _cell(vals, digits: int = 3) -> str:
    return " / ".join(fmt(v, digits) for v in vals)


def _score(vals) -> float:
    v = [abs(x) for x in vals if x is not None and np.isfinite(x)]
    return float(np.mean(v)) if v and len(v) == len(vals) else np.inf


def _bold_best(rows_vals, ncols) -> set:
    bold = set()
    for j in range(ncols):
        s = [_score(r[j]) for r in rows_vals]
        if s and np.isfinite(min(s)) and len(s) > 1:
            bold.add((int(np.argmin(s)), j + 1))
    return bold


def _groups(m) -> list[str]:
    return sorted((m.get("truth") or m.get("calibration") or {"A": None}).keys())


def _camera(truth: dict, group: str, k: int):
    """Camera k's median error against the truth in one group, or None"""
    cams = get(truth, group, "cameras") or []
    return cams[k].get("median_px") if k < len(cams) and isinstance(cams[k], dict) else None


def headline(result) -> Table:
    """Methods: each camera against the truth, baseline and rotation error, depth RMS at each distance (A / B)"""
    d = [f"{z:g}" for z in result.get("distances", [])]
    ncam = max([2] + [len(get(m, "truth", g, "cameras") or []) for m in result["methods"] for g in _groups(m)])
    header = (["method"] + [f"camera {k} vs truth, px" for k in range(ncam)]
              + ["baseline error, mm", "rotation error, deg"] + [f"depth RMS at {z} m, mm" for z in d])
    rows, vals = [], []
    for m in result["methods"]:
        gs = _groups(m)
        t = m.get("truth") or {}
        v = [[_camera(t, g, k) for g in gs] for k in range(ncam)]
        v += [[get(t, g, "extrinsics", "baseline_error_mm") for g in gs],
              [get(t, g, "extrinsics", "rotation_error_deg") for g in gs]]
        v += [[get(t, g, "depth", "depths", z, "rms_mm") for g in gs] for z in d]
        vals.append(v)
        rows.append([m["method"]] + [_cell(c, 2 if j >= ncam + 2 else 3) for j, c in enumerate(v)])
    cap = ("Each calibration (pose group A / B) against the true rig: each camera's median projection error over "
           "its imager (camera 2: the colour camera, calibrated with the pair, when there is one); camera 1's position (baseline length) and rotation relative to camera 0; the RMS depth "
           "error of held-out board corners seen by the true cameras and triangulated through the calibrated, "
           "rectified pair. Bold: best in its column.")
    return Table(header, rows, cap, _bold_best(vals, len(header) - 1))


def _worst(vals):
    v = [abs(x) for x in vals if x is not None and np.isfinite(x)]
    return max(v) if v else None


def verdicts(result) -> list[str]:
    """A few sentences: each method's worst baseline and rotation error, its depth error at the farthest distance

    SYNOPSIS

        >>> r = {"distances": [2.0], "methods": [{"method": "rotstar", "truth": {
        ...     "A": {"extrinsics": {"baseline_error_mm": 0.01, "baseline_true_mm": 50.0, "rotation_error_deg": 0.002},
        ...           "depth": {"depths": {"2": {"rms_mm": 1.0, "rms_pct": 0.05}}}},
        ...     "B": {"extrinsics": {"baseline_error_mm": -0.02, "baseline_true_mm": 50.0, "rotation_error_deg": 0.001},
        ...           "depth": {"depths": {"2": {"rms_mm": 3.0, "rms_pct": 0.15}}}}}}]}
        >>> for v in verdicts(r): print(v)
        rotstar: baseline within 0.02 mm of the true 50 mm, rotation within 0.002 deg (both calibrations).
        Depth RMS error at 2 m, from the calibration alone (worse of A and B): rotstar 3 mm (0.15 %).
    """
    out, depth = [], []
    far = f"{max(result.get('distances') or [0]):g}"
    for m in result["methods"]:
        t = m.get("truth") or {}
        gs = sorted(t)
        db = _worst([get(t, g, "extrinsics", "baseline_error_mm") for g in gs])
        dr = _worst([get(t, g, "extrinsics", "rotation_error_deg") for g in gs])
        b = next((get(t, g, "extrinsics", "baseline_true_mm") for g in gs), None)
        if db is not None and dr is not None:
            out.append(f"{m['method']}: baseline within {fmt(db, 2)} mm of the true {fmt(b, 3)} mm, rotation within "
                       f"{fmt(dr, 2)} deg (both calibrations).")
        rms = [get(t, g, "depth", "depths", far, "rms_mm") for g in gs]
        if _worst(rms) is not None:
            g = gs[int(np.nanargmax([abs(x) if x is not None else np.nan for x in rms]))]
            depth.append(f"{m['method']} {fmt(_worst(rms), 2)} mm "
                         f"({fmt(get(t, g, 'depth', 'depths', far, 'rms_pct'), 2)} %)")
    if depth:
        out.append(f"Depth RMS error at {far} m, from the calibration alone (worse of A and B): "
                   + ", ".join(depth) + ".")
    return out + [v for m in result["methods"] for v in [glass_verdict(m)] if v]


def glass_verdict(m: dict) -> str:
    """One sentence on a method's cover glass: the estimates, and the worst baseline and rotation errors of the
    plain solve, the written calibration and the one corrected for the known thickness ('' without a glass entry)

        >>> ext = lambda db, dr: {"extrinsics": {"baseline_error_mm": db, "rotation_error_deg": dr}}
        >>> m = {"method": "rotstar", "truth": {"A": ext(0.03, 0.004)},
        ...      "glass": {"A": {"thickness_mm": 4.1, "sigma_mm": 0.2, "applied": False, "plain": ext(0.03, 0.004),
        ...                      "known": {"thickness_mm": 0.7, **ext(0.002, 0.001)}}}}
        >>> print(glass_verdict(m))
        rotstar, cover glass: estimated 4.1 +- 0.2 mm (A, not applied); baseline / rotation error (worst of A and B): plain 0.03 mm / 0.004 deg, written 0.03 mm / 0.004 deg, corrected for the known 0.7 mm 0.002 mm / 0.001 deg.
    """
    gl = m.get("glass") or {}
    if not gl:
        return ""
    gs = sorted(gl)

    def worst(src):
        return (f"{fmt(_worst([get(src(g), 'extrinsics', 'baseline_error_mm') for g in gs]), 2)} mm / "
                f"{fmt(_worst([get(src(g), 'extrinsics', 'rotation_error_deg') for g in gs]), 2)} deg")

    est = ", ".join(f"{fmt(get(gl, g, 'thickness_mm'), 3)} +- {fmt(get(gl, g, 'sigma_mm'), 2)} mm "
                    f"({g}, {'applied' if get(gl, g, 'applied') else 'not applied'})" for g in gs)
    out = (f"{m['method']}, cover glass: estimated {est}; baseline / rotation error (worst of A and B): "
           f"plain {worst(lambda g: get(gl, g, 'plain'))}, written {worst(lambda g: get(m, 'truth', g))}")
    known = get(gl, gs[0], "known", "thickness_mm")
    if known is not None:
        out += f", corrected for the known {known:g} mm {worst(lambda g: get(gl, g, 'known'))}"
    return out + "."


def depth_table(result, key: str = "depth") -> Table:
    """Per method and group: the depth error at each distance, mean / RMS / 95th percentile (mm) and RMS (%)"""
    d = [f"{z:g}" for z in result.get("distances", [])]
    header = ["method", "group"] + [f"{z} m: mean / RMS / p95, mm" for z in d] + [f"{z} m: RMS, %" for z in d]
    rows = []
    noise = None
    for m in result["methods"]:
        for g in _groups(m):
            e = get(m, "truth", g, key)
            if not e:
                continue
            noise = e.get("noise_px") if key != "depth" else noise
            rows.append([m["method"] if not rows or rows[-1][0] != m["method"] else "", g]
                        + [" / ".join(fmt(get(e, "depths", z, k), 2) for k in ("mean_mm", "rms_mm", "p95_mm"))
                           for z in d]
                        + [fmt(get(e, "depths", z, "rms_pct"), 2) for z in d])
    if key == "depth":
        cap = ("Depth error of the calibration alone: held-out board corners at each distance projected with the "
               "true cameras (exact pixels), rectified with the calibrated pair (mrcal.rectified_system), depth "
               "from the rectified disparity (mrcal.stereo_range) minus the true depth.")
    else:
        cap = ("The same with each method's own corner noise added to the held-out pixels (the RMS of its "
               "corners against the true ones on the calibration poses, per coordinate): what a depth from "
               "that detector's corners would show.")
    return Table(header, rows, cap)


def crossval_table(result) -> Table:
    """Per method: the A and B calibrations against each other, and against their uncertainties"""
    d = [f"{z:g}" for z in result.get("distances", [])]
    header = (["method", "camera 0: diff/(uA+uB)", "camera 1: diff/(uA+uB)", "baseline A-B, mm",
               "rotation A-B, deg"] + [f"pair diff at {z} m, px" for z in d]
              + [f"depth A-B at {z} m, mm (1-sigma)" for z in d])
    rows = []
    for m in result["methods"]:
        cv = m.get("crossval") or {}
        cams = cv.get("cameras") or []
        row = [m["method"]]
        for k in (0, 1):
            c = cams[k] if k < len(cams) else {}
            row.append(f"{fmt(c.get('ratio_median'), 2)} ({c.get('verdict') or c.get('error', '-')[:40]})"
                       if c else "-")
        row += [fmt(get(cv, "extrinsics", "baseline_error_mm"), 2),
                fmt(get(cv, "extrinsics", "rotation_error_deg"), 2)]
        row += [fmt(get(cv, "pair_diff", z, "median_px"), 2) for z in d]
        row += [f"{fmt(get(cv, 'depth', z, 'diff_median_mm'), 2)} ({fmt(get(cv, 'depth', z, 'unc_median_mm'), 2)})"
                for z in d]
        rows.append(row)
    cap = ("mrcal's cross-validation of the two calibrations (groups A and B): per camera the projection diff "
           "over the imager against the sum of the two 1-sigma uncertainties (~1 or less: consistent; far above: "
           "model errors); camera 1's extrinsics of A against B (mrcal gives no extrinsics uncertainty: the plain "
           "difference); mrcal.stereo_pair_diff (camera 0's pixels reprojected into camera 1 through each "
           "calibration, median over the imager); the median depth difference of points over camera 0's imager "
           "triangulated with A and with B, and in brackets sqrt(sigma_A^2 + sigma_B^2), each calibration's "
           "depth uncertainty from its corner noise (mrcal.triangulate).")
    return Table(header, rows, cap)


def calibration_table(result) -> Table:
    """Per method and group: boards, fit RMS per camera, corner error against the truth"""
    header = ["method", "group", "boards cam 0 / cam 1", "fit RMS cam 0 / cam 1, px", "corners vs truth, px RMS"]
    rows = []
    for m in result["methods"]:
        for g in _groups(m):
            c = get(m, "calibration", g) or []
            rows.append([m["method"] if not rows or rows[-1][0] != m["method"] else "", g,
                         " / ".join(str(x.get("boards", "-")) for x in c),
                         " / ".join(fmt(x.get("rms_px")) for x in c),
                         fmt(m.get("corner_rms_px"))])
    cap = ("Boards each camera saw in each group's joint calibration, the RMS of its own fit, and the method's "
           "corners against the true projections (all poses, per coordinate).")
    return Table(header, rows, cap)


def _arrow(a, b, c=None, digits: int = 3) -> str:
    return f"{fmt(a, digits)} -> {fmt(b, digits)}" + ("" if c is None else f" ({fmt(c, digits)})")


def glass_table(result) -> Table:
    """Per method and group: the cover glass estimated, and the pair against the truth before -> after the correction;
    and, when the run has it ("known"), the same pair corrected for the known thickness, in a row of its own

        >>> cam = lambda px: {"median_px": px}
        >>> ext = lambda db, dr: {"baseline_error_mm": db, "rotation_error_deg": dr}
        >>> m = {"method": "rotstar",
        ...      "truth": {"A": {"cameras": [cam(0.01), cam(0.02)], "extrinsics": ext(0.001, 0.0005)}},
        ...      "glass": {"A": {"thickness_mm": 0.71, "sigma_mm": 0.03, "applied": True, "reason": "estimated",
        ...                      "plain": {"cameras": [cam(0.1), cam(0.2)], "extrinsics": ext(0.02, 0.008)}}}}
        >>> print(glass_table({"glass_mm": 0.7, "methods": [m]}).markdown().splitlines()[-1])
        | rotstar | A | 0.710 +- 0.030 mm, applied | 0.1 -> 0.01 | 0.2 -> 0.02 | 0.02 -> 0.001 | 0.008 -> 0.0005 |
        >>> m["glass"]["A"]["reference"] = m["truth"]["A"]
        >>> glass_table({"glass_mm": 0.7, "methods": [m]}).rows[-1][3:5]
        ['0.1 -> 0.01 (0.01)', '0.2 -> 0.02 (0.02)']
        >>> m["glass"]["A"]["known"] = {"thickness_mm": 0.7, "cameras": [cam(0.011), cam(0.021)],
        ...                             "extrinsics": ext(0.002, 0.0006)}
        >>> glass_table({"glass_mm": 0.7, "methods": [m]}).rows[-1]
        ['', 'A', '0.700 mm known, applied', '0.1 -> 0.011 (0.01)', '0.2 -> 0.021 (0.02)', '0.02 -> 0.002 (0.001)', '0.008 -> 0.0006 (0.0005)']
    """
    header = ["method", "group", "glass", "camera 0 vs truth, px", "camera 1 vs truth, px",
              "baseline error, mm", "rotation error, deg"]
    rows = []
    for m in result["methods"]:
        for g in _groups(m):
            e = get(m, "glass", g) or {}
            est = ("-" if e.get("thickness_mm") is None else
                   f"{e['thickness_mm']:.3f} +- {e['sigma_mm']:.3f} mm" if e.get("sigma_mm") is not None else
                   f"{e['thickness_mm']:.3f} mm")
            est += ", applied" if e.get("applied") else f", not applied: {e.get('reason', '')}"
            rows.append([m["method"] if not rows or rows[-1][0] != m["method"] else "", g, est,
                         *_glass_cells(e.get("plain"), get(m, "truth", g), e.get("reference"))])
            if e.get("known"):
                rows.append(["", g, f"{e['known']['thickness_mm']:.3f} mm known, applied",
                             *_glass_cells(e.get("plain"), e["known"], e.get("reference"))])
    cap = (f"The screen's cover glass ({result.get('glass_mm', 0):g} mm, index 1.5): the thickness rotstar-calibrate "
           "estimated from each calibration, and each camera (median over its imager, at infinity) and camera 1's "
           "pose against the truth, plain (the joint mrcal solve before the correction) -> written (corrected when "
           "applied); in the 'known' rows the same solve corrected for the known thickness instead (what "
           "rotstar-calibrate --glass MM writes); in brackets the same-noise reference on simulated data: the "
           "glass-free solve with the calibration's own corner errors, what a perfect correction would give.")
    return Table(header, rows, cap)


def _glass_cells(plain: dict | None, after: dict | None, reference: dict | None) -> list[str]:
    """plain -> after (reference) for camera 0, camera 1, the baseline and the rotation; each a pair's truth error"""
    p, t, f = {"g": plain}, {"g": after}, {"g": reference}
    return [*[_arrow(_camera(p, "g", k), _camera(t, "g", k), _camera(f, "g", k)) for k in (0, 1)],
            *[_arrow(get(p, "g", "extrinsics", q), get(t, "g", "extrinsics", q), get(f, "g", "extrinsics", q))
              for q in ("baseline_error_mm", "rotation_error_deg")]]


def tables(result) -> list[tuple[str, Table]]:
    """[(heading, table)] of the section, in order"""
    out = [("Against the true rig", headline(result)), ("Depth error", depth_table(result, "depth"))]
    if any(get(m, "truth", g, "depth_noisy") for m in result["methods"] for g in _groups(m)):
        out.append(("Depth error with each detector's corner noise", depth_table(result, "depth_noisy")))
    if any(m.get("crossval") for m in result["methods"]):
        out.append(("Cross-validation (A against B)", crossval_table(result)))
    if any(m.get("glass") for m in result["methods"]):
        out.append(("The screen's cover glass, before and after the correction", glass_table(result)))
    out.append(("Calibrations", calibration_table(result)))
    return out


def section(result, level: int = 2) -> str:
    """The stereo section as Markdown"""
    h = "#" * level
    out = [f"{h} Stereo: {result.get('label', 'pair')}", ""]
    if result.get("setup"):
        out += [result["setup"].strip(), ""]
    out += [f"- {v}" for v in verdicts(result)] + [""]
    for title, t in tables(result):
        out += [f"{h}# {title}", "", t.markdown(), "", f"*{t.caption}*", ""]
    return "\n".join(out)


def section_html(result) -> str:
    """The stereo section as HTML"""
    e = _html.escape
    out = [f"<h2>Stereo: {e(result.get('label', 'pair'))}</h2>"]
    if result.get("setup"):
        out += [f"<p>{e(p)}</p>" for p in result["setup"].strip().split("\n\n")]
    out += ["<ul>"] + [f"<li>{e(v)}</li>" for v in verdicts(result)] + ["</ul>"]
    for title, t in tables(result):
        out += [f"<h3>{e(title)}</h3>", t.html()]
    return "\n".join(out)


def check(result, fn: str = "results.json") -> None:
    """ValueError 'fn: reason' unless result is a rotstar-stereo results dict

    SYNOPSIS

        >>> check({"format": "rotstar-stereo/1", "methods": []})
        >>> check({"format": "rotstar-stereo/1"}, "x.json")
        Traceback (most recent call last):
        ...
        ValueError: x.json: a rotstar-stereo results file without its methods
    """
    if not isinstance(result, dict) or result.get("format") != FORMAT:
        raise ValueError(f"{fn}: not a rotstar-stereo results file")
    if not isinstance(result.get("methods"), list) or not all(isinstance(m, dict) and "method" in m
                                                               for m in result["methods"]):
        raise ValueError(f"{fn}: a rotstar-stereo results file without its methods")

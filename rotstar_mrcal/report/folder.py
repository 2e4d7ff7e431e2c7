"""The report folder of rotstar-report: pages, figures copied and drawn, results

SYNOPSIS

    from rotstar_mrcal.report.folder import load_results, build_report
    loaded = [load_results(d) for d in ("xval-low", "xval-high")]
    written = build_report([r for r, _ in loaded], [d for _, d in loaded], "report", "my title")
    written["index.html"]

    >>> slug("8000 us (saturated)")
    '8000-us-saturated'

build_report writes OUT/index.md and index.html (report.markdown/html),
headline.md (with the extra sections in short), paper.md (simulated data:
the held-out error by tilt of the test poses; the extra sections whole: the
lab's scripts/demo.py adds the paper's claims, add_sections), results.json (all conditions), the summary bar charts, each
condition's per-pose plot and maps (copied from its rotstar-crossval
folder), and mrcal's own views of the first method's group-A calibration
(mrcalshow.calibration_figures: uncertainty, residuals, diff against group
B, distortion, valid region), each captioned with the mrcal-show-* command
that redraws it. Every file is written whole (a temporary name, then
renamed).
"""

from __future__ import annotations

import json
import os
import re
import shutil

from rotstar_mrcal.atomic import atomic_path, atomic_write
from rotstar_mrcal.report import plots, stereo as stereoreport
from rotstar_mrcal.evaluate.groups import Comparison
from rotstar_mrcal.report.page import headline_markdown, html, markdown, methods_of, paper_section, with_sections
from rotstar_mrcal.report.mrcalshow import calibration_figures
import matplotlib.pyplot as plt


def slug(s: str) -> str:
    """A file-name-safe version of a label

    SYNOPSIS

        >>> slug("8000 us (saturated)")
        '8000-us-saturated'
    """
    return re.sub(r"[^A-Za-z0-9]+", "-", s).strip("-").lower() or "condition"


def load_results(path: str) -> tuple[dict, str]:
    """(results, folder) of a rotstar-crossval results.json; ValueError 'file: reason' if it is not one"""
    fn = os.path.join(path, "results.json") if os.path.isdir(path) else path
    if not os.path.isfile(fn):
        raise ValueError(f"{fn}: {'no such file' if not os.path.exists(fn) else 'not a regular file'}")
    try:
        with open(fn) as f:
            r = json.load(f)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ValueError(f"{fn}: not a rotstar-crossval results file ({e})") from None
    if isinstance(r, dict) and r.get("format") == stereoreport.FORMAT:  # make stereo's: the stereo section
        stereoreport.check(r, fn)
        return r, os.path.dirname(os.path.abspath(fn))
    if not isinstance(r, dict) or r.get("format") != "rotstar-crossval/1":
        raise ValueError(f"{fn}: not a rotstar-crossval results file (nor a rotstar-stereo one)")
    try:
        Comparison.from_json(r)
    except ValueError as e:
        raise ValueError(f"{fn}: {e}") from None
    return r, os.path.dirname(os.path.abspath(fn))


def _copy(src_dir: str, rel: str, out: str, dst_rel: str) -> str | None:
    src = os.path.join(src_dir, rel)
    if not os.path.exists(src):
        return None
    os.makedirs(os.path.dirname(os.path.join(out, dst_rel)), exist_ok=True)
    shutil.copyfile(src, os.path.join(out, dst_rel))
    return dst_rel


def build_report(results, dirs, out: str, title: str, notes: str = "", extra_figures=(), mrcal_figures: bool = True,
          log=None, sections=()) -> dict:
    """Write the report folder; returns {'index.md': path, ...}

    Results of format rotstar-stereo/1 (make stereo) are shown as stereo
    sections after the conditions; sections (page.Section) after the
    headline, in paper.md and in short in headline.md.
    """
    stereo = [r for r in results if r.get("format") == stereoreport.FORMAT]
    dirs = [d for r, d in zip(results, dirs) if r.get("format") != stereoreport.FORMAT]
    results = [r for r in results if r.get("format") != stereoreport.FORMAT]
    os.makedirs(out, exist_ok=True)
    labels = [r["label"] for r in results]
    if len(set(labels)) != len(labels):
        raise ValueError(f"conditions need distinct labels; got {labels} (rotstar-crossval --label)")
    methods = methods_of(results)
    figures = []
    for src in extra_figures:
        path, _, cap = src.partition(":")
        dst = _copy(os.path.dirname(os.path.abspath(path)), os.path.basename(path), out, os.path.basename(path))
        if dst:
            figures.append((cap or os.path.basename(path), dst))

    def series(kind, key):
        vals = {}
        for m in methods:
            v = []
            for r in results:
                e = next((x for x in r["methods"] if x["method"] == m), None)
                d = (e or {}).get(kind) or {}
                v.append((d.get(key) or {}).get("mean_px" if kind == "heldout" else "median_px"))
            vals[m] = v
        return vals

    def bars(kind, panels, ylabel, fn, caption, at):
        fig = plots.summary_bars(labels, [(title, series(kind, key)) for title, key in panels], ylabel)
        with atomic_path(os.path.join(out, fn)) as tmp:  # (a full disk: no half-written figure, the file named)
            fig.savefig(tmp, dpi=110)
        plt.close(fig)
        figures.insert(at, (caption, fn))

    if results:
        bars("heldout", [("calibrated on A, tested on B", "A->B"), ("calibrated on B, tested on A", "B->A")],
             "held-out mean reprojection error, px", "summary-heldout.png",
             "Held-out mean reprojection error (the paper's metric) by method and condition", 0)
    if any(m.get("truth") for r in results for m in r["methods"]):
        bars("truth", [("calibrated on A", "A"), ("calibrated on B", "B")],
             "vs true model: median error over the imager, px", "summary-truth.png",
             "Calibrated model against the true camera (simulated data), median over the imager", 1)

    per_condition = {}
    for r, d in zip(results, dirs):
        s = slug(r["label"])
        figs = []
        if r.get("figures", {}).get("per_pose"):
            dst = _copy(d, r["figures"]["per_pose"], out, f"{s}/per-pose.png")
            if dst:
                figs.append(("Held-out MRE of each test pose (as in the paper's figure)", dst))
        for m in r["methods"]:
            rel = (m.get("figures") or {}).get("maps")
            if rel:
                dst = _copy(d, rel, out, f"{s}/{os.path.basename(rel)}")
                if dst:
                    figs.append((f"{m['method']}: projection diff of the A and B calibrations, their "
                                 "uncertainties (dots: the corners each saw)"
                                 + (", and each against the true model" if m.get("truth") else ""), dst))
        if mrcal_figures:
            figs += _mrcal_views(r, d, out, s, log)
        per_condition[r["label"]] = figs

    md = markdown(results, title, figures, per_condition, notes, stereo, sections)
    page = html(results, title, figures, per_condition, notes, stereo, sections)
    head_md = ""
    paper = ""
    if results:
        head_md = headline_markdown(results) + "".join(f"\n{s.headline}" for s in sections if s.headline)
        paper = paper_section(results, sections)  # the table by tilt (simulated) and the extra sections
    for r in stereo:
        head_md += ("\n" if head_md else "") + stereoreport.headline(r).markdown() + "\n"
    summary = {"format": "rotstar-report/1", "conditions": results}
    if stereo:
        summary["stereo"] = stereo
    files = {"index.md": md, "index.html": page, "headline.md": head_md,
             "results.json": json.dumps(summary, indent=1) + "\n"}
    if paper:
        files["paper.md"] = paper
    _write(out, files)
    return {k: os.path.join(out, k) for k in files}


def add_sections(out: str, sections) -> dict:
    """Put sections (page.Section) into the report folder OUT that build_report wrote without them: the same
    pages as build_report(..., sections=sections) would have written; returns {'index.md': path, ...}"""
    with open(os.path.join(out, "results.json")) as f:
        results = json.load(f)["conditions"]
    old = {}
    for name in ("index.md", "index.html", "headline.md"):
        with open(os.path.join(out, name)) as f:
            old[name] = f.read()
    files = with_sections(old, results, sections)
    if not files["paper.md"]:
        del files["paper.md"]
    _write(out, files)
    return {k: os.path.join(out, k) for k in files}


def _write(out: str, files: dict) -> None:
    for name, text in files.items():  # each file whole or not at all
        with atomic_write(os.path.join(out, name)) as f:
            f.write(text)


def _mrcal_views(r: dict, d: str, out: str, s: str, log=None) -> list:
    """mrcal-show-* figures of the first calibrated method's A model (B for the diff); [(caption, png)]"""
    m = next((m for m in r["methods"] if (m.get("models") or {}).get("A")), None)
    if m is None:
        return []
    a = os.path.join(d, m["models"]["A"])
    b = os.path.join(d, m["models"]["B"]) if m["models"].get("B") else None
    if not os.path.exists(a):
        return []
    try:
        figs, _ = calibration_figures(a, os.path.join(out, s), other=b if b and os.path.exists(b) else None,
                                      prefix=f"mrcal-{m['method']}-")
    except RuntimeError as e:  # a figure mrcal could not draw: say so, keep the report
        (log or print)(f"mrcal's views of {a}: {e}")
        return []
    out_figs = []
    for cap, png, cmd in figs:
        (log or print)(f"redraw with: {cmd}")
        out_figs.append((f"{m['method']}, calibrated on A: {cap}. Redraw: `{cmd}`", os.path.relpath(png, out)))
    return out_figs



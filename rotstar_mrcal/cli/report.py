"""rotstar-report: rotstar-crossval results (one folder per condition) in, one report folder out"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import sys

from ..validate import plots, report
from .common import say

DESCRIPTION = """\
Build the validation report from one or more rotstar-crossval output folders
(each holds results.json; one folder per condition, e.g. per exposure, in
the order given). Writes OUT/index.md and OUT/index.html (the same page),
OUT/headline.md, OUT/results.json (all conditions) and the figures: the
summary bar charts, and each condition's per-pose plot and maps, copied.

Per condition it also draws mrcal's own views of the first method's
calibration on group A (mrcal-show-projection-uncertainty, -residuals,
-residuals-board-observation, -distortion-off-pinhole,
-valid-intrinsics-region, and -projection-diff against group B's), with
colour scales that fit the data, the outlier count and the valid region;
each with the mrcal-show-* command that redraws it (stderr and the page).

stdout: the headline table and the verdict (Markdown), for pasting;
stderr: the files written and the mrcal-show-* commands.

Exit status: 0 written; 2 bad arguments (an unreadable results.json,
duplicate labels, an --out that cannot be a folder).
"""


def parse_args(argv=None):
    p = argparse.ArgumentParser(prog="rotstar-report", description=DESCRIPTION,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("xval", nargs="+", help="rotstar-crossval --outdir folders (or their results.json)")
    p.add_argument("--out", default="report", help="report folder (default report)")
    p.add_argument("--title", default="rotstar-mrcal validation report")
    p.add_argument("--notes", help="a Markdown file whose text goes under the title (the set-up)")
    p.add_argument("--figure", action="append", default=[], metavar="PNG[:CAPTION]",
                   help="an extra figure to show after the headline; repeatable")
    p.add_argument("--no-mrcal-figures", action="store_true", help="leave out mrcal's own views (faster)")
    return p.parse_args(argv)


def slug(s: str) -> str:
    """A file-name-safe version of a label

    SYNOPSIS

        >>> slug("8000 us (saturated)")
        '8000-us-saturated'
    """
    return re.sub(r"[^A-Za-z0-9]+", "-", s).strip("-").lower() or "condition"


def load_results(path: str) -> tuple[dict, str]:
    fn = os.path.join(path, "results.json") if os.path.isdir(path) else path
    with open(fn) as f:
        r = json.load(f)
    if r.get("format") != "rotstar-crossval/1":
        raise ValueError(f"{fn}: not a rotstar-crossval results file")
    return r, os.path.dirname(os.path.abspath(fn))


def _copy(src_dir: str, rel: str, out: str, dst_rel: str) -> str | None:
    src = os.path.join(src_dir, rel)
    if not os.path.exists(src):
        return None
    os.makedirs(os.path.dirname(os.path.join(out, dst_rel)), exist_ok=True)
    shutil.copyfile(src, os.path.join(out, dst_rel))
    return dst_rel


def build(results, dirs, out: str, title: str, notes: str = "", extra_figures=(), mrcal_figures: bool = True,
          log=None) -> dict:
    """Write the report folder; returns {'index.md': path, ...}"""
    import matplotlib.pyplot as plt

    os.makedirs(out, exist_ok=True)
    labels = [r["label"] for r in results]
    if len(set(labels)) != len(labels):
        raise ValueError(f"conditions need distinct labels; got {labels} (rotstar-crossval --label)")
    methods = report.methods_of(results)
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
        fig.savefig(os.path.join(out, fn), dpi=110)
        plt.close(fig)
        figures.insert(at, (caption, fn))

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

    md = report.markdown(results, title, figures, per_condition, notes)
    page = report.html(results, title, figures, per_condition, notes)
    head = report.headline(results)
    head_md = head.markdown() + "\n\n" + "\n".join(f"- {v}" for v in report.verdicts(results)) + "\n"
    files = {"index.md": md, "index.html": page, "headline.md": head_md,
             "results.json": json.dumps({"format": "rotstar-report/1", "conditions": results}, indent=1) + "\n"}
    for name, text in files.items():  # each file whole or not at all
        with open(os.path.join(out, name + ".tmp"), "w") as f:
            f.write(text)
        os.replace(os.path.join(out, name + ".tmp"), os.path.join(out, name))
    return {k: os.path.join(out, k) for k in files}


def _mrcal_views(r: dict, d: str, out: str, s: str, log=None) -> list:
    """mrcal-show-* figures of the first calibrated method's A model (B for the diff); [(caption, png)]"""
    from ..validate.mrcalshow import calibration_figures

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
        (log or say)(f"rotstar-report: mrcal's views of {a}: {e}")
        return []
    out_figs = []
    for cap, png, cmd in figs:
        (log or say)(f"rotstar-report: redraw with: {cmd}")
        out_figs.append((f"{m['method']}, calibrated on A: {cap}. Redraw: `{cmd}`", os.path.relpath(png, out)))
    return out_figs


def main(argv=None) -> int:
    a = parse_args(argv)
    try:
        loaded = [load_results(p) for p in a.xval]
    except (OSError, ValueError, json.JSONDecodeError) as e:
        say(f"rotstar-report: {e}")
        return 2
    try:
        os.makedirs(a.out, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        say(f"rotstar-report: --out {a.out}: a file is in the way (not a folder)")
        return 2
    notes = ""
    if a.notes:
        with open(a.notes) as f:
            notes = f.read()
    try:
        written = build([r for r, _ in loaded], [d for _, d in loaded], a.out, a.title, notes, a.figure,
                        mrcal_figures=not a.no_mrcal_figures)
    except ValueError as e:
        say(f"rotstar-report: {e}")
        return 2
    say(f"rotstar-report: wrote {written['index.html']} and {written['index.md']}")
    with open(written["headline.md"]) as f:
        sys.stdout.write(f.read())
    return 0


if __name__ == "__main__":
    sys.exit(main())

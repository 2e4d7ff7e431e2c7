"""The figures of a cross-validation (evaluate.groups.Comparison): each set's heat maps and the per-pose plot

SYNOPSIS

    from rotstar_mrcal.evaluate.groups import compare_sets
    from rotstar_mrcal.report import crossval
    c = compare_sets({"rotstar": ("xval/rotstar/A.vnl", "xval/rotstar/B.vnl")}, "xval")
    crossval.draw(c, "xval")         # xval/rotstar-maps.png, xval/per-pose.png; their names into c
    print(crossval.markdown(c))      # the table rotstar-crossval prints
    print(crossval.glass_markdown(c))  # with --glass: the cover glass, each model plain -> corrected

Each map has its own colour scale, from zero to its data's range
(plots.heatmaps), so that 0.01 px structure shows; the per-pose plot is
linear from zero. The file names go into the comparison's JSON (the set's
figures["maps"], the comparison's figures["per_pose"]), where rotstar-report
finds them.
"""

from __future__ import annotations

import os

import matplotlib.pyplot as plt

from rotstar_mrcal.evaluate.groups import Comparison
from rotstar_mrcal.report import plots
from rotstar_mrcal.report.page import detail
from rotstar_mrcal.report.table import Table, fmt, get


def draw(c: Comparison, outdir: str) -> None:
    """Write c's figures into outdir and their names into c"""
    for m in c.maps:
        fig = plots.heatmaps(m.q, m.panels, m.imagersize, points=m.points, title=m.title)
        m.figures["maps"] = f"{m.method}-maps.png"
        fig.savefig(os.path.join(outdir, m.figures["maps"]), dpi=100)
        plt.close(fig)
    per_pose = c.per_pose()
    if any(series for _, series in per_pose):
        fig = plots.per_pose(per_pose)
        c.figures["per_pose"] = "per-pose.png"
        fig.savefig(os.path.join(outdir, c.figures["per_pose"]), dpi=100)
        plt.close(fig)


def markdown(c: Comparison) -> str:
    """The comparison's table, as rotstar-crossval prints it"""
    return detail(c.to_json()).markdown()


def glass_cell(g: dict | None) -> str:
    """What the cover glass's correction found for one calibration, in short

        >>> glass_cell({"thickness_mm": 0.7, "sigma_mm": None, "given": True, "applied": True})
        '0.7 mm given, applied'
        >>> glass_cell({"thickness_mm": 4.2, "sigma_mm": 0.31, "given": False, "applied": False})
        '4.2 +- 0.31 mm, not applied'
    """
    if not g:
        return "-"
    t = "no estimate" if g.get("thickness_mm") is None else (
        f"{fmt(g['thickness_mm'])} mm given" if g.get("given") else
        f"{fmt(g['thickness_mm'])} +- {fmt(g.get('sigma_mm'), 2)} mm")
    return f"{t}, {'applied' if g.get('applied') else 'not applied'}"


def glass_table(result: dict) -> Table:
    """Per corner set and group: the cover glass found, and the model against the truth (median / max over
    the imager) plain -> as tested (corrected when applied); result: a rotstar-crossval results.json"""
    header = ["method", "group", "cover glass", "vs truth plain, px", "vs truth corrected, px"]
    rows = []
    for m in result["methods"]:
        for s in "AB":
            g = get(m, "glass", s)
            after = get(m, "truth", s)
            before = get(g, "truth_plain") or (after if g and not g.get("applied") else None)
            rows.append([m["method"] if s == "A" else "", s, glass_cell(g),
                         *[f"{fmt(get(t, 'median_px'))} / {fmt(get(t, 'max_px'))}" if t else "-"
                           for t in (before, after)]])
    gl = result.get("glass") or {}
    how = "estimated from each calibration" if gl.get("mm") is None else f"{gl['mm']:g} mm given"
    cap = (f"{result['label']}: the screen's cover glass ({how}, index {gl.get('index', 1.5):g}; "
           "rotstar-crossval --glass), and each calibration against the true camera, median / max over the imager, "
           "plain (mrcal-calibrate-cameras) and as tested (corrected when applied, else the plain model)")
    return Table(header, rows, cap)


def glass_markdown(c: Comparison) -> str:
    """glass_table of a comparison run with a cover glass, with its caption"""
    t = glass_table(c.to_json())
    return t.markdown() + f"\n\n*{t.caption}*"

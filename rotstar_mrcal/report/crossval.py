"""The figures of a cross-validation (evaluate.groups.Comparison): each set's heat maps and the per-pose plot

SYNOPSIS

    from rotstar_mrcal.evaluate.groups import compare_sets
    from rotstar_mrcal.report import crossval
    c = compare_sets({"rotstar": ("xval/rotstar/A.vnl", "xval/rotstar/B.vnl")}, "xval")
    crossval.draw(c, "xval")         # xval/rotstar-maps.png, xval/per-pose.png; their names into c
    print(crossval.markdown(c))      # the table rotstar-crossval prints

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

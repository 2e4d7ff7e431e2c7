"""doc/uncertainty.md's figures: mrcal's views of a calibration drawn and their block of the doc rewritten

SYNOPSIS

    from rotstar_lab.uncertaintydoc import uncertainty_doc
    uncertainty_doc("cal/camera-0.cameramodel", "doc/img/uncertainty", "doc/uncertainty.md")

What scripts/calib_bench.py (make calib-bench) writes: the figures are
rotstar_mrcal.report.mrcalshow's, the block is rewritten with
rotstar_lab.docblock.
"""

from __future__ import annotations

import os

import mrcal

from rotstar_lab.docblock import rewrite_block
from rotstar_mrcal.report.mrcalshow import draw, redraw_command, scales, show_commands


def uncertainty_doc(model: str, img_dir: str, doc: str, halves: tuple[str, str] | None = None,
                    splined: str | None = None, image_root: str | None = None, names: dict | None = None) -> list:
    """Draw the figures of doc/uncertainty.md and rewrite its mrcal-show block; the Figures

    model: the calibration to show; halves: the two calibrations of
    rotstar-crossval SEQ (their diff); splined: a splined model (its
    correction). names: {path: the name to show in the commands}. The PNGs go
    to img_dir, linked relative to the doc.
    """
    figs = show_commands(model, img_dir, other=halves[0] if halves else None, image_root=image_root)
    if halves:  # the diff of the two halves, not of the model against half A
        d = next(f for f in figs if f.name == "diff")
        d.argv[-2:] = list(halves)
        s = scales(mrcal.cameramodel(halves[0]), mrcal.cameramodel(halves[1]))
        d.argv[d.argv.index("--cbmax") + 1] = f"{s['diff_cbmax']:g}"
    if splined:
        figs += [f for f in show_commands(splined, img_dir) if f.name == "splined-correction"]
    draw(figs)
    names = {**{f.stdin: os.path.basename(f.stdin) for f in figs if f.stdin}, **(names or {})}

    def shown(f):
        cmd = redraw_command(f)
        for path, name in sorted(names.items(), key=lambda kv: -len(kv[0])):
            cmd = cmd.replace(os.path.abspath(path), name).replace(path, name)
        return cmd

    out = []
    for f in figs:
        rel = os.path.relpath(f.png, os.path.dirname(os.path.abspath(doc)))
        out += [f"### {f.name}", "", "```", shown(f), "```", "", f"![{f.caption}]({rel})", "", f"*{f.caption}*", ""]
    rewrite_block(doc, "mrcal-show", "\n".join(out))
    return figs

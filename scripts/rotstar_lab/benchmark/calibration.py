"""Each method's correct boards calibrated with mrcal, against the true camera

SYNOPSIS

    cal = calibrate_all(scene, run.labelled, run.weights, tmp, log=print)
    cal["rotstar"]["median_px"]     # the model's error over the imager, px
    cal["rotstar-weighted"]         # the same corners with the variant's weights

mrcal-calibrate-cameras (CAL_LENSMODEL, the true lens family; focal seed from
the boards) on the boards a method got right, then the model against the
truth over the imager at infinity, after aligning the solved board poses with
the true ones (validate.truth.truth_error, 'procrustes').
"""

from __future__ import annotations

import os

import mrcal
import numpy as np

from rotstar_mrcal.calibrate.focal import estimate_focal
from rotstar_mrcal.peers.registry import METHODS
from rotstar_mrcal.pattern.layout import Layout
from rotstar_mrcal.calibrate import solve as calib
from rotstar_mrcal.evaluate.truth import truth_error, truth_poses_of
from rotstar_mrcal.vnl import write_corners

CAL_LENSMODEL = "LENSMODEL_OPENCV8"  # the d435 preset's own lens family


def calibrate_one(boards: list, weights: list | None, layout: Layout, rts: np.ndarray, model: mrcal.cameramodel,
                  outdir: str) -> dict:
    """mrcal-calibrate-cameras (CAL_LENSMODEL) on one method's boards; its error against the true camera

    boards: per pose (ny, nx, 2) or None; weights: per pose (ny, nx) or None.
    """
    use = [i for i, b in enumerate(boards) if b is not None]
    if len(use) < calib.MIN_BOARDS:
        return {"boards": len(use), "error": f"{len(use)} boards: too few to calibrate"}
    os.makedirs(outdir, exist_ok=True)
    vnl = os.path.join(outdir, "corners.vnl")
    names = [f"pose{i:03d}/frame.png" for i in use]
    with open(vnl, "w") as f:
        write_corners(f, [(n, boards[i]) for n, i in zip(names, use)],
                      None if weights is None else [weights[i] for i in use])
    focal = estimate_focal([boards[i] for i in use], layout.board_points()[..., :2], model.imagersize())
    argv = calib.calibrate_argv(vnl, layout, model.imagersize(), focal, CAL_LENSMODEL, outdir, "*/frame.png",
                                weights=weights is not None)
    try:
        m = calib.run_calibration(argv, in_process=True)
    except calib.CalibrationError as e:
        return {"boards": len(use), "error": str(e).splitlines()[0]}
    e = truth_error(m, model, truth_poses_of(m, {f"pose{i:03d}": rts[i] for i in use}))
    return {"boards": len(use), "fit_rms_px": calib.calibration_stats(m)["rms_px"], **e.summary()}


def calibrate_all(scene, labelled: dict, weights: dict, tmp: str, log=None) -> dict[str, dict]:
    """Every method with boards (and its variants, with their weights), in the registry's order"""
    out = {}
    for name, m in METHODS.items():
        src = m.variant_of or name
        if src not in labelled:
            continue
        layout, rts = (scene.square, scene.rts_square) if m.needs == "square" else (scene.layout, scene.rts)
        if log:
            log(f"  calibrating {name} ({CAL_LENSMODEL})")
        out[name] = calibrate_one(labelled[src], weights.get(name) if m.variant_of else None, layout, rts,
                                  scene.model, os.path.join(tmp, name))
    return out

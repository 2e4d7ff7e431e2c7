"""A screen's cover glass: plain calibration vs rotstar-calibrate's correction, against the true camera (issue 22)

SYNOPSIS

    from rotstar_lab.benchmark.glass import run, table
    rows = run("glass-bench-out", poses=(20,), glass_mm=(0, 0.5, 1.0, 1.5), seed=0)
    print(table(rows))

For each number of poses, one set of random D435 poses (simulate.random_poses:
0.3-0.6 m, tilted up to MAX_TILT_DEG) and, for each glass thickness, the
exact observations of the board's corners through that glass
(optics.refraction.apparent_points, projected with the true camera), plus
Gaussian noise of NOISE_PX (the same noise for every thickness). The corners
are exact projections, not detections: this measures the glass and its
correction alone, as issue 22's table did. Each corner set is written as a
corners.vnl next to a truth-only dataset and calibrated by
calibrate.solve.calibrate with the lens model of the true camera
(LENSMODEL_OPENCV8) and the glass estimated (its default): the plain fit is
the model mrcal-calibrate-cameras wrote (candidates/model/), the corrected
one what rotstar-calibrate writes. Both against the true camera
(evaluate.truth: the board poses aligned by Procrustes, at infinity): the
median and the worst error over the imager.

One more row per number of poses, without glass, through a lens whose
entrance pupil moves along the axis with the field angle (PUPIL_MM at
1 rad, growing as theta^2): a pose-dependent error of the same sign that
no glass explains, which the estimate must report, not apply.
"""

from __future__ import annotations

import os

import mrcal
import numpy as np

from rotstar_mrcal import dataset as ds
from rotstar_mrcal.calibrate.cornerset import load_corner_set
from rotstar_mrcal.calibrate.solve import calibrate
from rotstar_mrcal.evaluate.truth import truth_error, truth_poses_of
from rotstar_mrcal.optics.refraction import Glass, apparent_points
from rotstar_mrcal.pattern.layout import Layout, make_layout
from rotstar_mrcal.simulate.camera import preset_model
from rotstar_mrcal.simulate.dataset import Truth, pose_names, true_corners, write_truth
from rotstar_mrcal.simulate.poses import random_poses
from rotstar_mrcal.vnl import write_corners

NOISE_PX = 0.005
MAX_TILT_DEG = 60.0
LENSMODEL = "LENSMODEL_OPENCV8"
PUPIL_MM = 2.0


def observed_corners(model: mrcal.cameramodel, layout: Layout, rts: np.ndarray, glass: Glass,
                     pupil_mm: float = 0.0) -> np.ndarray:
    """Exact corners (npose, ny, nx, 2) of the emitting layer's board points seen through glass

    pupil_mm: the lens's viewpoint for a ray at field angle theta sits
    pupil_mm * theta^2 (theta in radians) in front of the nominal centre, along
    the axis (a fixed point iteration on the pixel; 0: a central camera).
    """
    c = mrcal.transform_point_rt(mrcal.invert_rt(rts), np.zeros(3))  # camera centres, board frames
    a = apparent_points(c[:, None, None, :], layout.board_points()[None], glass)
    p = mrcal.transform_point_rt(rts[:, None, None, :], a)
    q = mrcal.project(p, *model.intrinsics())
    for _ in range(6 if pupil_mm else 0):
        v = mrcal.unproject(q, *model.intrinsics(), normalize=True)
        theta = np.arccos(np.clip(v[..., 2], -1, 1))
        q = mrcal.project(p - np.stack((0 * theta, 0 * theta, pupil_mm * 1e-3 * theta**2), axis=-1),
                          *model.intrinsics())
    return q


def write_case(folder: str, layout: Layout, model: mrcal.cameramodel, rts: np.ndarray, corners: np.ndarray,
               note: str) -> str:
    """A truth-only dataset (pattern.json, truth.json, truth.cameramodel) and its corners.vnl; the vnl's path"""
    names = pose_names(len(rts))
    os.makedirs(folder, exist_ok=True)
    ds.write_pattern(folder, layout)
    model.write(os.path.join(folder, "truth.cameramodel"))
    write_truth(folder, Truth(model, layout, dict(zip(names, rts)),
                              {n: true_corners(model, layout, r) for n, r in zip(names, rts)}, {"corners": note}))
    first = next(f["file"] for f in layout.frames() if f["kind"] == "rotstar")
    vnl = os.path.join(folder, "corners.vnl")
    with open(vnl, "w") as f:
        write_corners(f, [(f"{n}/{first}", c) for n, c in zip(names, corners)])
    return vnl


def vs_truth(model: mrcal.cameramodel, truth) -> tuple[float, float]:
    """(median, worst) px over the imager at infinity against the true camera"""
    e = truth_error(model, truth.model, truth_poses_of(model, truth.rt_cam_board))
    return float(e.median), float(np.nanmax(e.error))


def run_one(work: str, n: int, glass_mm: float, seed: int = 0, pupil_mm: float = 0.0, log=None) -> dict:
    """One row: n poses, a glass of glass_mm (and a pupil moving pupil_mm at 1 rad), plain vs corrected"""
    model, layout = preset_model("d435"), make_layout()
    rts = random_poses(model, layout, n, np.random.default_rng([0, seed]), max_tilt_deg=MAX_TILT_DEG)
    q = observed_corners(model, layout, rts, Glass.mm(glass_mm), pupil_mm)
    q = q + np.random.default_rng([22, seed, n]).normal(0, NOISE_PX, q.shape)
    name = f"n{n}-glass{glass_mm:g}" + (f"-pupil{pupil_mm:g}" if pupil_mm else "") + f"-seed{seed}"
    vnl = write_case(os.path.join(work, name), layout, model, rts, q,
                     f"exact corners through {glass_mm:g} mm of glass + {NOISE_PX} px noise")
    cs = load_corner_set(vnl)
    c = calibrate(cs, os.path.join(work, name, "cal"), spec=LENSMODEL, keep=True, in_process=True, log=log)
    plain = mrcal.cameramodel(c.candidate(c.chosen).path)
    corrected = mrcal.cameramodel(c.model_path)
    g = c.glass
    return {"poses": n, "glass_mm": glass_mm, "pupil_mm": pupil_mm,
            "plain": vs_truth(plain, cs.truth), "corrected": vs_truth(corrected, cs.truth),
            "estimate_mm": g["thickness_mm"], "sigma_mm": g["sigma_mm"], "applied": g["applied"],
            "reason": g["reason"], "rms_plain_px": g["rms_before_px"], "rms_corrected_px": g["rms_after_px"]}


def run(work: str, poses=(20,), glass_mm=(0.0, 0.5, 1.0, 1.5), seed: int = 0, pupil: bool = True,
        log=None) -> list[dict]:
    """Every row of the table: each number of poses with each glass, then the moving pupil (module doc)"""
    rows = []
    for n in poses:
        for t in glass_mm:
            rows.append(run_one(work, n, t, seed, log=log))
        if pupil:
            rows.append(run_one(work, n, 0.0, seed, PUPIL_MM, log=log))
    return rows


def _f(v) -> str:
    return "-" if v is None else f"{v:.3f}"


def table(rows: list[dict]) -> str:
    """The rows as a Markdown table; 'x glass-free' is the corrected median over the same poses' glass-free plain one"""
    free = {r["poses"]: r["plain"][0] for r in rows if r["glass_mm"] == 0 and not r["pupil_mm"]}
    out = ["| poses | glass | plain vs truth, median / max | corrected, median / max | corrected / glass-free "
           "| thickness estimated | applied |",
           "|---|---|---|---|---|---|---|"]
    for r in rows:
        what = f"{r['glass_mm']:g} mm" + (f", pupil moving {r['pupil_mm']:g} mm" if r["pupil_mm"] else "")
        ratio = r["corrected"][0] / free[r["poses"]] if r["poses"] in free else float("nan")
        est = "-" if r["estimate_mm"] is None else f"{_f(r['estimate_mm'])} +- {_f(r['sigma_mm'])} mm"
        out.append(f"| {r['poses']} | {what} | {r['plain'][0]:.4f} / {r['plain'][1]:.3f} px | "
                   f"{r['corrected'][0]:.4f} / {r['corrected'][1]:.3f} px | {ratio:.2f}x | {est} | "
                   f"{'yes' if r['applied'] else 'no: ' + r['reason']} |")
    return "\n".join(out)

"""A screen's cover glass on rendered captures: rotstar-simulate --glass, then rotstar-calibrate, against the truth

SYNOPSIS

    from rotstar_lab.benchmark.glassrender import rendered_row, rendered_rig_row
    row = rendered_row("work", 20, 1.0, seed=4, jobs=1)      # one D435, rendered through 1 mm of glass
    row["plain"], row["corrected"], row["reference"]        # (median, worst) px against the true camera
    rig = rendered_rig_row("work", 20, 1.0, seed=4, jobs=1)  # the D435's infrared pair (--rig d435)
    rig["plain"]["baseline_error_mm"], rig["corrected"]["rotation_error_deg"]

Everything runs as the user runs it: rotstar-simulate --glass renders the
capture, rotstar-calibrate (its defaults: the glass estimated) detects and
calibrates. The plain model is the solve before the correction (a one-camera
run's candidates/lean/, a rig's candidates/rig/), the corrected one what
rotstar-calibrate wrote.

The reference (same_noise_reference). Two renders of the same poses, one
with glass and one without, have different detection errors, and at 16-40
poses two such calibrations differ by more than 1.2x (median over the imager
against the truth) a third to a half of the time without any glass at all
(measured with exact corners and independent noise draws; issue 22's note).
So a rendered capture is compared with the glass-free calibration that has
its own corner errors: each detected corner's error against the refracted
truth (the true pose and camera, optics.refraction: where the emitting
point is seen through the glass) is put on the unrefracted true corner, and
the plain solve is repeated on those corners from the plain solve's state
(the same boards, mrcal's outliers kept as they were). What is left between
the corrected model and this reference is what the correction did not take
out; the detector's own behaviour under glass (its corners against the
refracted truth) is in noise_px.
"""

from __future__ import annotations

import copy
import json
import os
import subprocess
import sys

import mrcal
import numpy as np

from rotstar_lab.benchmark.glass import TOLERANCE, estimate_off, observed_corners
from rotstar_mrcal.evaluate.stereo import camera_truth_error, extrinsics_error, pose_of_path
from rotstar_mrcal.evaluate.truth import truth_error, truth_poses_of
from rotstar_mrcal.optics.refraction import Glass
from rotstar_mrcal.peers.checkerboard import relabelled_boards
from rotstar_mrcal.programs import run_tool
from rotstar_mrcal.simulate.dataset import load_truth
from rotstar_mrcal.simulate.rig import load_rig_truth


def _tool(name: str) -> str:
    here = os.path.join(os.path.dirname(sys.executable), name)
    return here if os.path.exists(here) else name


def run(argv, log) -> None:
    """Run one of our programs (printed to log first); RuntimeError with its stderr's end when it fails"""
    log("$ " + " ".join(map(str, argv)))
    r = run_tool([_tool(argv[0]), *map(str, argv[1:])], text=True, stdout=subprocess.DEVNULL,
                 stderr=subprocess.PIPE)
    if r.returncode:
        raise RuntimeError(r.stderr[-2000:])


def true_grids(models, layout, rt_cam_board: dict, glass: Glass, oi: dict) -> tuple[np.ndarray, np.ndarray]:
    """(refracted, unrefracted) true corners of every board observation of oi: (Nobs, ny, nx, 2) each

    models[k]: the true camera k; rt_cam_board[(pose name, k)]: its true
    pose. Each observation's pose comes from its image path; the grid is
    labelled as the detector labelled it (the relabelling nearest the
    observed corners). NaN where the pose is unknown.
    """
    obs = oi["observations_board"]
    names = {p for p, _ in rt_cam_board}
    out = np.full((2,) + obs.shape[:-1] + (2,), np.nan)
    for i, (path, (_, k, _)) in enumerate(zip(oi["imagepaths"], oi["indices_frame_camintrinsics_camextrinsics"])):
        rt = rt_cam_board.get((pose_of_path(str(path), names), int(k)))
        if rt is None:
            continue
        both = np.concatenate((observed_corners(models[k], layout, rt[None], glass)[0],
                               observed_corners(models[k], layout, rt[None], Glass())[0]), axis=-1)
        best = min((g for _, g in relabelled_boards(both) if g.shape[:2] == obs.shape[1:3]),
                   key=lambda g: np.nanmean(np.linalg.norm(g[..., :2] - obs[i, ..., :2], axis=-1)))
        out[0, i], out[1, i] = best[..., :2], best[..., 2:]
    return out[0], out[1]


def same_noise_reference(oi0: dict, refracted: np.ndarray, unrefracted: np.ndarray) -> tuple[dict, float]:
    """(oi0 solved again on glass-free corners with oi0's own corner errors, their RMS per coordinate px); module doc"""
    oi = copy.deepcopy(oi0)
    oi["do_apply_outlier_rejection"] = False
    obs = oi["observations_board"].copy()
    used = (obs[..., 2] > 0) & np.isfinite(refracted[..., 0])
    err = np.where(used[..., None], obs[..., :2] - refracted, 0.0)
    obs[..., :2] = np.where(used[..., None], unrefracted + err, obs[..., :2])
    obs[..., 2] = np.where(used, obs[..., 2], -1.0)
    oi["observations_board"] = obs
    mrcal.optimize(**oi)
    return oi, float(np.sqrt(np.mean(err[used] ** 2)))


def glass_of(calibration_json: str) -> dict:
    """What rotstar-calibrate found about the glass (calibration.json's glass; {} without)"""
    with open(calibration_json) as f:
        return json.load(f).get("glass") or {}


def one_vs_truth(model: mrcal.cameramodel, truth) -> tuple[float, float]:
    """(median, worst) px over the imager at infinity against a one-camera dataset's true camera"""
    e = truth_error(model, truth.model, truth_poses_of(model, truth.rt_cam_board))
    return float(e.median), float(np.nanmax(e.error))


def _estimate(g: dict) -> dict:
    return {"estimate_mm": g.get("thickness_mm"), "sigma_mm": g.get("sigma_mm"), "applied": bool(g.get("applied")),
            "reason": g.get("reason", "no glass estimated")}


def rendered_row(work: str, n: int, glass_mm: float, seed: int = 0, jobs: int = 1, log=print) -> dict:
    """One D435 rendered through glass_mm, rotstar-calibrate's defaults: plain, corrected, reference (module doc)"""
    seq = os.path.join(work, f"render-n{n}-glass{glass_mm:g}-seed{seed}")
    cal = seq + "-cal"
    if not os.path.exists(os.path.join(seq, "truth.json")):
        run(["rotstar-simulate", "--out", seq, "--poses", n, "--seed", seed, "--glass", glass_mm, "--jobs", jobs,
             "--force"], log)
    run(["rotstar-calibrate", seq, "--outdir", cal, "--jobs", jobs], log)
    truth = load_truth(seq)
    plain = mrcal.cameramodel(os.path.join(cal, "candidates", "lean", "camera-0.cameramodel"))
    oi = plain.optimization_inputs()
    refr, straight = true_grids([truth.model], truth.layout, {(p, 0): rt for p, rt in truth.rt_cam_board.items()},
                                Glass.mm(glass_mm, truth.settings.get("glass_index", 1.5)), oi)
    ref, noise = same_noise_reference(oi, refr, straight)
    return {"poses": n, "glass_mm": glass_mm, "rendered": True, "noise_px": noise,
            "plain": one_vs_truth(plain, truth),
            "corrected": one_vs_truth(mrcal.cameramodel(os.path.join(cal, "camera-0.cameramodel")), truth),
            "reference": one_vs_truth(mrcal.cameramodel(optimization_inputs=ref, icam_intrinsics=0), truth),
            **_estimate(glass_of(os.path.join(cal, "calibration.json")))}


def rig_vs_truth(models, truth) -> dict:
    """Camera 1 against camera 0, calibrated against the truth; camera 0's lens (median px over its imager)"""
    e = extrinsics_error(models[:2], truth.models[:2])
    return {"baseline_error_mm": e.baseline_error_mm, "direction_error_deg": e.direction_error_deg,
            "rotation_error_deg": e.rotation_error_deg,
            "camera0_median_px": camera_truth_error(models[0], truth.models[0], truth.rt_ref_board).median}


def rendered_rig_row(work: str, n: int, glass_mm: float, seed: int = 0, jobs: int = 1, log=print,
                     rig: str = "d435") -> dict:
    """The D435's infrared pair (rotstar-simulate --rig RIG) rendered through glass_mm, rotstar-calibrate's defaults"""
    seq = os.path.join(work, f"render-{rig}-n{n}-glass{glass_mm:g}-seed{seed}")
    cal = seq + "-cal"
    if not os.path.exists(os.path.join(seq, "truth.json")):
        run(["rotstar-simulate", "--rig", rig, "--out", seq, "--poses", n, "--seed", seed,
             "--glass", glass_mm, "--jobs", jobs, "--force"], log)
    run(["rotstar-calibrate", seq, "--outdir", cal, "--jobs", jobs], log)
    truth = load_rig_truth(seq)
    plain = [mrcal.cameramodel(os.path.join(cal, "candidates", "rig", f"camera-{k}.cameramodel")) for k in (0, 1)]
    corrected = [mrcal.cameramodel(os.path.join(cal, f"camera-{k}.cameramodel")) for k in (0, 1)]
    oi = plain[0].optimization_inputs()
    rts = {(p, k): mrcal.compose_rt(m.extrinsics_rt_fromref(), rt)
           for p, rt in truth.rt_ref_board.items() for k, m in enumerate(truth.models)}
    refr, straight = true_grids(truth.models, truth.layout, rts,
                                Glass.mm(glass_mm, truth.settings.get("glass_index", 1.5)), oi)
    ref, noise = same_noise_reference(oi, refr, straight)
    reference = [mrcal.cameramodel(optimization_inputs=ref, icam_intrinsics=k) for k in (0, 1)]
    return {"poses": n, "glass_mm": glass_mm, "rendered": True, "noise_px": noise, "rig": rig,
            "plain": rig_vs_truth(plain, truth), "corrected": rig_vs_truth(corrected, truth),
            "reference": rig_vs_truth(reference, truth), **_estimate(glass_of(os.path.join(cal, "calibration.json")))}


def _pair(v) -> str:
    return f"{v[0]:.4f} / {v[1]:.3f} px"


def _estimate_cell(r: dict) -> str:
    est = "-" if r["estimate_mm"] is None else f"{r['estimate_mm']:.3f} +- {r['sigma_mm']:.3f} mm"
    return f"{est}, {'applied' if r['applied'] else 'not applied: ' + r['reason']}"


def rendered_table(rows: list[dict]) -> str:
    """The one-camera rendered rows as a Markdown table (corrected / reference: the 1.2x of issue 22)"""
    out = ["| poses | glass | plain vs truth, median / max | corrected | same-noise glass-free reference "
           "| corrected / reference | corners vs refracted truth | thickness estimated |",
           "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['poses']} | {r['glass_mm']:g} mm | {_pair(r['plain'])} | {_pair(r['corrected'])} | "
                   f"{_pair(r['reference'])} | {r['corrected'][0] / r['reference'][0]:.2f}x | "
                   f"{r['noise_px']:.4f} px RMS | {_estimate_cell(r)} |")
    return "\n".join(out)


def rendered_rig_table(rows: list[dict]) -> str:
    """The rendered stereo rows: camera 1 against camera 0, plain -> corrected (same-noise reference)"""
    out = ["| poses | glass | baseline error, plain -> corrected (reference) | its direction | camera 1's rotation "
           "| camera 0 vs truth, median | thickness estimated |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        p, c, f = r["plain"], r["corrected"], r["reference"]
        out.append(f"| {r['poses']} | {r['glass_mm']:g} mm | {p['baseline_error_mm']:+.4f} -> "
                   f"{c['baseline_error_mm']:+.4f} ({f['baseline_error_mm']:+.4f}) mm | "
                   f"{p['direction_error_deg']:.4f} -> {c['direction_error_deg']:.4f} "
                   f"({f['direction_error_deg']:.4f}) deg | {p['rotation_error_deg']:.4f} -> "
                   f"{c['rotation_error_deg']:.4f} ({f['rotation_error_deg']:.4f}) deg | "
                   f"{p['camera0_median_px']:.4f} -> {c['camera0_median_px']:.4f} ({f['camera0_median_px']:.4f}) px | "
                   f"{_estimate_cell(r)} |")
    return "\n".join(out)


def rendered_failures(rows: list[dict], rig: list[dict]) -> list[str]:
    """What issue 22 asks that the rendered rows do not show: corrected within TOLERANCE of the same-noise
    reference, the estimate within 0.1 mm or 2 sigma of the truth, applied with glass and not without"""
    out = []
    for what, r, c, f in ([("one camera", r, r["corrected"][0], r["reference"][0]) for r in rows]
                          + [("stereo pair", r, r["corrected"]["camera0_median_px"],
                              r["reference"]["camera0_median_px"]) for r in rig]):
        name = f"rendered {what}, {r['poses']} poses, glass {r['glass_mm']:g} mm"
        if c > TOLERANCE * f:
            out.append(f"{name}: corrected {c:.4f} px > {TOLERANCE}x its same-noise reference {f:.4f} px")
        if r["glass_mm"] and (estimate_off(r) or not r["applied"]):
            out.append(f"{name}: estimate {r['estimate_mm']} +- {r['sigma_mm']} mm"
                       + ("" if r["applied"] else ", not applied"))
        if not r["glass_mm"] and r["applied"]:
            out.append(f"{name}: an estimate of {r['estimate_mm']:.3f} mm was applied")
    return out


def rendered_report(rows: list[dict], rig: list[dict], seed: int, bad: list[str]) -> str:
    """The rendered tables with their notes"""
    text = ""
    if rows:
        text += ("Rendered and detected (`rotstar-simulate --glass`, then `rotstar-calibrate` with its defaults; "
                 f"seed {seed}); the reference is the glass-free solve with the capture's own corner errors "
                 "(rotstar_lab.benchmark.glassrender):\n\n" + rendered_table(rows))
    if rig:
        preset = rig[0].get("rig", "d435")
        text += (f"\n\nThe D435's infrared pair rendered (`rotstar-simulate --rig {preset} --glass`, then "
                 "`rotstar-calibrate` with its defaults), camera 1 against the truth, plain -> corrected "
                 "(same-noise reference):\n\n" + rendered_rig_table(rig))
    return text + ("\n\n*Not met: " + "; ".join(bad) + "*" if bad else "")

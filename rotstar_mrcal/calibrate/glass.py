"""Taking a screen's cover glass out of a calibration: corrected observations, the thickness estimated

SYNOPSIS

    import mrcal
    from rotstar_mrcal.calibrate.glass import correct_glass
    model = mrcal.cameramodel("cal/candidates/lean/camera-0.cameramodel")  # a solved calibration
    g = correct_glass(model)                    # the thickness estimated from the data
    g.thickness_mm, g.sigma_mm, g.applied, g.reason
    g.model                                     # the re-solved model (the input model when not applied)
    correct_glass(model, thickness_mm=0.7)      # a thickness the user knows
    corrected_boards(g.inputs)                  # its corrected corners, for a corners.vnl (rotstar-glass)

What the glass does (optics.refraction, doc/simulator.md): the light of an
emitting point P reaches the camera as if from A, a point of the board's
plane moved away from the camera by t (tan(theta) - tan(theta_g)), theta the
angle of the ray to the screen's normal and sin(theta) = n sin(theta_g).
The shift depends on the viewing angle, so on the pose and the place on the
board: mrcal's board (a rigid plane, one warp for all poses) cannot take it
and it goes into the lens model.

The correction. After a first solve every board's pose is known, so the
camera centre in board coordinates is too. For a thickness t, each board
point's apparent point A is computed (apparent_points), and the observation
is moved by project(P) - project(A): to where the emitting point would have
been seen without glass. The problem is then solved again with mrcal.optimize
from the solved state, the shifts recomputed from the new poses and
intrinsics, and solved again (SOLVES solves in all; the shifts settle to
~1e-5 px). mrcal's outliers of the first solve stay outliers, and no new ones
are rejected, so that the fits at different t see the same corners.

The thickness. The fit's cost C(t) (the sum of the squared board
residuals after the corrected solves) is smallest at the thickness that
explains the data best. It is evaluated on a coarse grid, a parabola is
fitted around the best point, and evaluated again around its vertex: the
vertex of the last parabola is the estimate, and its curvature gives the
uncertainty, sigma_t^2 = 2 s^2 / C''(t), s^2 = C(t_hat) / (measurements -
states) the fit's noise variance (a profile-likelihood interval).

What is applied. An estimate within MIN_SIGMAS sigma of 0 (or negative) is no
glass: the input model is kept unchanged (at 2 sigma, one glass-free
rendered capture came out 0.139 +- 0.053 mm, and the correction applied
doubled its error against the truth: 0.012 -> 0.023 px). An estimate above MAX_PLAUSIBLE_MM is not
a cover glass but another pose-dependent error with the same sign (a lens
whose entrance pupil moves with the field angle, which mrcal's central models
cannot represent, is one; the screen's own geometry another): it is reported,
not applied, and the input model is kept. So is an estimate that the boards
do not agree on: the thickness is estimated again from the less tilted half
of the boards and from the more tilted half (a glass is one thickness for
all; a moving entrance pupil shifts corners with the field angle, not with
the board's tilt, so its two halves differ), and halves more than
HALVES_Z of their combined sigma apart are "another pose-dependent error".
Otherwise the model re-solved at the estimate is the result. A thickness
given by the user is applied as given.
"""

from __future__ import annotations

import copy
import dataclasses

import mrcal
import numpy as np

from rotstar_mrcal.optics.refraction import DEFAULT_INDEX, Glass, apparent_points

SOLVES = 3
"""mrcal solves per thickness (the shifts recomputed from each solve's poses)"""

MAX_PLAUSIBLE_MM = 3.0
"""Thicker than any display's cover glass: an estimate beyond is another pose-dependent error"""

COARSE_MM = (0.0, 1.0, 2.0, 4.0)
"""The thicknesses the cost is evaluated at first"""

FINE_STEP_MM = 0.25
"""Half-width of the second parabola around the first one's vertex"""

MIN_SIGMAS = 3.0
"""An estimate is a glass only this many sigma above 0 (one-sided: 0.13 % of glass-free captures by chance)"""

HALVES_Z = 3.0
"""The less and the more tilted half of the boards disagree on the thickness beyond this many sigma: no glass"""

MIN_HALF_BOARDS = 5
"""Fewer boards in a half: the halves are not compared"""


def board_points(oi: dict) -> np.ndarray:
    """The solved (warped) board's points, board frame: (ny, nx, 3)"""
    ny, nx = oi["observations_board"].shape[1:3]
    return mrcal.ref_calibration_object(nx, ny, oi["calibration_object_spacing"],
                                        calobject_warp=oi.get("calobject_warp"))


def cam_from_frame(oi: dict) -> np.ndarray:
    """rt_cam_frame of every board observation: (Nobs, 6)"""
    idx = oi["indices_frame_camintrinsics_camextrinsics"]
    rt = oi["rt_ref_frame"][idx[:, 0]]
    ext = oi["rt_cam_ref"]
    if len(ext) == 0:
        return rt
    with_ext = mrcal.compose_rt(ext[np.maximum(idx[:, 2], 0)], rt)
    return np.where((idx[:, 2] >= 0)[:, None], with_ext, rt)


def observation_shift(oi: dict, glass: Glass) -> np.ndarray:
    """project(P) - project(A) of every board point of every observation: (Nobs, ny, nx, 2) pixels

    What to add to an observed corner to move it to where the emitting point
    would have been seen without the glass, given the solved poses and
    intrinsics of oi.
    """
    obj = board_points(oi)
    rt = cam_from_frame(oi)
    c = mrcal.transform_point_rt(mrcal.invert_rt(rt), np.zeros(3))  # camera centres, board frames
    a = apparent_points(c[:, None, None, :], obj[None], glass)
    intr = oi["intrinsics"][oi["indices_frame_camintrinsics_camextrinsics"][:, 1]][:, None, None, :]
    q_true = mrcal.project(mrcal.transform_point_rt(rt[:, None, None, :], obj), oi["lensmodel"], intr)
    q_app = mrcal.project(mrcal.transform_point_rt(rt[:, None, None, :], a), oi["lensmodel"], intr)
    return q_true - q_app


def board_cost(oi: dict) -> tuple[float, int]:
    """(sum of the squared board residuals, their number) at oi's state"""
    x = mrcal.measurements_board(oi)  # (N, 2) weighted residuals, mrcal's outliers left out
    return float(np.sum(x * x)), int(x.size)


def solve_with_glass(oi0: dict, thickness_mm: float, index: float = DEFAULT_INDEX, solves: int = SOLVES) -> dict:
    """oi0's problem solved again with its observations corrected for a glass (a new optimization_inputs)

    oi0's observations are the raw ones; its state is the starting point.
    Outliers stay as oi0 has them; no new ones are rejected. A negative
    thickness applies the opposite shift (no glass does that; the cost's
    search runs through 0 smoothly).
    """
    return solve_corrected(oi0, Glass.mm(abs(thickness_mm), index), np.sign(thickness_mm), solves)


def solve_corrected(oi0: dict, glass: Glass, sign: float = 1.0, solves: int = SOLVES) -> dict:
    """solve_with_glass for a Glass: each of `solves` solves moves the raw observations by sign times the shift
    from the poses it starts from (observation_shift); no glass: solved once, as they are"""
    oi = copy.deepcopy(oi0)
    oi["do_apply_outlier_rejection"] = False
    raw = oi0["observations_board"]
    for _ in range(solves if not glass.none else 1):
        obs = raw.copy()
        if not glass.none:
            obs[..., :2] = raw[..., :2] + sign * observation_shift(oi, glass)
        oi["observations_board"] = obs
        mrcal.optimize(**oi)
    return oi


def cost_at(oi0: dict, thickness_mm: float, index: float) -> float:
    """C(t): the board residuals' sum of squares of the corrected solve at thickness_mm"""
    return board_cost(solve_with_glass(oi0, thickness_mm, index))[0]


def parabola(t: np.ndarray, c: np.ndarray) -> tuple[float, float]:
    """(vertex, second derivative) of the least-squares parabola through (t, c)

        >>> [round(v, 9) for v in parabola(np.array((0.0, 1, 2, 3)), np.array((4.0, 1, 0, 1)))]
        [2.0, 2.0]
    """
    a, b, _ = np.polyfit(t, c, 2)
    return (float(-b / (2 * a)) if a > 0 else float("nan")), float(2 * a)


@dataclasses.dataclass
class GlassResult:
    """What correct_glass found and did"""

    thickness_mm: float  # the estimate (or the given thickness); NaN when the cost has no minimum
    sigma_mm: float  # its 1-sigma uncertainty (NaN when given)
    index: float
    given: bool  # the thickness was given, not estimated
    applied: bool  # the model is the re-solved one
    reason: str
    rms_before_px: float  # fit RMS (per corner, 2-D) without and with the correction
    rms_after_px: float
    costs: dict  # thickness mm -> C(t), every thickness evaluated
    halves: list | None = None  # [[t, sigma] of the less tilted half of the boards, [t, sigma] of the more tilted]
    model: mrcal.cameramodel | None = None  # the result (the input model when not applied)
    inputs: dict | None = None  # the re-solved optimization inputs when applied (every camera of a rig)

    def models(self, inputs_models: list) -> list:
        """Every camera of the problem re-solved (the input models, camera by camera, when not applied)"""
        if self.inputs is None:
            return list(inputs_models)
        return [corrected_model(m, self.inputs, k) for k, m in enumerate(inputs_models)]

    def to_json(self) -> dict:
        d = {k: (None if isinstance(v, float) and not np.isfinite(v) else v)  # JSON has no NaN
             for k, v in dataclasses.asdict(self).items() if k not in ("model", "inputs")}
        d["costs"] = {f"{k:.4g}": v for k, v in sorted(self.costs.items())}
        if self.halves is not None:
            d["halves"] = [[v if np.isfinite(v) else None for v in h] for h in self.halves]
        return d

    def line(self) -> str:
        """One line for people (glass_line)"""
        return glass_line(self.to_json())


def glass_line(d: dict) -> str:
    """One line of a GlassResult's JSON for people"""
    if d["thickness_mm"] is None:
        what = "no estimate"
    else:
        what = (f"{d['thickness_mm']:.3f} mm (given)" if d["given"] else
                f"{d['thickness_mm']:.3f} +- {d['sigma_mm']:.3f} mm (estimated)")
    return (f"cover glass (index {d['index']:g}): {what}; {'applied' if d['applied'] else 'not applied'}: "
            f"{d['reason']}; fit RMS {d['rms_before_px']:.5f} -> {d['rms_after_px']:.5f} px")


def estimate_thickness(oi0: dict, index: float = DEFAULT_INDEX) -> tuple[float, float, dict]:
    """(t_hat mm, sigma mm, {t mm: C(t)}) from a solved problem; module doc"""
    costs = {t: cost_at(oi0, t, index) for t in COARSE_MM}
    ts = np.array(sorted(costs))
    k = int(np.argmin([costs[t] for t in ts]))
    near = ts[max(0, min(k - 1, len(ts) - 3)):][:3]
    t1, _ = parabola(near, np.array([costs[t] for t in near]))
    if not np.isfinite(t1):
        return float("nan"), float("nan"), costs
    t1 = float(np.clip(t1, ts[0] - 1.0, ts[-1] + 1.0))
    for t in (t1 - FINE_STEP_MM, t1, t1 + FINE_STEP_MM):
        costs.setdefault(t, cost_at(oi0, t, index))
    fine = np.array((t1 - FINE_STEP_MM, t1, t1 + FINE_STEP_MM))
    t_hat, curv = parabola(fine, np.array([costs[t] for t in fine]))
    if not (np.isfinite(t_hat) and curv > 0):
        return float("nan"), float("nan"), costs
    c_hat, nmeas = board_cost(solve_with_glass(oi0, t_hat, index))
    dof = max(1, nmeas - mrcal.num_states(**oi0))
    return t_hat, float(np.sqrt(2 * (c_hat / dof) / curv)), costs


def board_tilts(oi: dict) -> np.ndarray:
    """Degrees between each observed board's normal and the line of sight to its centre: (Nobs,)"""
    rt = cam_from_frame(oi)
    centre = mrcal.transform_point_rt(rt, board_points(oi).reshape(-1, 3).mean(axis=0))
    normal = mrcal.R_from_r(rt[:, :3])[:, :, 2]
    cos = np.abs(np.sum(normal * centre, axis=-1)) / np.linalg.norm(centre, axis=-1)
    return np.degrees(np.arccos(np.clip(cos, 0, 1)))


def subset_inputs(oi: dict, keep: np.ndarray) -> dict:
    """oi with only the board observations keep (indices), their frames renumbered; solved again"""
    out = copy.deepcopy(oi)
    idx = oi["indices_frame_camintrinsics_camextrinsics"][keep].copy()
    frames, idx[:, 0] = np.unique(idx[:, 0], return_inverse=True)
    out["indices_frame_camintrinsics_camextrinsics"] = idx.astype(np.int32)
    out["observations_board"] = oi["observations_board"][keep].copy()
    out["rt_ref_frame"] = oi["rt_ref_frame"][frames].copy()
    if oi.get("imagepaths") is not None:
        out["imagepaths"] = np.asarray(oi["imagepaths"])[keep]
    mrcal.optimize(**out)
    return out


def halves_estimates(oi0: dict, index: float) -> list | None:
    """[[t, sigma] from the less tilted half of the boards, [t, sigma] from the more tilted], or None if few

    The halves are halves of the board poses (frames), by their mean tilt
    over the cameras that saw them: every camera of a rig keeps boards in both.
    """
    iframe = oi0["indices_frame_camintrinsics_camextrinsics"][:, 0]
    nframes = len(oi0["rt_ref_frame"])
    tilt = np.bincount(iframe, board_tilts(oi0), nframes) / np.maximum(np.bincount(iframe, None, nframes), 1)
    order = np.argsort(tilt, kind="stable")
    if nframes < 2 * MIN_HALF_BOARDS:
        return None
    half = nframes // 2
    return [list(estimate_thickness(subset_inputs(oi0, np.flatnonzero(np.isin(iframe, part))), index)[:2])
            for part in (order[:half], order[half:])]


def halves_disagree(halves: list | None) -> bool:
    """The two halves' thicknesses more than HALVES_Z combined sigma apart (or one has no estimate)"""
    if halves is None:
        return False
    (a, sa), (b, sb) = halves
    return not (np.isfinite(a) and np.isfinite(b)) or abs(a - b) > HALVES_Z * np.hypot(sa, sb)


def _rms(oi: dict) -> float:
    c, n = board_cost(oi)
    return float(np.sqrt(2 * c / n)) if n else float("nan")


def corrected_boards(oi: dict) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """[(image path, (ny, nx, 2) corners, (ny, nx) weights)] of a problem's board observations, as it holds them

    For a re-solved problem (GlassResult.inputs): the corrected corners, to
    write as a corners.vnl (vnl.write_corners) for a second mrcal run. A
    corner mrcal did not use (missing, or an outlier) is NaN with weight 0.
    """
    paths = oi.get("imagepaths")
    obs = oi["observations_board"]
    if paths is None or len(paths) != len(obs):
        raise ValueError("the model's optimization_inputs name no image per board (mrcal-calibrate-cameras "
                         "writes them): cannot write a corners file")
    used = obs[..., 2] > 0
    return [(str(p), np.where(u[..., None], o[..., :2], np.nan), np.where(u, o[..., 2], 0.0))
            for p, o, u in zip(paths, obs, used)]


def corrected_model(model: mrcal.cameramodel, oi: dict, icam: int = 0) -> mrcal.cameramodel:
    """Camera icam of a re-solved problem, with the input model's (camera icam's) valid-intrinsics region"""
    out = mrcal.cameramodel(optimization_inputs=oi, icam_intrinsics=icam)
    vir = model.valid_intrinsics_region()
    if vir is not None:
        out.valid_intrinsics_region(vir)
    return out


def correct_glass(model: mrcal.cameramodel, thickness_mm: float | None = None,
                  index: float = DEFAULT_INDEX) -> GlassResult:
    """Estimate (thickness_mm None) or apply a cover glass to a solved calibration; module doc

    model: any camera of the solve (its optimization_inputs hold the whole
    problem; a rig's every camera); .model is camera 0 of the result,
    .models() every camera.
    """
    oi0 = model.optimization_inputs()
    oi0["do_apply_outlier_rejection"] = False
    mrcal.optimize(**oi0)  # the baseline: the same solver and corners as the corrected solves
    before = _rms(oi0)
    if thickness_mm is not None:
        if thickness_mm == 0:
            return GlassResult(0.0, float("nan"), index, True, False, "no glass (as given)", before, before,
                               {0.0: board_cost(oi0)[0]}, model=model)
        oi = solve_with_glass(oi0, thickness_mm, index)
        return GlassResult(float(thickness_mm), float("nan"), index, True, True, "as given", before, _rms(oi),
                           {float(thickness_mm): board_cost(oi)[0]}, model=corrected_model(model, oi), inputs=oi)
    t_hat, sigma, costs = estimate_thickness(oi0, index)
    keep = lambda why: GlassResult(t_hat, sigma, index, False, False, why, before, before, costs,  # noqa: E731
                                   model=model)
    if not np.isfinite(t_hat):
        return keep("the fit's cost has no minimum in the thickness")
    if t_hat > MAX_PLAUSIBLE_MM:
        return keep(f"more than any cover glass ({MAX_PLAUSIBLE_MM:g} mm): another pose-dependent error "
                    "(e.g. a moving entrance pupil), not applied")
    if t_hat <= MIN_SIGMAS * sigma:
        return keep(f"no glass: the estimate is within {MIN_SIGMAS:g} sigma of 0")
    halves = halves_estimates(oi0, index)
    if halves_disagree(halves):
        (a, sa), (b, sb) = halves
        r = keep(f"the less and the more tilted boards disagree ({a:.3f} +- {sa:.3f} vs {b:.3f} +- {sb:.3f} mm): "
                 "another pose-dependent error (e.g. a moving entrance pupil), not applied")
        r.halves = halves
        return r
    oi = solve_with_glass(oi0, t_hat, index)
    return GlassResult(t_hat, sigma, index, False, True, "estimated from the data" + (
        "" if halves else f" (fewer than {2 * MIN_HALF_BOARDS} boards: the halves not compared)"), before, _rms(oi),
        costs, halves, model=corrected_model(model, oi), inputs=oi)

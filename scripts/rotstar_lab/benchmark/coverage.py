"""Does covering the imager's edges and corners pay off in mrcal's own terms? (issue 13)

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.pattern.layout import make_layout
    >>> from rotstar_mrcal.simulate.camera import preset_model
    >>> from rotstar_lab.benchmark.coverage import plan_captures, corners_in_view, regions
    >>> model, layout = preset_model("d435"), make_layout()
    >>> plan = plan_captures(model, layout, n=6, hanging=2, seed=0)
    >>> plan.captures["whole"], plan.captures["edges"], plan.kinds[6:]
    ([0, 1, 2, 3, 4, 5], [0, 1, 2, 3, 6, 7], ['top-left', 'top-right'])
    >>> [round(float(corners_in_view(model, layout, plan.rts[k]).mean()), 2) for k in (6, 7)]
    [0.71, 0.44]
    >>> {k: v.shape for k, v in regions((1280, 800)).items()}
    {'corners': (4, 2), 'ring': (960, 2), 'centre': (96, 2)}

    # the whole experiment (scripts/coverage_bench.py, `make coverage-bench`):
    r = run("work", n=20, hanging=8, corners="detect", jobs=2)
    print(table(r))

Two simulated captures with the same number of poses, on the same camera
(the D435 preset: 1280 x 800, OPENCV8) and the same pattern:

    whole   n poses with the whole board in view, as a user captures them
            today (simulate.random_poses: stratified over the imager, 0.3-0.6
            m, tilted up to WHOLE_MAX_TILT_DEG, any roll)
    edges   the first n - k of those, and k boards hanging over the image's
            corners and edges (hanging_pose: close, HANGING_DISTANCE_M
            for the D435 and the default board (scaled for others),
            tilted HANGING_TILT_DEG, any roll, HANGING_IN_VIEW of the corners
            in view, the board covering the image's corner or a point of its
            edge); the four corners first, then the four edges

One dataset holds all n + k poses (rendered once); each capture is a
corners.vnl of its poses, written by vnl.write_corners (mrcal's row rule
applied) and calibrated by validate.calibrate.calibrate with one lens model
for both (OPENCV8, the true camera's family, by default). Then, in the
calibrated model and against the true camera (validate.truth.truth_error,
the board poses aligned by Procrustes), at infinity:

    corners   the four imager corners, CORNER_INSET px inside
    ring      the outer RING of the imager (a point grid, RING_GRID wide,
              in the band within 10 % of the width of the left and right
              edges or 10 % of the height of the top and bottom edges)
    centre    the central 20 % x 20 %, for reference

the projection uncertainty (mrcal.projection_uncertainty through
validate.uncertainty: 1-sigma, worst direction, at infinity) and the model's
error against the true camera. The ratios are whole / edges: above 1, the
capture with hanging boards is better.

Corners come from rotstar's detection (corners="detect": detect.run's
detect_dataset on the rendered frames) or, to check this machinery only,
from the truth (corners="truth+noise": the true projections of the corners
whose refinement window lies inside the image, plus Gaussian noise). The
second is never a result: table() says so in its first line and
scripts/coverage_bench.py refuses to write it into the documentation.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os

import mrcal
import numpy as np

from rotstar_mrcal import dataset as ds
from rotstar_mrcal.pattern.layout import Layout, make_layout
from rotstar_mrcal.simulate.dataset import (
    load_truth, pose_names, Settings, true_corners, Truth, write_dataset, write_truth,
)
from rotstar_mrcal.simulate.poses import (
    board_samples, default_distance_range, look_at_pose, random_poses, REFERENCE_DISTANCE_M,
)
from rotstar_mrcal.simulate.camera import preset_model
from rotstar_mrcal.evaluate.uncertainty import imager_grid, projection_uncertainty
from rotstar_mrcal.calibrate.solve import calibrate, CalibrationError
from rotstar_mrcal.vnl import write_corners
from rotstar_mrcal.calibrate.cornerset import load_corner_set
from rotstar_mrcal.detect.run import detect_dataset
from rotstar_mrcal.dataset import open_dataset
from rotstar_mrcal.evaluate.truth import truth_error, truth_poses_of

CAPTURES = ("whole", "edges")
ZONES = ("top-left", "top-right", "bottom-left", "bottom-right", "left", "right", "top", "bottom")
WHOLE_MAX_TILT_DEG = 50.0  # doc/capture.md's advice before issue 13
HANGING_DISTANCE_M = (0.22, 0.4)
HANGING_TILT_DEG = (20.0, 60.0)
HANGING_IN_VIEW = (0.3, 0.75)
VIEW_MARGIN_PX = 10.0  # a corner is seen when its refinement window (10 px) lies inside the image
CORNER_INSET = 5.0
RING = 0.1
RING_GRID = 64
NOISE_PX = 0.01  # truth+noise: about rotstar's error on the simulated D435 (README: 0.006 px RMS)
MACHINERY_NOTE = ("MACHINERY CHECK ONLY (corners = truth + noise, not rotstar's detection): "
                  "not a result, never to be reported")


# ---------------------------------------------------------------------------
# the poses
# ---------------------------------------------------------------------------
def corners_in_view(model: mrcal.cameramodel, layout: Layout, rt, margin: float = VIEW_MARGIN_PX) -> np.ndarray:
    """(ny, nx) bool: the corners in front of the camera that project at least margin px inside the image"""
    W, H = model.imagersize()
    p = mrcal.transform_point_rt(np.asarray(rt, float), layout.board_points())
    q = mrcal.project(p, *model.intrinsics())
    with np.errstate(invalid="ignore"):
        return ((p[..., 2] > 0) & np.isfinite(q).all(axis=-1) & (q[..., 0] >= margin) & (q[..., 1] >= margin)
                & (q[..., 0] <= W - 1 - margin) & (q[..., 1] <= H - 1 - margin))


def zone_box(zone: str, imagersize, ring: float = RING) -> tuple[float, float, float, float]:
    """(x0, y0, x1, y1) of a zone's part of the imager's outer ring (a corner: both bands)"""
    W, H = (float(v) for v in imagersize)
    bx, by = ring * W, ring * H
    x = {"left": (0, bx), "right": (W - bx, W), None: (0, W)}
    y = {"top": (0, by), "bottom": (H - by, H), None: (0, H)}
    parts = zone.split("-")
    h = next((s for s in parts if s in ("left", "right")), None)
    v = next((s for s in parts if s in ("top", "bottom")), None)
    return x[h][0], y[v][0], x[h][1], y[v][1]


def _anchor(zone: str, imagersize, inset: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(the zone's point on the image border, moved inset px inward; the unit vector toward the image centre)

    A corner's point is the image corner, an edge's the middle of the edge.
    """
    W, H = (float(v) for v in imagersize)
    x0, y0, x1, y1 = zone_box(zone, imagersize)
    a = np.array((0.0 if x0 == 0 and x1 < W else (W - 1 if x1 == W and x0 > 0 else (W - 1) / 2),
                  0.0 if y0 == 0 and y1 < H else (H - 1 if y1 == H and y0 > 0 else (H - 1) / 2)))
    d = np.array(((W - 1) / 2, (H - 1) / 2)) - a
    d = np.where(np.abs(d) < 1, 0, d)
    return a + inset * np.sign(d), d / np.linalg.norm(d)


def hanging_ok(model: mrcal.cameramodel, layout: Layout, rt, zone: str, in_view=HANGING_IN_VIEW,
               margin: float = VIEW_MARGIN_PX, along=(0.0, 0.0)) -> bool:
    """A board hanging over the zone: a fraction in_view of its corners seen, unfolded, and covering the zone

    Covering: the board's corner grid covers the image corner (or the
    point of the edge `along` px from its middle), 2 margin px inside.
    """
    rt = np.asarray(rt, float)
    R = mrcal.R_from_r(rt[:3])
    if (R.T @ rt[3:])[2] <= 0 or np.any(mrcal.transform_point_rt(rt, board_samples(layout))[:, 2] <= 0):
        return False  # the camera behind the screen, or part of the screen behind the camera
    seen = corners_in_view(model, layout, rt, margin)
    if not in_view[0] <= seen.mean() <= in_view[1]:
        return False
    p = mrcal.transform_point_rt(rt, layout.board_points())[seen]
    q, dq_dp, _ = mrcal.project(p, *model.intrinsics(), get_gradients=True)
    if np.any(np.linalg.det(dq_dp @ R[:, :2]) <= 0):
        return False  # the projection folds
    return bool(covers(model, layout, rt, _anchor(zone, model.imagersize(), inset=2 * margin)[0] + along))


def covers(model: mrcal.cameramodel, layout: Layout, rt, q) -> np.ndarray:
    """Does the board's corner grid cover pixel(s) q (..., 2)? (the pixel's ray meets the board inside its grid)"""
    v = mrcal.unproject(np.asarray(q, float), *model.intrinsics())
    R, t = mrcal.R_from_r(np.asarray(rt[:3], float)), np.asarray(rt[3:], float)
    # the ray s v in board coordinates: R^T (s v - t); its z = 0 gives s
    vb, tb = v @ R, R.T @ t
    s = tb[2] / vb[..., 2]
    p = s[..., None] * vb - tb
    eps = 1e-9  # metres: a corner of the grid covers its own pixel
    (x0, y0), (x1, y1) = layout.board_points()[0, 0, :2] - eps, layout.board_points()[-1, -1, :2] + eps
    return (s > 0) & (p[..., 0] >= x0) & (p[..., 0] <= x1) & (p[..., 1] >= y0) & (p[..., 1] <= y1)


def hanging_distance(model: mrcal.cameramodel, layout: Layout) -> tuple[float, float]:
    """HANGING_DISTANCE_M for another camera or board, scaled as simulate's default distance range

    >>> from rotstar_mrcal.simulate.camera import preset_model
    >>> hanging_distance(preset_model("d435"), make_layout())
    (0.22, 0.4)
    """
    k = default_distance_range(model, layout)[0] / REFERENCE_DISTANCE_M[0]
    return tuple(float(round(d * k, 12)) for d in HANGING_DISTANCE_M)


def hanging_pose(model: mrcal.cameramodel, layout: Layout, zone: str, rng, *, distance=None,
                 tilt_deg=HANGING_TILT_DEG, in_view=HANGING_IN_VIEW, max_tries: int = 2000) -> np.ndarray:
    """rt_cam_board of a board close to the camera, tilted, hanging over an image corner or edge (hanging_ok)

    distance: (min, max) metres, default hanging_distance(model, layout).
    """
    rng = np.random.default_rng(rng)
    distance = hanging_distance(model, layout) if distance is None else distance
    W, H = (float(v) for v in model.imagersize())
    a, inward = _anchor(zone, (W, H))
    along = np.array((-inward[1], inward[0]))
    for _ in range(max_tries):
        d = rng.uniform(*distance)
        shift = 0.0 if "-" in zone else rng.uniform(-0.25, 0.25) * (W if zone in ("top", "bottom") else H)
        target = a + inward * rng.uniform(-0.1, 0.35) * min(W, H) + along * shift
        rt = look_at_pose(model, layout, target, d, tilt=math.radians(rng.uniform(*tilt_deg)),
                          tilt_axis=rng.uniform(0, 2 * math.pi), roll=rng.uniform(0, 2 * math.pi))
        if hanging_ok(model, layout, rt, zone, in_view, along=along * shift):
            return rt
    raise RuntimeError(f"no board hanging over the {zone} with {in_view[0]:.0%}-{in_view[1]:.0%} of its corners "
                       f"in view after {max_tries} tries")


@dataclasses.dataclass
class Plan:
    """The poses rendered (whole ones first, then the hanging ones) and which of them each capture holds"""

    rts: np.ndarray  # (n + k, 6)
    kinds: list[str]  # 'whole' or the zone a board hangs over
    captures: dict[str, list[int]]  # 'whole', 'edges' -> indices into rts

    @property
    def names(self) -> list[str]:
        return pose_names(len(self.rts))


def plan_captures(model: mrcal.cameramodel, layout: Layout, n: int = 20, hanging: int = 8, seed: int = 0,
                  max_tilt_deg: float = WHOLE_MAX_TILT_DEG) -> Plan:
    """n whole-board poses, and k = hanging boards over the corners, then the edges; see the module doc"""
    if not 0 < hanging < n:
        raise ValueError(f"hanging boards must be 1 to n - 1 = {n - 1}, not {hanging}")
    whole = random_poses(model, layout, n, np.random.default_rng([11, seed]), max_tilt_deg=max_tilt_deg)
    zones = [ZONES[k % len(ZONES)] for k in range(hanging)]
    hang = [hanging_pose(model, layout, z, np.random.default_rng([12, seed, k])) for k, z in enumerate(zones)]
    return Plan(np.concatenate((whole, hang)), ["whole"] * n + zones,
                {"whole": list(range(n)), "edges": list(range(n - hanging)) + list(range(n, n + hanging))})


# ---------------------------------------------------------------------------
# where to look
# ---------------------------------------------------------------------------
def regions(imagersize, inset: float = CORNER_INSET, ring: float = RING, gridn: int = RING_GRID) -> dict:
    """{'corners': (4, 2), 'ring': (m, 2), 'centre': (k, 2)} pixels (module doc)"""
    W, H = (float(v) for v in imagersize)
    corners = np.array(((inset, inset), (W - 1 - inset, inset), (inset, H - 1 - inset),
                        (W - 1 - inset, H - 1 - inset)))
    q = imager_grid((W, H), gridn).reshape(-1, 2)
    outer = (q[:, 0] < ring * W) | (q[:, 0] > (1 - ring) * W) | (q[:, 1] < ring * H) | (q[:, 1] > (1 - ring) * H)
    centre = (np.abs(q[:, 0] - W / 2) < 0.1 * W) & (np.abs(q[:, 1] - H / 2) < 0.1 * H)
    return {"corners": corners, "ring": q[outer], "centre": q[centre]}


def _rms(x) -> float:
    return float(np.sqrt(np.nanmean(np.square(x))))


def measure(model: mrcal.cameramodel, truth_model: mrcal.cameramodel, rt_cam_board: dict, where=None) -> dict:
    """{'uncertainty': {...}, 'error': {...}} px at infinity in the regions (module doc)

    Each holds 'corners' (the four values: top-left, top-right, bottom-left,
    bottom-right), 'corners_mean', 'ring_rms', 'ring_median', 'centre_median'.
    """
    where = regions(model.imagersize()) if where is None else where
    rt = truth_poses_of(model, rt_cam_board)
    out = {}
    for what, f in (("uncertainty", lambda q: projection_uncertainty(model, q)),
                    ("error", lambda q: truth_error(model, truth_model, rt, q=q).error)):
        v = {k: np.asarray(f(q), float) for k, q in where.items()}
        out[what] = {"corners": [float(x) for x in v["corners"]], "corners_mean": float(np.mean(v["corners"])),
                     "ring_rms": _rms(v["ring"]), "ring_median": float(np.median(v["ring"])),
                     "centre_median": float(np.median(v["centre"]))}
    return out


# ---------------------------------------------------------------------------
# the corners of each pose
# ---------------------------------------------------------------------------
def truth_noise_corners(model, layout: Layout, rts, sigma: float = NOISE_PX, seed: int = 0,
                        margin: float = VIEW_MARGIN_PX) -> list[np.ndarray]:
    """MACHINERY CHECK ONLY: true corners in view (corners_in_view) plus Gaussian noise; NaN elsewhere"""
    rng = np.random.default_rng([13, seed])
    out = []
    for rt in rts:
        c = true_corners(model, layout, rt) + rng.normal(0, sigma, (layout.ny, layout.nx, 2))
        c[~corners_in_view(model, layout, rt, margin)] = np.nan
        out.append(c)
    return out


def detected_corners(seq: str, jobs: int = 1, progress=None) -> list[np.ndarray | None]:
    """rotstar's corners of every pose of seq (detect.run.detect_dataset), None where it found no board"""
    det = detect_dataset(open_dataset(seq), jobs=jobs, progress=progress)
    return [r.corners.corners if r.found else None for r in det.results()]


def write_truth_only(seq: str, layout: Layout, model: mrcal.cameramodel, plan: Plan) -> None:
    """pattern.json, truth.json and truth.cameramodel without images (for corners="truth+noise")"""
    os.makedirs(seq, exist_ok=True)
    ds.write_pattern(seq, layout)
    model.write(os.path.join(seq, "truth.cameramodel"))
    write_truth(seq, Truth(model, layout, dict(zip(plan.names, plan.rts)),
                           {n: true_corners(model, layout, r) for n, r in zip(plan.names, plan.rts)},
                           {"corners": "truth+noise (machinery check)"}))


# ---------------------------------------------------------------------------
# the experiment
# ---------------------------------------------------------------------------
@dataclasses.dataclass
class CaptureResult:
    """One capture calibrated and measured"""

    name: str
    poses: int
    hanging: int  # of which hanging over an edge or corner
    boards: int  # boards mrcal used
    hanging_used: int  # ... of them hanging over an edge or corner
    sparse: list[str]  # poses written as no board (too few corners for mrcal)
    missing: list[str]  # poses that gave no board at all
    corners: int  # corners mrcal used
    ring_corners: int  # ... of them in the outer ring of the imager
    lensmodel: str
    rms_px: float  # the fit's RMS (2-D)
    outliers: int
    uncertainty: dict  # measure()
    error: dict
    model: str  # the model file
    note: str = ""  # what the calibration had to do (validate.calibrate: a board mrcal seeded badly)


@dataclasses.dataclass
class CoverageResult:
    corners: str  # 'detect' or 'truth+noise'
    camera: str
    seed: int
    captures: dict[str, CaptureResult]

    def ratios(self) -> dict:
        """whole / edges for every number of measure(): > 1 where the capture with hanging boards is better"""
        a, b = self.captures["whole"], self.captures["edges"]
        out = {}
        for what in ("uncertainty", "error"):
            x, y = getattr(a, what), getattr(b, what)
            out[what] = {k: (float(np.divide(x[k], y[k])) if k != "corners" else
                             [float(u / v) for u, v in zip(x[k], y[k])]) for k in x}
        return out

    def to_json(self) -> dict:
        return {"corners": self.corners, "camera": self.camera, "seed": self.seed,
                "captures": {k: dataclasses.asdict(v) for k, v in self.captures.items()}, "ratios": self.ratios()}


def calibrate_capture(seq: str, name: str, files: list[str], boards: list, outdir: str, lensmodel: str,
                      plan: Plan, idx: list[int], log=None) -> CaptureResult:
    """Write seq/<name>.vnl, calibrate it (validate.calibrate.calibrate, one lens model), measure it"""
    vnl = os.path.join(seq, f"{name}.vnl")
    with open(vnl, "w") as f:
        sparse = write_corners(f, [(files[i], boards[i]) for i in idx])
    cs = load_corner_set(vnl)
    c = calibrate(cs, outdir, spec=lensmodel, keep=True, in_process=True, log=log)
    if not c.model_path:  # an implausible fit is not written even with keep

        raise CalibrationError(f"{vnl}: no model: " + "; ".join(c.failures))
    model = mrcal.cameramodel(c.model_path)
    W, H = cs.imagersize
    obs = model.optimization_inputs()["observations_board"]
    q = obs[..., :2][obs[..., 2] > 0]
    ring = (q[:, 0] < RING * W) | (q[:, 0] > (1 - RING) * W) | (q[:, 1] < RING * H) | (q[:, 1] > (1 - RING) * H)
    m = measure(model, cs.truth.model, cs.truth.rt_cam_board)
    names = plan.names
    used = set(cs.names)
    return CaptureResult(name, len(idx), sum(plan.kinds[i] != "whole" for i in idx), len(cs.files),
                         sum(plan.kinds[i] != "whole" and names[i] in used for i in idx),
                         [os.path.basename(os.path.dirname(s.file)) for s in sparse],
                         [names[i] for i in idx if boards[i] is None], int(len(q)), int(ring.sum()),
                         model.intrinsics()[0], c.stats["rms_px"], c.stats["outliers"], m["uncertainty"],
                         m["error"], c.model_path, c.candidate(c.chosen).note)


def run(work: str, n: int = 20, hanging: int = 8, seed: int = 0, corners: str = "detect", camera: str = "d435",
        layout: Layout | None = None, lensmodel: str = "LENSMODEL_OPENCV8", settings: Settings | None = None,
        jobs: int = 1, log=None) -> CoverageResult:
    """Simulate, detect (or truth+noise), calibrate and measure both captures; see the module doc"""
    log = log or (lambda s: None)
    if corners not in ("detect", "truth+noise"):
        raise ValueError(f"corners must be 'detect' or 'truth+noise', not {corners!r}")
    model, layout = preset_model(camera), layout or make_layout()
    plan = plan_captures(model, layout, n, hanging, seed)
    seq = os.path.join(work, "seq")
    first = next(f["file"] for f in layout.frames() if f["kind"] == "rotstar")
    files = [f"{p}/{first}" for p in plan.names]
    if corners == "detect":
        if not _rendered(seq, plan):
            log(f"rendering {len(plan.rts)} poses into {seq}")
            write_dataset(seq, layout, model, plan.rts, settings or Settings(bits=16, seed=seed), jobs=jobs,
                          progress=log, extra={"camera": camera, "kinds": plan.kinds})
        log(f"detecting {seq}")
        boards = detected_corners(seq, jobs)
    else:
        log(MACHINERY_NOTE)
        write_truth_only(seq, layout, model, plan)
        boards = truth_noise_corners(model, layout, plan.rts, seed=seed)
    caps = {}
    for name in CAPTURES:
        log(f"calibrating the {name} capture ({lensmodel})")
        caps[name] = calibrate_capture(seq, name, files, boards, os.path.join(work, f"cal-{name}"), lensmodel, plan,
                                       plan.captures[name], log)
    return CoverageResult(corners, camera, seed, caps)


def _rendered(seq: str, plan: Plan) -> bool:
    """seq already holds these poses, rendered (a re-run reuses them)"""
    try:
        with open(os.path.join(seq, "truth.json")) as f:
            t = json.load(f)
        rts = np.array([t["poses"][p]["rt_cam_board"] for p in plan.names])
    except (OSError, KeyError, ValueError):
        return False
    return (rts.shape == plan.rts.shape and np.allclose(rts, plan.rts, atol=1e-12)
            and all(os.path.isdir(os.path.join(seq, p)) for p in plan.names) and len(t["poses"]) == len(plan.names))


# ---------------------------------------------------------------------------
# what it says
# ---------------------------------------------------------------------------
def _f(v: float) -> str:
    return f"{v:.4f}" if v < 1 else f"{v:.3g}"


def table(r: CoverageResult) -> str:
    """The Markdown table: both captures side by side and the ratios"""
    a, b = r.captures["whole"], r.captures["edges"]
    ra = r.ratios()
    lines = [MACHINERY_NOTE, ""] if r.corners != "detect" else []
    lines += [f"| {r.camera}, {a.lensmodel.replace('LENSMODEL_', '')}, px at infinity | whole boards only | "
              f"with boards over the edges | ratio |", "|---|---|---|---|"]

    def row(label, x, y, q):
        lines.append(f"| {label} | {x} | {y} | {q} |")

    row("poses (hanging over an edge or corner)", f"{a.poses} ({a.hanging})", f"{b.poses} ({b.hanging})", "")
    row("boards mrcal used (hanging)", f"{a.boards} ({a.hanging_used})", f"{b.boards} ({b.hanging_used})", "")
    row("corners used (in the outer 10 %)", f"{a.corners} ({a.ring_corners})", f"{b.corners} ({b.ring_corners})", "")
    row("fit RMS (2-D)", _f(a.rms_px), _f(b.rms_px), "")
    for what, label in (("uncertainty", "uncertainty (1-sigma)"), ("error", "error vs the true camera")):
        x, y, q = getattr(a, what), getattr(b, what), ra[what]
        row(f"{label}: the 4 corners, mean", _f(x["corners_mean"]), _f(y["corners_mean"]),
            f"**{q['corners_mean']:.1f}x**")
        row(f"{label}: each corner (TL, TR, BL, BR)", " / ".join(_f(v) for v in x["corners"]),
            " / ".join(_f(v) for v in y["corners"]), " / ".join(f"{v:.1f}" for v in q["corners"]))
        row(f"{label}: outer 10 %, RMS", _f(x["ring_rms"]), _f(y["ring_rms"]), f"**{q['ring_rms']:.1f}x**")
        row(f"{label}: outer 10 %, median", _f(x["ring_median"]), _f(y["ring_median"]), f"{q['ring_median']:.1f}x")
        row(f"{label}: centre, median", _f(x["centre_median"]), _f(y["centre_median"]), f"{q['centre_median']:.1f}x")
    notes = [f"{c.name}: {', '.join(c.sparse)} written as no board (too few corners for mrcal)"
             for c in (a, b) if c.sparse]
    notes += [f"{c.name}: {', '.join(c.missing)} gave no board" for c in (a, b) if c.missing]
    notes += [f"{c.name}: {c.note}" for c in (a, b) if c.note]
    if notes:
        lines += [""] + [f"- {x}" for x in notes]
    return "\n".join(lines)


def seeds_table(results: list[CoverageResult]) -> str:
    """The ratios (whole / with edges) of runs with other poses (seeds), one row each"""
    lines = ["| seed | boards mrcal used (hanging), with edges | uncertainty ratio: 4 corners, mean | worst corner | "
             "outer 10 %, RMS | error ratio: 4 corners, mean | outer 10 %, RMS |", "|---|---|---|---|---|---|---|"]
    for r in results:
        q, b = r.ratios(), r.captures["edges"]
        u, e = q["uncertainty"], q["error"]
        lines.append(f"| {r.seed} | {b.boards} ({b.hanging_used}) | {u['corners_mean']:.1f}x | {min(u['corners']):.1f}x | "
                     f"{u['ring_rms']:.1f}x | {e['corners_mean']:.1f}x | {e['ring_rms']:.1f}x |")
    return "\n".join(lines)


def verdict(results, factor: float = 2.0) -> tuple[bool, str]:
    """(is the uncertainty at every imager corner at least factor x lower with hanging boards, one line)

    results: one CoverageResult or a list of them (seeds): every corner of every run.
    """
    results = [results] if isinstance(results, CoverageResult) else list(results)
    q = [v for r in results for v in r.ratios()["uncertainty"]["corners"]]
    ok = min(q) >= factor
    runs = f" over {len(results)} captures" if len(results) > 1 else ""
    return ok, (f"uncertainty at the imager corners {min(q):.1f}-{max(q):.1f}x lower with boards over the edges{runs} "
                f"({'at least' if ok else 'NOT at least'} {factor:g}x at every corner)")


def figure(r: CoverageResult, fn: str, gridn: int = RING_GRID) -> str:
    """Uncertainty and error against the truth over the imager, both captures, the corners each used"""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    models = {k: mrcal.cameramodel(c.model) for k, c in r.captures.items()}
    seq = os.path.dirname(os.path.dirname(os.path.abspath(next(iter(r.captures.values())).model)))
    truth = load_truth(os.path.join(seq, "seq"))
    W, H = models["whole"].imagersize()
    q = imager_grid((W, H), gridn)
    maps = {}
    for k, m in models.items():
        maps[("uncertainty", k)] = projection_uncertainty(m, q)
        maps[("error", k)] = truth_error(m, truth.model, truth_poses_of(m, truth.rt_cam_board), q=q).error
    fig, ax = plt.subplots(2, 2, figsize=(11, 6.4), constrained_layout=True)
    titles = {"whole": "whole boards only", "edges": "with boards over the edges"}
    for i, what in enumerate(("uncertainty", "error")):
        vals = np.concatenate([maps[(what, k)].ravel() for k in CAPTURES])
        norm = LogNorm(vmin=max(np.nanpercentile(vals, 1), 1e-5), vmax=np.nanmax(vals))
        for j, k in enumerate(CAPTURES):
            a = ax[i, j]
            im = a.imshow(maps[(what, k)], extent=(0, W, H, 0), norm=norm, cmap="viridis")
            obs = models[k].optimization_inputs()["observations_board"]
            p = obs[..., :2][obs[..., 2] > 0]
            a.scatter(p[:, 0], p[:, 1], s=0.4, color="white", alpha=0.6, linewidths=0)
            a.set_xlim(0, W)
            a.set_ylim(H, 0)
            a.set_title(f"{titles[k]}: " + ("uncertainty (1-sigma)" if what == "uncertainty" else
                                            "error vs the true camera"), fontsize=10)
        fig.colorbar(im, ax=ax[i, :], shrink=0.9, label="px at infinity")
    if r.corners != "detect":
        fig.suptitle(MACHINERY_NOTE, color="red", fontsize=9)
    os.makedirs(os.path.dirname(os.path.abspath(fn)), exist_ok=True)
    fig.savefig(fn, dpi=90)
    plt.close(fig)
    return fn

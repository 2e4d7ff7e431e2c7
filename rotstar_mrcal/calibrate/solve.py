"""Running mrcal-calibrate-cameras, the lean-then-splined choice, the Calibration and its JSON

SYNOPSIS

    # the whole calibration, as rotstar-calibrate runs it:
    cs = cornerset.load_corner_set("cal/corners.vnl", truth=False)
    c = calibrate(cs, "cal")            # a Calibration; c.ok, c.reason, c.to_json()
    print("\n".join(c.summary_lines()))

The command is calibrate.command's, the checks calibrate.checks'.

The lens model. mrcal's practice (doc/how-to-calibrate.org, "Model
choice", and the tour) is to fit a lean model first and a rich one when the
data can constrain it, and to compare them. The default ('auto') here:

1. LENSMODEL_OPENCV8, the lean model, on every board (LEAN_LENSMODEL; this is
   also the model of rotstar-detect's printed command and of rotstar-crossval).
2. mrcal's recommended LENSMODEL_SPLINED_STEREOGRAPHIC (order 3, dense knots
   whose Ny/Nx follows the imager's aspect ratio, a field of view of
   4 atan(W / 4f) + 10% from the focal seed f) only when the boards can
   constrain it: at least SPLINED_MIN_BOARDS boards whose corners reach
   SPLINED_MIN_COVERAGE of the cells of a knot-sized grid over the imager.
3. Both are compared with mrcal.projection_diff against the sum of their
   projection uncertainties. The splined model is written only when it
   explains the corners clearly better (fit RMS below SPLINED_BETTER_RMS of
   the lean one's) and the two differ beyond their uncertainty: the lean
   model does not fit the lens. When the splined fit is no better, the lean
   model is written (the splined one's extra freedom is not supported by the
   boards). When they fit equally well but disagree, the check fails.

A board mrcal seeds badly. mrcal-calibrate-cameras seeds every board's pose
from a stereographic core without distortion and rejects outliers from the
first full solve on. A board far into an image corner, close and tilted (a
board hanging over the edge, which the identity frames make possible) can
be seeded so far off that mrcal rejects most of its corners, leaving a few
in a line: a board pose the data no longer pins down, which makes the
projection uncertainty explode (measured on a simulated 20-pose capture: 37
of 42 corners of one such board rejected, the uncertainty at the imager
corners 5000 px instead of 0.05). Short of that, which corners of such
boards mrcal rejects depends on the random start it gives the distortion
terms (measured: 0, 5 or 8 good corners of the same 20 boards over eight
starts). So whenever mrcal rejected corners, calibrate() solves again,
seeded from the model of the first solve (mrcal-calibrate-cameras --seed
instead of --focal: every board's pose then starts from a model with
distortion, and no term starts at random), and keeps that solve if it
rejects fewer corners; real outliers are rejected by both.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import runpy
import shutil
import sys
import tempfile

import cv2
import mrcal
import numpy as np

from rotstar_mrcal.atomic import atomic_path
from rotstar_mrcal.programs import run_tool
from rotstar_mrcal.calibrate.command import (
    DEFAULT_KNOTS_X, LEAN_LENSMODEL, InputError, calibrate_argv, command_line, image_glob,
    mrcal_corners, recommended_lensmodel, reseeded_argv, resolve_lensmodel,
)
from rotstar_mrcal.calibrate.checks import (
    MAX_DROP_SEARCH, MIN_BOARDS, MOSTLY_OUTLIERS, check_inputs, far_boards, fit_failures, misordered_boards,
    model_failures, mostly_line, splined_supported,
)
from rotstar_mrcal.calibrate.cornerset import pose_name
from rotstar_mrcal.calibrate.focal import focal_seed
from rotstar_mrcal.calibrate.glass import correct_glass, glass_line
from rotstar_mrcal.optics.refraction import DEFAULT_INDEX
from rotstar_mrcal.evaluate.crossval import cross_validate
from rotstar_mrcal.evaluate.uncertainty import projection_uncertainty

SPLINED_BETTER_RMS = 0.8
"""The splined model replaces the lean one only if its fit RMS is below this fraction of the lean one's"""


class CalibrationError(RuntimeError):
    """mrcal-calibrate-cameras failed; the message ends with its last output lines"""


def calibration_argv(cs, outdir: str, lensmodel: str, focal: float | None = None, vnl: str | None = None) -> list[str]:
    """The mrcal-calibrate-cameras command for a corner set (sources.CornerSet); vnl: mrcal's copy (mrcal_corners)"""
    focal = focal_seed(cs, check=False) if focal is None else focal
    return calibrate_argv(vnl or cs.vnl, cs.layout, cs.imagersize, focal, lensmodel, outdir,
                          image_glob(cs.files), weights=cs.weights)


def first_argv(cs, outdir: str, spec: str = "auto", focal: float | None = None, knots_x: int = DEFAULT_KNOTS_X,
               force: bool = False) -> list[str]:
    """The first mrcal-calibrate-cameras command calibrate() would run, after the inputs' checks (--dry-run)"""
    check_inputs(cs)
    f = focal or focal_seed(cs, check=not force)
    lm = resolve_lensmodel(spec, cs.imagersize, f, knots_x)
    check_inputs(cs, lm, force)
    return calibration_argv(cs, os.path.join(outdir, "candidates", "lean"), lm, f)


def _executable(name: str) -> str:
    """name on PATH, or next to this Python (the venv's bin, where mrcal's tools are)"""
    found = shutil.which(name)
    if found:
        return found
    here = os.path.join(os.path.dirname(sys.executable), name)
    if os.path.exists(here):
        return here
    raise CalibrationError(f"{name} not found on PATH nor next to {sys.executable}; "
                           "put the venv's bin first on PATH")


def run_calibration(argv, in_process: bool = False) -> mrcal.cameramodel:
    """Run a calibrate_argv command; return the model it wrote (camera-0)

    in_process: run the mrcal-calibrate-cameras script in this Python
    (runpy, with sys.argv set and its output captured) instead of a new
    process: the same program, without paying for Python and mrcal's start
    (a few seconds without cached bytecode). For worker processes that run
    many calibrations, and the leave-one-out search (_culprits: up to
    MAX_DROP_SEARCH solves). Measured (lean model, 6 boards, 2 busy cores):
    0.8-0.9 s a solve as a program, 0.15-0.19 s in process (0.5 s the first),
    so 0.7 s saved a solve, 28 s on a 40-board search: kept. Raises CalibrationError with the tail of mrcal's
    output when it fails.
    """
    argv = [str(a) for a in argv]
    outdir = argv[argv.index("--outdir") + 1]
    os.makedirs(outdir, exist_ok=True)
    exe = _executable(argv[0])
    if in_process:
        code, text = _run_script(exe, argv[1:])
    else:
        r = run_tool([exe] + argv[1:], capture_output=True, text=True)
        code, text = r.returncode, r.stdout + r.stderr
    if code != 0:
        tail = "\n".join(text.strip().splitlines()[-6:])
        raise CalibrationError(f"mrcal-calibrate-cameras exited with {code}:\n{tail}")
    fn = os.path.join(outdir, "camera-0.cameramodel")
    if not os.path.exists(fn):
        raise CalibrationError(f"mrcal-calibrate-cameras wrote no {fn}")
    return mrcal.cameramodel(fn)


def _dup_or_none(fd: int) -> int | None:
    """os.dup(fd), None if fd is not open"""
    try:
        return os.dup(fd)
    except OSError:
        return None


def _run_script(script: str, args) -> tuple[int, str]:
    """runpy a Python script as __main__ with sys.argv = [script, *args]; (exit code, its output)

    Its output, Python's and the C library's (file descriptors 1 and 2), is
    captured and returned; its standard input (sys.stdin and descriptor 0)
    is /dev/null meanwhile, as for the programs steps.run_tool starts, so
    that it never reads the terminal. Global state the script changes and we know of
    (sys.argv, numpy's print options: mrcal-calibrate-cameras sets
    linewidth=300) is put back.
    """
    saved_argv, saved_print = sys.argv, np.get_printoptions()
    sys.argv = [script, *args]
    code = 0
    sys.stdout.flush()
    sys.stderr.flush()
    saved_fds, saved_stdin = (os.dup(1), os.dup(2), _dup_or_none(0)), sys.stdin
    with tempfile.TemporaryFile(mode="w+") as tmp, open(os.devnull) as null:
        os.dup2(tmp.fileno(), 1)
        os.dup2(tmp.fileno(), 2)
        os.dup2(null.fileno(), 0)
        sys.stdin = null
        try:
            with contextlib.redirect_stdout(tmp), contextlib.redirect_stderr(tmp):
                runpy.run_path(script, run_name="__main__")
        except SystemExit as e:
            code = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
            if not isinstance(e.code, (int, type(None))):
                tmp.write(str(e.code))
        except Exception as e:  # the script raised: report it as a failed run
            code = 1
            tmp.write(f"{type(e).__name__}: {e}")
        finally:
            tmp.flush()
            os.dup2(saved_fds[0], 1)
            os.dup2(saved_fds[1], 2)
            if saved_fds[2] is None:
                os.close(0)
            else:
                os.dup2(saved_fds[2], 0)
                os.close(saved_fds[2])
            os.close(saved_fds[0])
            os.close(saved_fds[1])
            sys.argv, sys.stdin = saved_argv, saved_stdin
            np.set_printoptions(**saved_print)
        tmp.seek(0)
        return code, tmp.read()


# ---------------------------------------------------------------------------
# what a calibration says about itself
# ---------------------------------------------------------------------------
def board_residuals(model: mrcal.cameramodel):
    """Unweighted reprojection errors of a calibration's own boards

    Returns (N, ny, nx) pixel distances between the observed corners and the
    solved model's projection of the (warped) board, NaN where a corner was
    missing or rejected as an outlier; each board through its own camera
    (several cameras solved jointly). mrcal's printed RMS is per axis, of
    weighted residuals, and counts missing points as zeros; this is the plain
    2-D error of the points the solve used.
    """
    oi = model.optimization_inputs()
    obs = oi["observations_board"]
    N, ny, nx = obs.shape[:3]
    obj = mrcal.ref_calibration_object(nx, ny, oi["calibration_object_spacing"],
                                       calobject_warp=oi.get("calobject_warp"))
    rt_ref_frame = oi["rt_ref_frame"][oi["indices_frame_camintrinsics_camextrinsics"][:, 0]]
    icam = oi["indices_frame_camintrinsics_camextrinsics"][:, 2]
    p = mrcal.transform_point_rt(rt_ref_frame[:, None, None, :], obj)
    if np.any(icam >= 0):
        p = np.where((icam >= 0)[:, None, None, None],
                     mrcal.transform_point_rt(oi["rt_cam_ref"][np.maximum(icam, 0)][:, None, None, :], p), p)
    intr = oi["intrinsics"][oi["indices_frame_camintrinsics_camextrinsics"][:, 1]]  # each board's camera
    q = mrcal.project(p, oi["lensmodel"], intr[:, None, None, :])
    e = np.linalg.norm(q - obs[..., :2], axis=-1)
    return np.where(obs[..., 2] > 0, e, np.nan)


def calibration_stats(model: mrcal.cameramodel) -> dict:
    """Numbers of a calibration: boards, points used, RMS and worst residual (2-D, unweighted)"""
    e = board_residuals(model)
    ok = np.isfinite(e)
    return {
        "lensmodel": model.intrinsics()[0],
        "boards": int(e.shape[0]),
        "points": int(ok.sum()),
        "rms_px": float(np.sqrt(np.mean(e[ok] ** 2))) if ok.any() else float("nan"),
        "mean_px": float(np.mean(e[ok])) if ok.any() else float("nan"),
        "max_px": float(np.max(e[ok])) if ok.any() else float("nan"),
        "focal_px": [float(v) for v in model.intrinsics()[1][:2]],
    }


REGIONS = ("top-left", "top", "top-right", "left", "centre", "right", "bottom-left", "bottom", "bottom-right")


def region_of(q, imagersize) -> np.ndarray:
    """Index into REGIONS (thirds of the imager) of pixels q (..., 2)"""
    W, H = imagersize
    q = np.asarray(q, float)
    ix = np.clip((q[..., 0] * 3 / W).astype(int), 0, 2)
    iy = np.clip((q[..., 1] * 3 / H).astype(int), 0, 2)
    return iy * 3 + ix


def model_stats(model: mrcal.cameramodel, cs=None) -> dict:
    """What a calibration reports about itself (JSON-able)

    boards and corners used, outliers (mrcal's rejections: corners the input
    had that the solve dropped; counted by imager region), the 2-D unweighted
    fit RMS and worst residual (pose, corner, pixel), mrcal's noise estimate
    sigma (per axis, of the weighted residuals), the 1-sigma projection
    uncertainty (worst direction, at infinity) at the imager centre and
    corners, and the valid-intrinsics region's share of the imager. cs (the
    corner set the model was calibrated from) tells input gaps from outliers.
    """
    oi = model.optimization_inputs()
    lens, intr = model.intrinsics()
    W, H = (int(v) for v in model.imagersize())
    obs = oi["observations_board"]
    e = board_residuals(model)
    ok = np.isfinite(e)
    ip = oi.get("imagepaths")
    paths = [pose_name(p) for p in (ip if ip is not None else [])]
    if cs is not None and len(paths) == obs.shape[0]:
        byname = dict(zip(cs.names, cs.corners))
        given = np.stack([np.isfinite(byname[p]).all(axis=-1) if p in byname else np.ones(obs.shape[1:3], bool)
                          for p in paths])
    else:
        given = np.ones(obs.shape[:3], bool)
    outlier = given & (obs[..., 2] <= 0)
    where = np.bincount(region_of(obs[..., :2][outlier], (W, H)), minlength=9)
    lost, had = outlier.sum(axis=(1, 2)), given.sum(axis=(1, 2))
    mostly = {(paths[b] if len(paths) == obs.shape[0] else str(b)): [int(lost[b]), int(had[b])]
              for b in np.flatnonzero(lost > MOSTLY_OUTLIERS * had)} if cs is not None else {}
    stats = {
        "lensmodel": lens,
        "boards": int(obs.shape[0]),
        "corners": int(ok.sum()),
        "outliers": int(outlier.sum()),
        "outlier_fraction": float(outlier.sum() / max(1, given.sum())),
        "outliers_where": {r: int(c) for r, c in zip(REGIONS, where) if c},
        "boards_mostly_outliers": mostly,  # pose -> [corners rejected, corners given]
        "rms_px": float(np.sqrt(np.mean(e[ok] ** 2))) if ok.any() else float("nan"),
        "worst_px": float(np.max(e[ok])) if ok.any() else float("nan"),
        "board_rms_px": {(paths[b] if len(paths) == obs.shape[0] else str(b)): float(np.sqrt(np.mean(e[b][ok[b]] ** 2)))
                         for b in range(obs.shape[0]) if ok[b].any()},
        "sigma_px": float(np.std(mrcal.measurements_board(oi))),
        "focal_px": [float(v) for v in intr[:2]],
        "centre_px": [float(v) for v in intr[2:4]],
    }
    if ok.any():
        b, i, j = np.unravel_index(np.nanargmax(np.where(ok, e, -1)), e.shape)
        stats["worst_at"] = {"pose": paths[b] if len(paths) == obs.shape[0] else int(b), "corner": [int(j), int(i)],
                             "pixel": [round(float(v), 1) for v in obs[b, i, j, :2]]}
    q = np.array([[(W - 1) / 2, (H - 1) / 2], [0, 0], [W - 1, 0], [0, H - 1], [W - 1, H - 1]], float)
    try:
        u = projection_uncertainty(model, q)
        stats["uncertainty_px"] = {"centre": float(u[0]), "corners_max": float(np.max(u[1:])),
                                   "corners": [float(v) for v in u[1:]]}
    except Exception as ex:  # noqa: BLE001 mrcal raises plain Exceptions
        stats["uncertainty_px"] = {"error": str(ex).splitlines()[0] if str(ex) else type(ex).__name__}
    vir = model.valid_intrinsics_region()
    if vir is None:
        stats["valid_region_fraction"] = None
    else:
        stats["valid_region_fraction"] = (float(cv2.contourArea(np.asarray(vir, np.float32)) / (W * H))
                                          if len(vir) >= 3 else 0.0)
    return stats


def stats_line(s: dict) -> str:
    """One line of model_stats for people"""
    where = ", ".join(f"{k} {v}" for k, v in s["outliers_where"].items())
    u = s.get("uncertainty_px", {})
    unc = (f"uncertainty {u['centre']:.4f} px at the centre, up to {u['corners_max']:.4f} at the corners"
           if "centre" in u else f"uncertainty unknown ({u.get('error')})")
    vr = s.get("valid_region_fraction")
    at = s.get("worst_at", {})
    return (f"{s['lensmodel']}: {s['boards']} boards, {s['corners']} corners, {s['outliers']} outliers"
            + (f" ({where})" if where else "")
            + f"; fit RMS {s['rms_px']:.5f} px (2-D), worst {s['worst_px']:.4f} px"
            + (f" ({at.get('pose')} corner {at.get('corner')} at {at.get('pixel')})" if at else "")
            + f"; {unc}; valid-intrinsics region "
            + ("not computed" if vr is None else f"{100 * vr:.0f}% of the imager"))


@dataclasses.dataclass
class Candidate:
    """One model fitted by mrcal-calibrate-cameras"""

    name: str  # 'lean' or 'splined'
    lensmodel: str
    command: str
    path: str  # the model file mrcal wrote (under outdir/candidates/)
    stats: dict | None = None
    error: str | None = None  # mrcal failed
    note: str = ""  # e.g. why it was solved again, seeded from its first solve

    def to_json(self) -> dict:
        return dataclasses.asdict(self)


@dataclasses.dataclass
class Calibration:
    """The result of calibrate(): the model written (or not) and why; owns its JSON form"""

    model_path: str | None  # outdir/camera-0.cameramodel when written
    chosen: str | None  # name of the candidate written or proposed
    reason: str  # why that one
    failures: list[str]  # checks that failed (empty: ok)
    kept: bool  # written despite failures (keep=True)
    candidates: list[Candidate]
    comparison: dict | None  # cross_validate(lean, splined).summary()
    focal_seed: float
    corners: str  # the corners.vnl
    dropped: dict = dataclasses.field(default_factory=dict)  # pose -> why its board was left out
    glass: dict | None = None  # calibrate.glass.GlassResult.to_json(): the cover glass estimated / applied


    FORMAT = "rotstar-calibrate/1"

    @property
    def ok(self) -> bool:
        return not self.failures

    @property
    def paths(self) -> list[str]:
        """The model written: [outdir/camera-0.cameramodel], or []"""
        return [self.model_path] if self.model_path else []

    @property
    def stats(self) -> dict | None:
        c = self.candidate(self.chosen)
        return c.stats if c else None

    def candidate(self, name):
        return next((c for c in self.candidates if c.name == name), None)

    def to_json(self) -> dict:
        return {"format": self.FORMAT, "ok": self.ok, "model": self.model_path, "chosen": self.chosen,
                "reason": self.reason, "failures": self.failures, "kept": self.kept,
                "focal_seed_px": self.focal_seed, "corners": self.corners, "comparison": self.comparison,
                "dropped": self.dropped, "glass": self.glass,
                "candidates": [c.to_json() for c in self.candidates]}

    def summary_lines(self) -> list[str]:
        out = [f"dropped {k}: {v}" for k, v in self.dropped.items()]
        for c in self.candidates:
            mark = "written" if c.name == self.chosen and self.model_path else (
                "chosen" if c.name == self.chosen else "not written")
            out.append(f"{c.name} ({mark}): " + (stats_line(c.stats) if c.stats else f"failed: {c.error}")
                       + (f" [{c.note}]" if c.note else ""))
        if self.comparison:
            k = self.comparison
            out.append(f"lean vs splined: projection diff {k['diff_median_px']:.4f} px median (p95 "
                       f"{k['diff_p95_px']:.3f}), uncertainty uA+uB {k['unc_median_px']:.4f} px, ratio "
                       f"{k['ratio_median']:.2f} ({k['verdict']})")
        if self.glass:
            out.append(glass_line(self.glass))
        out.append(f"model: {self.reason}")
        return out


# ---------------------------------------------------------------------------
# the calibration: lean, then splined when supported; reseeded; implausible fits searched
# ---------------------------------------------------------------------------
def calibrate(cs, outdir: str, spec: str = "auto", focal: float | None = None, knots_x: int = DEFAULT_KNOTS_X,
              keep: bool = False, force: bool = False, in_process: bool = False, log=None,
              glass_mm: float | None = None, glass_index: float = DEFAULT_INDEX) -> Calibration:
    """Calibrate a corner set; write outdir/camera-0.cameramodel if its checks pass (or keep)

    spec: 'auto' (lean, then splined when supported; module doc), or one
    lens model (resolve_lensmodel). Raises InputError (before mrcal runs)
    for inputs that cannot give a model, CalibrationError when mrcal fails
    on the model that would be written. Every mrcal command goes to log (a
    function of one line) before it runs. The candidates' models stay in
    outdir/candidates/<name>/; outdir/camera-0.cameramodel is removed first
    and written (atomically) only for a result. Boards out of grid order
    (misordered_boards) are dropped before mrcal runs, a board that explains
    an implausible fit (fit_failures) after it; each is named in log and in
    Calibration.dropped. A fit that stays implausible is not written, even
    with keep.

    The screen's cover glass (calibrate.glass): glass_mm None estimates its
    thickness from the chosen fit and writes the model re-solved for it
    when the estimate is a plausible glass; a number applies that thickness
    (0: no correction). Calibration.glass says what was found and done.
    """
    log = log or (lambda s: None)
    final = os.path.join(outdir, "camera-0.cameramodel")
    _remove_stale(outdir)
    dropped = {}
    bad = misordered_boards(cs.corners, cs.files, cs.layout)
    if bad and 2 * len(bad) > len(cs.files):
        f0, why = next(iter(bad.items()))
        raise InputError(f"{cs.vnl}: {len(bad)} of its {len(cs.files)} boards are not the pattern's grid, e.g. "
                         f"{f0}: {why}")
    if bad:
        cs = _drop(cs, bad, dropped, log)
    check_inputs(cs)  # the boards and the image sizes first: they decide whether anything can be done
    f = focal_seed(cs, check=not force) if focal is None else float(focal)
    lensmodel = resolve_lensmodel(spec, cs.imagersize, f, knots_x)
    check_inputs(cs, lensmodel, force)
    plan, why = _plan(cs, spec, lensmodel, f, knots_x, log)
    vnl = mrcal_corners(cs.vnl, os.path.join(outdir, "candidates"), drop=set(dropped))
    if vnl != cs.vnl and not dropped:
        log(f"{cs.vnl} is not plain ASCII text with LF line ends: mrcal reads the text we read, copied to {vnl}")
    while True:
        chosen, reason, failures, cands, comparison = _fit(cs, outdir, plan, f, vnl, why, in_process, log)
        f_boards = focal_seed(cs, check=False)  # what the boards say, whatever --focal was
        implausible = fit_failures(chosen.stats, f_boards)
        if not implausible:
            break
        culprits = _culprits(cs, chosen, f_boards, outdir, dropped, log)
        if not culprits or len(cs.files) - len(culprits) < MIN_BOARDS:
            failures = implausible + failures
            break
        cs = _drop(cs, culprits, dropped, log)
        vnl = mrcal_corners(cs.vnl, os.path.join(outdir, "candidates"), drop=set(dropped))
    written, glass = None, None
    if not failures or (keep and not implausible):
        os.makedirs(outdir, exist_ok=True)
        source, glass = _glass(chosen, outdir, glass_mm, glass_index, log)
        _atomic_copy(source, final)
        written = final
    return Calibration(written, chosen.name, reason, failures, bool(failures) and bool(written), cands, comparison,
                       f, cs.vnl, {pose_name(k): v for k, v in dropped.items()}, glass)


def _glass(chosen: Candidate, outdir: str, glass_mm: float | None, index: float, log) -> tuple[str, dict | None]:
    """(the model file to write, the glass's JSON): chosen's model, or it re-solved for a cover glass"""
    if glass_mm == 0:
        return chosen.path, None
    log("cover glass: " + ("estimating its thickness from the fit" if glass_mm is None else
                           f"correcting for {glass_mm:g} mm (index {index:g})"))
    g = correct_glass(mrcal.cameramodel(chosen.path), glass_mm, index)
    d = g.to_json()
    if g.applied:
        d["model"] = os.path.join(outdir, "candidates", "glass", "camera-0.cameramodel")
        os.makedirs(os.path.dirname(d["model"]), exist_ok=True)
        g.model.write(d["model"])
    return d.get("model", chosen.path), d


def _remove_stale(outdir: str) -> None:
    """outdir's model and its candidates' models from an earlier run: a failed run leaves none behind"""
    names = ("lean", "splined", "model", "lean-seeded", "splined-seeded", "model-seeded")
    for stale in [os.path.join(outdir, "camera-0.cameramodel")] + [
            os.path.join(outdir, "candidates", n, "camera-0.cameramodel") for n in names + ("glass",)]:
        if os.path.exists(stale):
            os.remove(stale)


def _plan(cs, spec: str, lensmodel: str, f: float, knots_x: int, log) -> tuple[list, str | None]:
    """The candidates to fit, [(name, lens model)], and why the splined one is (not) among them"""
    plan = [("lean" if spec.strip().lower() in ("auto", "lean") else "model", lensmodel)]
    why = None
    if spec.strip().lower() == "auto":
        ok, why = splined_supported(cs, knots_x)
        if ok:
            plan.append(("splined", recommended_lensmodel(cs.imagersize, f, knots_x)))
            log(f"splined model supported ({why}): fitting it after the lean one")
        else:
            log(f"lean model only: {why}")
    return plan, why


def _atomic_copy(src: str, dst: str) -> None:
    with atomic_path(dst) as tmp:
        shutil.copyfile(src, tmp)


def _reseed(c: Candidate, argv, cs, in_process: bool, log) -> None:
    """Solve c again seeded from its first solve (module doc: a board mrcal seeds badly); keep the better one"""
    mostly = c.stats["boards_mostly_outliers"]
    first = ("most corners of " + mostly_line(mostly)) if mostly else f"{c.stats['outliers']} corner(s) as outliers"
    seeded = os.path.join(os.path.dirname(os.path.dirname(c.path)), os.path.basename(os.path.dirname(c.path))
                          + "-seeded")
    argv2 = reseeded_argv(argv, c.path, seeded)
    log(f"mrcal rejected {first}: solving again seeded from that model")
    log("$ " + command_line(argv2))
    stale = os.path.join(seeded, "camera-0.cameramodel")
    if os.path.exists(stale):
        os.remove(stale)
    try:
        model = run_calibration(argv2, in_process=in_process)
    except CalibrationError as e:
        c.note = f"mrcal rejected {first}; the seeded solve failed: {str(e).splitlines()[0]}"
        return
    s2 = model_stats(model, cs)
    if s2["outliers"] < c.stats["outliers"]:
        c.note = (f"solved again seeded from its first solve, in which mrcal rejected {first} "
                  f"({c.stats['outliers']} outliers then, {s2['outliers']} now)")
        c.path, c.command, c.stats = stale, command_line(argv2), s2
    else:
        c.note = f"mrcal rejected {first}, also when seeded from its first solve"


def _drop(cs, bad: dict, dropped: dict, log):
    """cs without the boards (files) in bad; each named in log and added to dropped (file -> why)"""
    for fn, why in bad.items():
        log(f"dropping {fn}: {why}")
        dropped[fn] = why
    keep = [i for i, fn in enumerate(cs.files) if fn not in bad]
    return dataclasses.replace(cs, files=[cs.files[i] for i in keep], corners=cs.corners[keep])


def _fit(cs, outdir, plan, f, vnl, why, in_process, log):
    """The candidates of plan fitted and the one to write chosen: (chosen, reason, failures, cands, comparison)"""
    cands = []
    for name, lm in plan:
        argv = calibration_argv(cs, os.path.join(outdir, "candidates", name), lm, f, vnl)
        c = Candidate(name, lm, command_line(argv), os.path.join(outdir, "candidates", name, "camera-0.cameramodel"))
        log("$ " + c.command)
        try:
            if os.path.exists(c.path):
                os.remove(c.path)
            model = run_calibration(argv, in_process=in_process)
            c.stats = model_stats(model, cs)
            if c.stats["outliers"]:
                _reseed(c, argv, cs, in_process, log)
        except CalibrationError as e:
            if not cands:
                raise
            c.error = str(e).splitlines()[0]
        cands.append(c)
    chosen, comparison = cands[0], None
    if plan[0][0] != "lean":
        reason = f"{chosen.lensmodel} (as asked)"
    elif len(cands) == 1:
        reason = f"{chosen.lensmodel} (the lean model" + (f"; {why}" if why else "") + ")"
    else:
        reason = f"{chosen.lensmodel} (the lean model; the splined fit failed: {cands[1].error})"
    failures = list(model_failures(chosen.stats))
    if len(cands) == 2 and cands[1].stats:
        lean, spl = cands
        ml, ms = mrcal.cameramodel(lean.path), mrcal.cameramodel(spl.path)
        comparison = cross_validate(ml, ms).summary()
        ratio, better = comparison["ratio_median"], spl.stats["rms_px"] < SPLINED_BETTER_RMS * lean.stats["rms_px"]
        spl_fail = model_failures(spl.stats)
        if better and ratio > 2 and not spl_fail:
            chosen, failures = spl, []
            reason = (f"{spl.lensmodel}: it fits the corners better than {lean.lensmodel} (RMS "
                      f"{spl.stats['rms_px']:.5f} vs {lean.stats['rms_px']:.5f} px) and the two differ by "
                      f"{comparison['diff_median_px']:.4f} px, {ratio:.1f}x their uncertainty: the lean model "
                      "does not fit this lens")
        elif better and ratio > 2:
            failures = [f"{lean.lensmodel} does not fit (the splined model fits better and differs by "
                        f"{comparison['diff_median_px']:.4f} px, {ratio:.1f}x the uncertainty) and the splined "
                        "model fails its checks: " + "; ".join(spl_fail)]
        elif ratio > 2 and spl.stats["rms_px"] <= lean.stats["rms_px"]:
            failures.append(f"the lean and splined models disagree by {comparison['diff_median_px']:.4f} px "
                            f"({ratio:.1f}x their uncertainty) and fit equally well: the boards cannot tell "
                            "which is right")
        elif ratio <= 2:
            reason = (f"{lean.lensmodel}: the splined model agrees with it within {ratio:.1f}x their uncertainty "
                      f"(RMS {spl.stats['rms_px']:.5f} vs {lean.stats['rms_px']:.5f} px): the lean model is enough")
        else:
            reason = (f"{lean.lensmodel}: the splined model fits the corners worse (RMS "
                      f"{spl.stats['rms_px']:.5f} vs {lean.stats['rms_px']:.5f} px); its "
                      f"{comparison['diff_median_px']:.4f} px difference is freedom the boards do not constrain")
    return chosen, reason, failures, cands, comparison


def _culprits(cs, chosen, f, outdir, dropped, log) -> dict:
    """{file: why} of the boards that explain an implausible fit, or {} when none does

    Boards far off the rest (far_boards) when the fit is otherwise
    plausible; else the first board whose leaving out gives a plausible lean
    fit, searched by solving without each, the worst-fitting first (up to
    MAX_DROP_SEARCH boards).
    """
    s = chosen.stats
    byname = dict(zip(cs.names, cs.files))
    far = far_boards(s["board_rms_px"])
    if far and len(fit_failures(s, f)) == 1:
        med = float(np.median(list(s["board_rms_px"].values())))
        return {byname[k]: f"its fit RMS {v:.3g} px is {v / med:.0f}x the median board's ({med:.3g} px)"
                for k, v in far.items() if k in byname}
    if len(cs.files) > MAX_DROP_SEARCH:
        return {}
    log(f"the fit is implausible ({'; '.join(fit_failures(s, f))}): solving without each board in turn")
    best = None
    rms = s["board_rms_px"]
    for fn in sorted(cs.files, key=lambda fn: -rms.get(pose_name(fn), 0.0)):  # the worst boards first
        folder = os.path.join(outdir, "candidates", "without")
        sub = dataclasses.replace(cs, files=[x for x in cs.files if x != fn],
                                  corners=cs.corners[[x != fn for x in cs.files]])
        argv = calibration_argv(sub, folder, LEAN_LENSMODEL, f,
                                mrcal_corners(cs.vnl, folder, drop={fn} | set(dropped)))
        with contextlib.suppress(FileNotFoundError):
            os.remove(os.path.join(folder, "camera-0.cameramodel"))
        try:
            st = model_stats(run_calibration(argv, in_process=True), sub)
        except CalibrationError:
            continue
        if not fit_failures(st, f):
            best = (fn, st["rms_px"])
            break
    if best is None:
        return {}
    why = fit_failures(s, f)
    return {best[0]: (f"the fit without it is plausible (RMS {best[1]:.3g} px), with it not: {why[0]}"
                      + (f" (and {len(why) - 1} more)" if len(why) > 1 else ""))}

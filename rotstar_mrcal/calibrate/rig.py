"""Several cameras calibrated at once: mrcal-calibrate-cameras with one glob per camera, and what it says per camera

SYNOPSIS

    >>> from rotstar_mrcal.pattern.layout import make_layout
    >>> argv = rig_argv("corners.vnl", make_layout(), {0: (1280, 800), 1: (1280, 800), 2: (1280, 720)},
    ...                 {0: 640, 1: 641, 2: 918}, "LENSMODEL_OPENCV8", "cal",
    ...                 ["seq/*/camera-0/rotstar_00.png", "seq/*/camera-1/rotstar_00.png", "seq/*/camera-2/rotstar_00.png"])
    >>> print(command_line(argv))
    mrcal-calibrate-cameras --corners-cache corners.vnl --lensmodel LENSMODEL_OPENCV8 --focal 640,641,918 --object-spacing 0.0144318182 --object-width-n 14 --object-height-n 9 --valid-intrinsics-region-parameters 5 0.05 2 3 0 --outdir cal 'seq/*/camera-0/rotstar_00.png' 'seq/*/camera-1/rotstar_00.png' 'seq/*/camera-2/rotstar_00.png'

    # the whole calibration, as rotstar-calibrate runs it on a multi-camera dataset:
    rs = load_rig_corners("cal/corners.vnl", "seq")
    c = calibrate_rig(rs, "cal")       # writes cal/camera-0.cameramodel, cal/camera-1.cameramodel, ...
    print("\\n".join(c.summary_lines()))

The command. mrcal-calibrate-cameras takes one image glob per camera (the
glob's position is the camera's index; `seq/*/camera-K/rotstar_00.png`)
and tells the instants apart by the number in the middle of the file names
(poseNNN; dataset.read_rig); every camera needs >= 2 boards for that (and
MIN_BOARDS for a calibration: check_rig). --focal takes one value per
camera, comma-separated. --imagersize applies to every camera: it is given
when all cameras have the same size; otherwise it is left out and mrcal
reads each camera's size from its first image, which must then be readable
from where the command runs (as the vnl names them, or next to the vnl).
mrcal writes camera-K.cameramodel for camera K, each with its extrinsics
(rt_cam_ref; camera 0 at the origin) and the whole problem's
optimization_inputs.

The lens model: the lean LENSMODEL_OPENCV8 for every camera (rotstar-calibrate's
lean/splined choice is the one-camera path's), or the one given.

Per camera (camera_stats): boards and corners used, mrcal's outliers (corners
the vnl had that the solve dropped) and the boards it rejected mostly (a
board labelled differently in this camera than in the others fits no common
board pose: its corners are rejected; detect.rig's labelling check should
have dropped it already), the 2-D fit RMS and worst residual, and where the
camera is relative to camera 0 (centre, mm; rotation, degrees). A camera
with more than calibrate.MAX_OUTLIER_FRACTION of its corners rejected, or a
board mostly rejected, fails the checks (no models written unless keep).
"""

from __future__ import annotations

import dataclasses
import math
import os
import shutil

import cv2
import mrcal
import numpy as np

from rotstar_mrcal import dataset
from rotstar_mrcal.atomic import atomic_path
from rotstar_mrcal.calibrate.focal import focal_estimates
from rotstar_mrcal.calibrate.glass import correct_glass, glass_line
from rotstar_mrcal.optics.refraction import DEFAULT_INDEX
from rotstar_mrcal.vnl import CornersFileError, mrcal_keeps, open_corners, read_corners
from rotstar_mrcal.calibrate.checks import (
    MAX_DROP_SEARCH, MAX_OUTLIER_FRACTION, MIN_BOARDS, MOSTLY_OUTLIERS, far_boards, fit_failures, misordered_boards,
)
from rotstar_mrcal.calibrate.command import (
    InputError, command_line, mrcal_corners, resolve_lensmodel, rig_argv, rig_globs,
)
from rotstar_mrcal.calibrate.cornerset import vnl_has_weights
from rotstar_mrcal.calibrate.solve import CalibrationError, run_calibration


def camera_of(path: str) -> int | None:
    """The camera index K of a file name .../camera-K/<file>, else None

    >>> camera_of("seq/pose003/camera-1/rotstar_00.png"), camera_of("seq/pose003/rotstar_00.png")
    (1, None)
    """
    return dataset.camera_index(os.path.basename(os.path.dirname(str(path))))


@dataclasses.dataclass
class RigCornerSet:
    """The boards of a multi-camera corners.vnl, split by camera"""

    vnl: str
    seq: str
    layout: object
    files: dict[int, list[str]]  # camera -> its boards' file names (boards mrcal keeps)
    corners: dict[int, np.ndarray]  # camera -> (N, ny, nx, 2)
    imagersizes: dict[int, tuple[int, int]]
    weights: bool

    @property
    def cameras(self) -> list[int]:
        return sorted(self.imagersizes)

    def focal(self, k: int) -> float:
        """Camera k's focal seed: the median of its boards' estimates (focal.focal_estimates)"""
        est = focal_estimates(list(self.corners[k]), self.layout.board_points()[..., :2], self.imagersizes[k])
        return float(np.median(est)) if len(est) else self.imagersizes[k][0] / 2


def load_rig_corners(vnl: str, seq: str, imagersize=None) -> RigCornerSet:
    """Read a corners.vnl of the multi-camera dataset seq; InputError when it holds no board of some camera

    imagersize (W, H), given, is every camera's: an InputError when the
    images of some camera are of another size.
    """
    pattern, layout = dataset.read_pattern(seq)
    rig = dataset.read_rig(seq, pattern["frames"])
    try:
        with open_corners(vnl) as f:
            boards = read_corners(f, layout.nx, layout.ny)
    except CornersFileError as e:
        raise InputError(str(e)) from None
    except ValueError as e:
        raise InputError(f"{vnl}: {e} (pattern: {seq}/pattern.json)") from None
    files = {k: [] for k in rig.cameras}
    for fn, grid in boards.items():
        k = camera_of(fn)
        if k in files and mrcal_keeps(grid):
            files[k].append(fn)
    corners = {k: (np.stack([boards[f] for f in fs]) if fs else np.zeros((0, layout.ny, layout.nx, 2)))
               for k, fs in files.items()}
    if imagersize:
        other = {k: v for k, v in rig.sizes.items() if v is not None and tuple(v) != tuple(imagersize)}
        if other:
            k, (W, H) = next(iter(other.items()))
            raise InputError(f"the imager size given, {imagersize[0]}x{imagersize[1]}, is not the size "
                             f"of {seq}'s camera-{k} images ({W}x{H}): give --imagersize {W} {H} or none")
    sizes = {k: (tuple(imagersize) if imagersize else rig.sizes[k]) for k in rig.cameras}
    return RigCornerSet(vnl, seq, layout, files, corners, sizes, vnl_has_weights(vnl))


def first_argv(rs: RigCornerSet, outdir: str, spec: str = "auto", focal: float | None = None) -> list[str]:
    """The first mrcal-calibrate-cameras command calibrate_rig would run (rotstar-calibrate --dry-run)"""
    check_rig(rs)
    focals = {k: focal or rs.focal(k) for k in rs.cameras}
    lm = resolve_lensmodel(spec, rs.imagersizes[0], focals[0])
    first = os.path.basename(rs.files[0][0])
    return rig_argv(rs.vnl, rs.layout, rs.imagersizes, focals, lm, os.path.join(outdir, "candidates", "rig"),
                    rig_globs(rs.seq, rs.cameras, first), rs.weights)


def check_rig(rs: RigCornerSet) -> None:
    """InputError (one line) unless every camera has >= MIN_BOARDS boards and a known image size"""
    for k in rs.cameras:
        n = len(rs.files[k])
        if n < MIN_BOARDS:
            raise InputError(f"{dataset.camera_folder(k)}: {n} board{'s' * (n != 1)} in {rs.vnl}; a calibration "
                             f"needs at least {MIN_BOARDS} per camera (mrcal itself 2, to match the instants)")
        if rs.imagersizes[k] is None:
            raise InputError(f"{dataset.camera_folder(k)}: no readable image gives the camera's size")


def rig_residuals(oi: dict) -> tuple[np.ndarray, np.ndarray]:
    """(N, ny, nx) 2-D reprojection errors (NaN: missing or outlier) and (N,) camera of each observation"""
    obs = oi["observations_board"]
    N, ny, nx = obs.shape[:3]
    idx = oi["indices_frame_camintrinsics_camextrinsics"]
    obj = mrcal.ref_calibration_object(nx, ny, oi["calibration_object_spacing"], calobject_warp=oi.get("calobject_warp"))
    p = mrcal.transform_point_rt(oi["rt_ref_frame"][idx[:, 0]][:, None, None, :], obj)
    ext = idx[:, 2]
    if len(oi["rt_cam_ref"]):
        p = np.where((ext >= 0)[:, None, None, None],
                     mrcal.transform_point_rt(oi["rt_cam_ref"][np.maximum(ext, 0)][:, None, None, :], p), p)
    q = np.stack([mrcal.project(p[b], oi["lensmodel"], oi["intrinsics"][idx[b, 1]]) for b in range(N)]) if N else p[..., :2]
    e = np.linalg.norm(q - obs[..., :2], axis=-1)
    return np.where(obs[..., 2] > 0, e, np.nan), idx[:, 1]


def relative_pose(model: mrcal.cameramodel) -> dict:
    """Where a camera is relative to camera 0: its centre (mm) and rotation (degrees)"""
    rt = model.extrinsics_rt_fromref()
    c = -mrcal.R_from_r(rt[:3]).T @ rt[3:]
    return {"centre_mm": [float(v) * 1000 for v in c], "distance_mm": float(np.linalg.norm(c) * 1000),
            "rotation_deg": float(math.degrees(np.linalg.norm(rt[:3])))}


def camera_stats(oi: dict, rs: RigCornerSet) -> dict[int, dict]:
    """Per camera: boards, corners, outliers, boards mostly rejected, fit RMS and worst residual (module doc)"""
    e, cam = rig_residuals(oi)
    obs = oi["observations_board"]
    paths = [os.path.normpath(str(p)) for p in (oi.get("imagepaths") if oi.get("imagepaths") is not None else [])]
    given_of = {os.path.normpath(f): np.isfinite(c).all(axis=-1)
                for k in rs.cameras for f, c in zip(rs.files[k], rs.corners[k])}
    out = {}
    for k in rs.cameras:
        b = np.flatnonzero(cam == k)
        ek = e[b]
        ok = np.isfinite(ek)
        given = np.stack([given_of.get(paths[i], np.ones(obs.shape[1:3], bool)) if len(paths) == len(obs)
                          else np.ones(obs.shape[1:3], bool) for i in b]) if len(b) else np.zeros((0,) + obs.shape[1:3], bool)
        outlier = given & ~(obs[b][..., 2] > 0)
        lost, had = outlier.sum(axis=(1, 2)), given.sum(axis=(1, 2))
        name = [dataset.camera_folder(k) + ":" + (paths[i].split(os.sep)[-3] if len(paths) == len(obs) else str(i))
                for i in b]
        out[k] = {
            "boards": int(len(b)),
            "corners": int(ok.sum()),
            "outliers": int(outlier.sum()),
            "outlier_fraction": float(outlier.sum() / max(1, given.sum())),
            "boards_mostly_outliers": {name[j]: [int(lost[j]), int(had[j])]
                                       for j in np.flatnonzero(lost > MOSTLY_OUTLIERS * had)},
            "rms_px": float(np.sqrt(np.mean(ek[ok] ** 2))) if ok.any() else float("nan"),
            "worst_px": float(np.max(ek[ok])) if ok.any() else float("nan"),
            "board_rms_px": {name[j]: float(np.sqrt(np.mean(ek[j][ok[j]] ** 2))) for j in range(len(b)) if ok[j].any()},
        }
    return out


@dataclasses.dataclass
class RigCalibration:
    """The result of calibrate_rig: the models written (or not), per camera what the solve says, and why"""

    models: dict[int, str]  # camera -> outdir/camera-K.cameramodel when written
    lensmodel: str
    command: str
    stats: dict[int, dict]  # camera_stats, plus 'lensmodel', 'focal_px', 'centre_px' and relative_pose
    failures: list[str]
    kept: bool
    corners: str
    dropped: dict = dataclasses.field(default_factory=dict)  # pose -> why it was left out
    glass: dict | None = None  # calibrate.glass.GlassResult.to_json()

    FORMAT = "rotstar-calibrate-rig/1"

    @property
    def ok(self) -> bool:
        return not self.failures

    @property
    def paths(self) -> list[str]:
        """The models written, camera 0 first"""
        return [self.models[k] for k in sorted(self.models)]

    def to_json(self) -> dict:
        return {"format": self.FORMAT, "ok": self.ok, "models": {f"camera-{k}": v for k, v in self.models.items()},
                "lensmodel": self.lensmodel, "command": self.command, "failures": self.failures, "kept": self.kept,
                "corners": self.corners, "cameras": {f"camera-{k}": v for k, v in self.stats.items()},
                "dropped": self.dropped, "glass": self.glass}

    def summary_lines(self) -> list[str]:
        out = [f"dropped {k}: {v}" for k, v in self.dropped.items()]
        for k, s in self.stats.items():
            rel = s["relative"]
            where = ("the reference (origin)" if k == 0 else
                     "centre at ({:.1f}, {:.1f}, {:.1f}) mm from camera-0 ({:.2f} mm away), turned {:.3f} deg".format(
                         *rel["centre_mm"], rel["distance_mm"], rel["rotation_deg"]))
            out.append(f"camera-{k}: {s['boards']} boards, {s['corners']} corners, {s['outliers']} outliers; fit RMS "
                       f"{s['rms_px']:.5f} px (2-D), worst {s['worst_px']:.4f} px; fx {s['focal_px'][0]:.2f} "
                       f"fy {s['focal_px'][1]:.2f}; {where}")
        if self.glass:
            out.append(glass_line(self.glass))
        return out


def rig_failures(stats: dict[int, dict]) -> list[str]:
    out = []
    for k, s in stats.items():
        if s["outlier_fraction"] > MAX_OUTLIER_FRACTION:
            out.append(f"camera-{k}: mrcal rejected {s['outliers']} of its corners as outliers "
                       f"({100 * s['outlier_fraction']:.1f}% > {100 * MAX_OUTLIER_FRACTION:.0f}%)")
        if s["boards_mostly_outliers"]:
            out.append(f"camera-{k}: mrcal rejected most corners of " + ", ".join(
                f"{n} ({a} of {b})" for n, (a, b) in s["boards_mostly_outliers"].items())
                + " (a board labelled differently than in the other cameras, or a pose barely constrained)")
    return out


def pose_of(path: str) -> str:
    """The pose folder of a rig file name

    >>> pose_of("seq/pose003/camera-1/rotstar_00.png")
    'pose003'
    """
    return os.path.basename(os.path.dirname(os.path.dirname(os.path.normpath(str(path)))))


def without(rs: RigCornerSet, files) -> RigCornerSet:
    """rs without the boards of these file names"""
    files = set(files)
    keep = {k: [i for i, f in enumerate(fs) if f not in files] for k, fs in rs.files.items()}
    return dataclasses.replace(rs, files={k: [rs.files[k][i] for i in keep[k]] for k in rs.files},
                               corners={k: rs.corners[k][keep[k]] for k in rs.corners})


def calibrate_rig(rs: RigCornerSet, outdir: str, spec: str = "auto", focal: float | None = None, keep: bool = False,
                  in_process: bool = False, log=None, glass_mm: float | None = None,
                  glass_index: float = DEFAULT_INDEX) -> RigCalibration:
    """Calibrate every camera of a rig at once; write outdir/camera-K.cameramodel if the checks pass (or keep)

    Raises InputError before mrcal runs (check_rig), CalibrationError when
    mrcal fails. The solve's own models stay in outdir/candidates/rig/.
    Boards out of grid order are left out before mrcal runs; when the fit is
    implausible (calibrate.fit_failures, per camera) the pose that explains
    it (boards far off the rest, or the one pose without which the fit is
    plausible) is left out and the rig solved again; each is named in log
    and RigCalibration.dropped. A fit that stays implausible is not written,
    even with keep. The screen's cover glass: as solve.calibrate (glass_mm
    None: estimated; 0: no correction), one thickness for the whole rig.
    """
    log = log or (lambda s: None)
    if spec.strip().lower() == "splined":
        raise InputError("--lensmodel splined is for one camera; give a LENSMODEL_... string for a rig")
    check_rig(rs)
    bad = {f: why for k in rs.cameras for f, why in misordered_boards(rs.corners[k], rs.files[k], rs.layout).items()}
    nboards = sum(len(fs) for fs in rs.files.values())
    if bad and 2 * len(bad) > nboards:
        f0, why = next(iter(bad.items()))
        raise InputError(f"{rs.vnl}: {len(bad)} of its {nboards} boards are not the pattern's grid, e.g. {f0}: {why}")
    dropped = {}
    for f, why in bad.items():
        log(f"dropping {f}: {why}")
        dropped[f] = why
    rs = without(rs, bad)
    check_rig(rs)
    focals = {k: (float(focal) if focal else rs.focal(k)) for k in rs.cameras}
    lensmodel = resolve_lensmodel(spec, rs.imagersizes[0], focals[0])
    finals = {k: os.path.join(outdir, f"camera-{k}.cameramodel") for k in rs.cameras}
    for fn in finals.values():
        if os.path.exists(fn):
            os.remove(fn)
    work = os.path.join(outdir, "candidates", "rig")
    while True:
        vnl = mrcal_corners(rs.vnl, os.path.join(outdir, "candidates"), drop=set(dropped))
        if vnl != rs.vnl and not dropped:
            log(f"{rs.vnl} is not plain ASCII text with LF line ends: mrcal reads the text we read, copied to {vnl}")
        cmd, stats = _solve_rig(rs, vnl, work, focals, lensmodel, in_process, log)
        estimates = {k: rs.focal(k) for k in rs.cameras}  # what the boards say, whatever --focal was
        implausible = _implausible(stats, estimates)
        if not implausible:
            break
        culprit = _rig_culprit(rs, stats, focals, estimates, lensmodel, outdir, dropped, implausible, log)
        if not culprit:
            break
        pose, why = culprit
        files = [f for fs in rs.files.values() for f in fs if pose_of(f) == pose]
        log(f"dropping {pose} ({', '.join(files)}): {why}")
        dropped.update({f: why for f in files})
        rs = without(rs, files)
    failures = implausible + rig_failures(stats)
    written, glass = {}, None
    if not failures or (keep and not implausible):
        sources, glass = _rig_glass(work, outdir, rs.cameras, glass_mm, glass_index, log)
        for k in rs.cameras:
            with atomic_path(finals[k]) as tmp:
                shutil.copyfile(sources[k], tmp)
            written[k] = finals[k]
    return RigCalibration(written, lensmodel, cmd, stats, failures, bool(failures) and bool(written), rs.vnl,
                          {_dropped_name(f): v for f, v in dropped.items()}, glass)


def _rig_glass(work: str, outdir: str, cameras, glass_mm, index: float, log) -> tuple[dict, dict | None]:
    """({camera: model file to write}, the glass's JSON): the solve's models, or them re-solved for a cover glass"""
    solved = {k: os.path.join(work, f"camera-{k}.cameramodel") for k in cameras}
    if glass_mm == 0:
        return solved, None
    log("cover glass: " + ("estimating its thickness from the fit" if glass_mm is None else
                           f"correcting for {glass_mm:g} mm (index {index:g})"))
    models = [mrcal.cameramodel(solved[k]) for k in sorted(cameras)]
    g = correct_glass(models[0], glass_mm, index)
    d = g.to_json()
    if not g.applied:
        return solved, d
    out = {}
    for k, m in zip(sorted(cameras), g.models(models)):
        out[k] = os.path.join(outdir, "candidates", "glass", f"camera-{k}.cameramodel")
        os.makedirs(os.path.dirname(out[k]), exist_ok=True)
        m.write(out[k])
    d["models"] = out
    return out, d


def _dropped_name(f: str) -> str:
    """pose003/camera-1 for seq/pose003/camera-1/rotstar_00.png"""
    return pose_of(f) + "/" + os.path.basename(os.path.dirname(os.path.normpath(f)))


def _implausible(stats: dict, focals: dict) -> list[str]:
    return [f"camera-{k}: {r}" for k in stats for r in fit_failures(stats[k], focals[k])]


def _solve_rig(rs, vnl, work, focals, lensmodel, in_process, log) -> tuple[str, dict]:
    """One mrcal solve of the rig into work: (its command, camera_stats with each camera's intrinsics and pose)"""
    for fn in [os.path.join(work, f"camera-{k}.cameramodel") for k in rs.cameras]:
        if os.path.exists(fn):
            os.remove(fn)
    first = os.path.basename(rs.files[0][0])
    argv = rig_argv(vnl, rs.layout, rs.imagersizes, focals, lensmodel, work,
                    rig_globs(rs.seq, rs.cameras, first), rs.weights)
    cmd = command_line(argv)
    log("$ " + cmd)
    run_calibration(argv, in_process=in_process)  # raises CalibrationError; checks camera-0 was written
    models = {}
    for k in rs.cameras:
        fn = os.path.join(work, f"camera-{k}.cameramodel")
        if not os.path.exists(fn):
            raise CalibrationError(f"mrcal-calibrate-cameras wrote no {fn}")
        models[k] = mrcal.cameramodel(fn)
    stats = camera_stats(models[0].optimization_inputs(), rs)
    for k, m in models.items():
        lens, intr = m.intrinsics()
        stats[k].update(lensmodel=lens, focal_px=[float(v) for v in intr[:2]], centre_px=[float(v) for v in intr[2:4]],
                        relative=relative_pose(m))
    return cmd, stats


def camera_offsets(rs: RigCornerSet, focals: dict) -> dict[str, float]:
    """{pose: how far (m) its cameras' relative position is from the median pose's}, from each board's own pose

    Each board's pose in its camera (cv2.solvePnP with a pinhole of the focal
    seed, no distortion: rough, but alike for every pose) gives where camera
    K is relative to camera 0 at that instant; a pose whose camera folders
    are swapped puts camera K on the other side. Poses seen by camera 0 only
    give 0. The order in which calibrate_rig tries leaving poses out.
    """
    obj = rs.layout.board_points().reshape(-1, 3).astype(np.float64)
    where: dict[str, list] = {}
    for k in rs.cameras:
        W, H = rs.imagersizes[k]
        K = np.array([[focals[k], 0, (W - 1) / 2], [0, focals[k], (H - 1) / 2], [0, 0, 1]], float)
        for f, grid in zip(rs.files[k], rs.corners[k]):
            q = grid.reshape(-1, 2)
            ok = np.isfinite(q).all(axis=1)
            if ok.sum() < 6:
                continue
            good, r, t = cv2.solvePnP(obj[ok], q[ok].astype(np.float64), K, None)
            if good:
                R = cv2.Rodrigues(r)[0]
                where.setdefault(pose_of(f), {})[k] = (R, t.ravel())
    rel = {}
    for pose, cams in where.items():
        if 0 in cams:
            R0, t0 = cams[0]
            # camera k's centre in camera 0's frame: board -> cam0 of (board coordinates of camera k's centre)
            rel[pose] = {k: R0 @ (-R.T @ t) + t0 for k, (R, t) in cams.items() if k != 0}
    out = {}
    for pose in where:
        d = 0.0
        for k, c in rel.get(pose, {}).items():
            med = np.median([v[k] for v in rel.values() if k in v], axis=0)
            d = max(d, float(np.linalg.norm(c - med)))
        out[pose] = d
    return out


def _rig_culprit(rs, stats, focals, estimates, lensmodel, outdir, dropped, implausible, log) -> tuple[str, str] | None:
    """(pose, why) that explains an implausible rig fit, or None (see calibrate_rig)

    Boards far off the rest all of one pose, when nothing else is wrong;
    else the pose whose leaving out gives a plausible fit (the lowest
    worst-camera RMS), searched by solving without each (up to
    calibrate.MAX_DROP_SEARCH poses; every camera keeps MIN_BOARDS boards),
    the poses whose cameras sit farthest from where they sit in the other
    poses (camera_offsets) first; the first that gives a plausible fit.
    """
    far = [k for k in stats for r in fit_failures(stats[k], estimates[k]) if r.startswith("boards far off")]
    if far and len(far) == len(implausible):
        names = {n for k in stats for n in far_boards(stats[k]["board_rms_px"])}
        poses = {n.split(":", 1)[1] for n in names}
        if len(poses) == 1:
            return poses.pop(), "its boards' fit is far off the rest: " + "; ".join(implausible)
    offsets = camera_offsets(rs, focals)
    poses = sorted({pose_of(f) for fs in rs.files.values() for f in fs}, key=lambda p: -offsets.get(p, 0.0))
    if len(poses) > MAX_DROP_SEARCH:
        return None
    log(f"the fit is implausible ({'; '.join(implausible)}): solving without each pose in turn")
    folder = os.path.join(outdir, "candidates", "without")
    best = None
    for pose in poses:
        files = [f for fs in rs.files.values() for f in fs if pose_of(f) == pose]
        sub = without(rs, files)
        if any(len(sub.files[k]) < MIN_BOARDS for k in sub.cameras):
            continue
        vnl = mrcal_corners(rs.vnl, folder, drop=set(dropped) | set(files))
        try:
            _, st = _solve_rig(sub, vnl, os.path.join(folder, "rig"), focals, lensmodel, True, lambda s: None)
        except CalibrationError:
            continue
        if not _implausible(st, estimates):
            best = (pose, max(st[k]["rms_px"] for k in st))
            break
    if best is None:
        return None
    return best[0], (f"the fit without it is plausible (worst camera RMS {best[1]:.3g} px), with it not: "
                     + implausible[0] + (f" (and {len(implausible) - 1} more)" if len(implausible) > 1 else ""))

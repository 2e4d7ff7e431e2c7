"""A simulated rig of several cameras (a D435's two infrared imagers and its colour camera) and its dataset

SYNOPSIS

    >>> import tempfile, numpy as np
    >>> from rotstar_mrcal.pattern.layout import make_layout
    >>> from rotstar_mrcal.simulate.rig import rig_cameras, rig_poses, write_rig_dataset, load_rig_truth
    >>> from rotstar_mrcal.simulate.dataset import Settings
    >>> cams = rig_cameras("d435-small", seed=0)                 # left IR at the origin, right IR 50 mm to the right
    >>> [c.role for c in cams], [tuple(int(v) for v in c.model.imagersize()) for c in cams]
    (['left IR', 'right IR'], [(640, 400), (640, 400)])
    >>> [round(float(v), 6) + 0 for v in baseline(cams[1].model)]   # the right imager's centre in camera 0's frame
    [0.05, 0.0, 0.0]
    >>> layout = make_layout(screen=(800, 600), pitch=100, band=24)
    >>> rt, seen = rig_poses(cams, layout, 2, np.random.default_rng(0))
    >>> rt.shape, seen.shape                                      # rt_ref_board per pose; which camera sees it
    ((2, 6), (2, 2))
    >>> seq = tempfile.mkdtemp()
    >>> truth = write_rig_dataset(seq, layout, cams, rt, seen, Settings(bits=8, supersample=1))
    >>> sorted(load_rig_truth(seq).corners["pose000"]) == [k for k in (0, 1) if seen[0, k]]
    True

The reference frame is camera 0's (mrcal's convention: camera 0 at the
origin); each camera's model carries its extrinsics rt_cam_ref (p_cam =
mrcal.transform_point_rt(rt_cam_ref, p_ref)), and a board pose is
rt_ref_board. On disk (the multi-camera layout of doc/dataset.md):

    seq/pattern.json
    seq/poseNNN/camera-K/<file>.png      camera K's frames of pose NNN, when it sees the board
    seq/truth-camera-K.cameramodel       camera K's true intrinsics and extrinsics
    seq/truth.json                       per pose rt_ref_board and each seeing camera's true corners

truth.json:

    {"format": "rotstar-rig-truth/1",
     "cameras": [{"model": "truth-camera-0.cameramodel", "role": "left IR", "blur_px": 1.0, "bits": 16}, ...],
     "settings": {...},
     "poses": {"pose000": {"rt_ref_board": [6 numbers],
                           "corners": {"camera-0": [[[x, y], ...nx], ...ny], "camera-1": ...}}, ...}}

A pose's corners list only the cameras that have its folder: a camera sees
a board when the whole band lattice is in its image with the margin
(poses.pose_ok), as a one-camera simulation demands of every pose; a
camera that does not see it has no folder for that pose. The board poses
are drawn for each camera in turn (poses.random_poses in that camera: pose
i is a whole board, spread over the imager, for camera i % ncam); every
camera sees the poses it sees (rig_poses).

The D435 (RIGS): camera 0 is the left infrared imager (camera.PRESETS
'd435'), camera 1 the right one, 50 mm along camera 0's x (librealsense
reports depth -> infrared 2 as a translation of -0.050 m: its centre at
x = +0.050), a lens of its own (focal lengths, centre and distortion drawn
about the left one's, seeded) turned by 0.1-0.3 degrees, and a PSF of its
own; with rgb, camera 2 is the colour camera, ~15 mm on the other side of the
left imager (librealsense: depth -> colour translation ~ +0.0146 m, so its
centre at x = -0.015), 1280x720 with fx ~ 918 (69 degrees across), 8-bit,
turned by ~0.3 degrees, recorded as grayscale. 'd435-small' is the same
rig at half the resolution (640x400, colour 640x360) for tests.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time

import mrcal
import numpy as np

from rotstar_mrcal import dataset as ds
from rotstar_mrcal.parallel import process_map
from rotstar_mrcal.pattern.layout import Layout
from rotstar_mrcal.simulate.camera import camera_rays, preset_model
from rotstar_mrcal.simulate.dataset import (
    Settings, _do_pose, _setup, _STATE, read_truth_json, true_corners, write_truth_json,
)
from rotstar_mrcal.optics.psf import LensPSF
from rotstar_mrcal.optics.blur import describe_psf
from rotstar_mrcal.simulate.poses import pose_ok, random_poses
from rotstar_mrcal.simulate.screen import exact_frames

RIG_TRUTH_FORMAT = "rotstar-rig-truth/1"

BASELINE_M = 0.050
"""The D435's infrared baseline: the right imager's centre at +x of the left one's"""

COLOUR_OFFSET_M = -0.015
"""The D435's colour camera: its centre ~15 mm from the left imager, away from the right one"""

RIGS = {
    "d435": dict(scale=1.0, description="Intel RealSense D435: left IR 1280x800 (camera 0), right IR 50 mm to its "
                                        "right (camera 1); --rgb adds the colour camera 1280x720 (camera 2)"),
    "d435-small": dict(scale=0.5, description="the D435 rig at half the resolution (640x400, colour 640x360), "
                                              "for tests"),
}

COLOUR_INTRINSICS = (918.0, 916.0, 631.4, 356.7, 0.03, -0.05, 3e-4, -2e-4, 0.0, 0.0, 0.0, 0.0)
"""D435 colour camera at 1280x720 (typical reported values: fx 918.6, fy 916.0, centre 631.4, 356.7), mild OPENCV8"""


@dataclasses.dataclass
class RigCamera:
    """One camera of a rig: its true model (intrinsics and extrinsics rt_cam_ref) and how it renders"""

    role: str
    model: mrcal.cameramodel
    blur_px: float  # Gaussian PSF sigma, camera pixels
    bits: int | None = None  # PNG bit depth (None: the settings')
    psf_scale: float = 1.0  # its lens's blur and aberrations against the left imager's


def scaled_intrinsics(intrinsics, scale: float) -> np.ndarray:
    """OPENCV intrinsics of the same lens on an imager scaled by `scale` (pixel centres kept)

    >>> scaled_intrinsics((640., 640., 638.5, 401., -0.05), 0.5).tolist()
    [320.0, 320.0, 319.0, 200.25, -0.05]
    """
    v = np.array(intrinsics, float)
    v[:2] *= scale
    v[2:4] = (v[2:4] + 0.5) * scale - 0.5
    return v


def camera_model(lensmodel: str, intrinsics, imagersize, r_cam_ref, centre_ref) -> mrcal.cameramodel:
    """A model whose camera centre is at centre_ref (reference frame) and whose rotation is r_cam_ref"""
    R = mrcal.R_from_r(np.asarray(r_cam_ref, float))
    rt = np.concatenate((r_cam_ref, -R @ np.asarray(centre_ref, float)))
    return mrcal.cameramodel(intrinsics=(lensmodel, np.asarray(intrinsics, float)),
                             imagersize=np.asarray(imagersize), rt_cam_ref=rt)


def baseline(model: mrcal.cameramodel) -> np.ndarray:
    """The camera's centre in the reference frame (camera 0's): -R^T t of rt_cam_ref"""
    rt = model.extrinsics_rt_fromref()
    return -mrcal.R_from_r(rt[:3]).T @ rt[3:]


def small_rotation(rng: np.random.Generator, lo_deg: float, hi_deg: float) -> np.ndarray:
    """A Rodrigues vector of a random axis and an angle uniform in [lo, hi] degrees"""
    axis = rng.normal(size=3)
    return axis / np.linalg.norm(axis) * math.radians(rng.uniform(lo_deg, hi_deg))


def rig_cameras(name: str = "d435", seed: int = 0, rgb: bool = False, blur_px: float = 1.0) -> list[RigCamera]:
    """The cameras of rig `name` (RIGS); the right imager's lens and the rotations are drawn from seed

    blur_px: the left imager's PSF sigma; the right one's is 10% smaller, the
    colour camera's 10% larger (lenses of their own).
    """
    try:
        scale = RIGS[name]["scale"]
    except KeyError:
        raise ValueError(f"unknown rig {name!r}; known: {', '.join(RIGS)}") from None
    rng = np.random.default_rng([3, int(seed)])
    left = preset_model("d435")
    lens, intr = left.intrinsics()
    W, H = (int(round(v * scale)) for v in left.imagersize())
    intr0 = scaled_intrinsics(intr, scale)
    intr1 = intr0.copy()
    intr1[:2] *= 1 + rng.normal(0, 0.004)  # fx = fy (square pixels) within a few pixels of the left one's
    intr1[2:4] += rng.normal(0, 3.0 * scale, 2)  # the centre within a few pixels
    intr1[4:9] += rng.normal(0, 1, 5) * (0.003, 0.003, 2e-4, 2e-4, 0.003)  # k1 k2 p1 p2 k3
    cams = [
        RigCamera("left IR", camera_model(lens, intr0, (W, H), np.zeros(3), np.zeros(3)), blur_px),
        RigCamera("right IR", camera_model(lens, intr1, (W, H), small_rotation(rng, 0.1, 0.3),
                                           (BASELINE_M, 0.0, 0.0)), 0.9 * blur_px, psf_scale=0.9),
    ]
    if rgb:
        intr2 = scaled_intrinsics(COLOUR_INTRINSICS, scale)
        cw, ch = int(round(1280 * scale)), int(round(720 * scale))
        cams.append(RigCamera("colour", camera_model(lens, intr2, (cw, ch), small_rotation(rng, 0.2, 0.4),
                                                     (COLOUR_OFFSET_M, 0.0, 0.0)), 1.1 * blur_px, bits=8,
                              psf_scale=1.1))
    return cams


def scaled_seidel(seidel, scale: float):
    """The Seidel amplitudes (waves) times scale, their directions kept

        >>> from rotstar_mrcal.optics.wavefront import Seidel
        >>> scaled_seidel(Seidel(coma=1.5, focus=0.3), 0.9).coma
        1.35
    """
    amp = ("tilt", "focus", "spherical", "coma", "astigmatism")
    return dataclasses.replace(seidel, **{a: round(getattr(seidel, a) * scale, 12) for a in amp})


def describe_lens(lens) -> str:
    """The truth's words for a camera's LensPSF"""
    s = lens.seidel
    terms = ", ".join(f"{a} {getattr(s, a):g}" for a in ("tilt", "focus", "spherical", "coma", "astigmatism")
                      if getattr(s, a))
    return f"Seidel wavefront PSF, waves at the image corners: {terms} (optics.LensPSF)"


def rig_poses(cameras: list[RigCamera], layout: Layout, n: int, rng=None, *, distance=None,
              max_tilt_deg: float = 60.0, margin_px: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """n board poses rt_ref_board (n, 6), and (n, ncam) bool: which camera sees each

    Pose i is drawn for camera i % ncam (poses.random_poses with that
    camera's model, spread over its imager, at its default distance range
    unless `distance` is given), so every camera sees at least its share of
    whole boards; every camera then sees the poses whose whole band lattice
    is inside its image with the margin (pose_ok; margin_px defaults to 2% of
    each camera's width).
    """
    rng = np.random.default_rng(rng)
    ncam = len(cameras)
    rt = np.empty((n, 6))
    for k, c in enumerate(cameras):
        idx = np.arange(k, n, ncam)
        if len(idx):
            rt_k = random_poses(c.model, layout, len(idx), rng, distance=distance, max_tilt_deg=max_tilt_deg,
                                margin_px=margin_px)
            rt[idx] = mrcal.compose_rt(mrcal.invert_rt(c.model.extrinsics_rt_fromref()), rt_k)
    seen = np.empty((n, ncam), bool)
    for k, c in enumerate(cameras):
        rt_k = mrcal.compose_rt(c.model.extrinsics_rt_fromref(), rt)
        margin = 0.02 * float(c.model.imagersize()[0]) if margin_px is None else margin_px
        seen[:, k] = [pose_ok(c.model, layout, r, margin) for r in rt_k]
    return rt, seen


@dataclasses.dataclass
class RigTruth:
    """The ground truth of a simulated multi-camera dataset"""

    models: list[mrcal.cameramodel]  # camera k's true model, extrinsics rt_cam_ref (camera 0 at the origin)
    layout: Layout
    rt_ref_board: dict[str, np.ndarray]  # pose -> (6,)
    corners: dict[str, dict[int, np.ndarray]]  # pose -> {camera k: (ny, nx, 2)} for the cameras that see it
    settings: dict

    @property
    def poses(self) -> list[str]:
        return sorted(self.rt_ref_board)

    def rt_cam_board(self, k: int, pose: str) -> np.ndarray:
        """The board pose in camera k's frame"""
        return mrcal.compose_rt(self.models[k].extrinsics_rt_fromref(), self.rt_ref_board[pose])


def truth_model_name(k: int) -> str:
    """truth-camera-K.cameramodel"""
    return f"truth-{ds.camera_folder(k)}.cameramodel"


def write_rig_dataset(seq: str, layout: Layout, cameras: list[RigCamera], rt_ref_board, seen,
                      settings: Settings = Settings(), *, frames: np.ndarray | None = None, jobs: int = 1,
                      progress=None, extra: dict | None = None, seidel=None) -> RigTruth:
    """Render every camera's poses (the one-camera renderer, per camera), write the truth; return it

    seen: (n, ncam) bool from rig_poses. Camera k's noise is seeded per
    (settings.seed, k, pose), so the images do not depend on jobs.
    seidel: an optics.Seidel (waves at the image corners, rotstar-simulate
    --seidel) instead of the Gaussian blur: each camera gets that lens over
    its own imager (optics.LensPSF), its amplitudes scaled by its psf_scale.
    """
    rt = np.asarray(rt_ref_board, float).reshape(-1, 6)
    seen = np.asarray(seen, bool)
    names = [f"pose{i:03d}" for i in range(len(rt))]
    frames = exact_frames(layout) if frames is None else np.asarray(frames, np.float32)
    os.makedirs(seq, exist_ok=True)
    ds.write_pattern(seq, layout)
    cam_settings = []
    for k, c in enumerate(cameras):
        bits = c.bits or settings.bits
        vb = settings.value_bits if settings.value_bits is not None and settings.value_bits <= bits else None
        cam_settings.append(dataclasses.replace(settings, blur_px=c.blur_px, bits=bits, value_bits=vb))
        c.model.write(os.path.join(seq, truth_model_name(k)))
    lenses = [None if seidel is None else LensPSF(scaled_seidel(seidel, c.psf_scale), c.model.imagersize())
              for c in cameras]
    truth = RigTruth(
        models=[c.model for c in cameras],
        layout=layout,
        rt_ref_board=dict(zip(names, rt)),
        corners={n: {k: true_corners(c.model, layout, mrcal.compose_rt(c.model.extrinsics_rt_fromref(), r))
                     for k, c in enumerate(cameras) if seen[i, k]}
                 for i, (n, r) in enumerate(zip(names, rt))},
        settings={**dataclasses.asdict(settings), **(extra or {}),
                  "cameras": [{"model": truth_model_name(k), "role": c.role,
                               "psf": describe_psf(s.blur_px) if lens is None else describe_lens(lens),
                               "blur_px": s.blur_px, "bits": s.bits} for k, (c, s, lens) in
                              enumerate(zip(cameras, cam_settings, lenses))]},
    )
    write_rig_truth(seq, truth)
    t0, done, total = time.perf_counter(), 0, int(seen.sum())
    for k, (c, s, lens) in enumerate(zip(cameras, cam_settings, lenses)):
        jobs_k = [(seq, k * 1_000_003 + i, f"{n}/{ds.camera_folder(k)}",
                   mrcal.compose_rt(c.model.extrinsics_rt_fromref(), r))
                  for i, (n, r) in enumerate(zip(names, rt)) if seen[i, k]]
        init = (layout, frames, (c.model.intrinsics(), c.model.imagersize()), camera_rays(c.model), s, lens)
        try:
            for name, dt in process_map(_do_pose, jobs_k, jobs, _setup, init):
                done += 1
                if progress:
                    progress(f"{name} ({done}/{total}) {dt:.1f} s, {time.perf_counter() - t0:.0f} s total")
        finally:
            _STATE.clear()
    return truth


def write_rig_truth(seq: str, truth: RigTruth) -> str:
    """Write seq/truth.json of a rig (the models go to truth-camera-K.cameramodel separately)"""
    d = {
        "format": RIG_TRUTH_FORMAT,
        "cameras": [truth_model_name(k) for k in range(len(truth.models))],
        "coordinates": "the reference frame is camera 0's; rt_ref_board maps board points (origin at corner (0, 0), "
                       "x right, y down, metres) to it: p_ref = mrcal.transform_point_rt(rt_ref_board, p_board); "
                       "camera k's model holds rt_cam_ref; corners[camera-k][j][i] is corner (i, j)'s projection "
                       "in camera k, mrcal image coordinates (top-left pixel centre = (0, 0))",
        "settings": truth.settings,
        "poses": {n: {"rt_ref_board": truth.rt_ref_board[n].tolist(),
                      "corners": {ds.camera_folder(k): c.tolist() for k, c in truth.corners[n].items()}}
                  for n in truth.poses},
    }
    return write_truth_json(seq, d)


def load_rig_truth(seq: str) -> RigTruth:
    """Read seq/truth.json, seq/truth-camera-K.cameramodel and seq/pattern.json of a simulated rig"""
    d = read_truth_json(seq, RIG_TRUTH_FORMAT, "a one-camera dataset's truth?")
    models = []
    for name in d["cameras"]:
        try:
            models.append(mrcal.cameramodel(os.path.join(seq, name)))
        except Exception:  # noqa: BLE001 mrcal raises a bare Exception
            raise ds.DatasetError(f"{os.path.join(seq, name)}: not a readable camera model") from None
    _, layout = ds.read_pattern(seq)
    poses = d["poses"]
    return RigTruth(
        models=models,
        layout=layout,
        rt_ref_board={n: np.array(p["rt_ref_board"], float) for n, p in poses.items()},
        corners={n: {ds.camera_index(k): np.array(c, float) for k, c in p["corners"].items()}
                 for n, p in poses.items()},
        settings=d.get("settings", {}),
    )

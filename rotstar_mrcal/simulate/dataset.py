"""Write a simulated dataset and its ground truth; read the truth back

SYNOPSIS

    >>> import tempfile, numpy as np
    >>> from rotstar_mrcal.pattern.layout import make_layout
    >>> from rotstar_mrcal.simulate.camera import preset_model
    >>> from rotstar_mrcal.simulate.poses import random_poses
    >>> from rotstar_mrcal.simulate.dataset import Settings, write_dataset, load_truth
    >>> layout = make_layout(screen=(800, 600), pitch=100, band=24)
    >>> model = preset_model("pinhole-small")
    >>> rts = random_poses(model, layout, 2, np.random.default_rng(0))
    >>> seq = tempfile.mkdtemp()
    >>> truth = write_dataset(seq, layout, model, rts, Settings(bits=8, seed=1))
    >>> truth.poses, truth.corners["pose000"].shape
    (['pose000', 'pose001'], (4, 6, 2))
    >>> np.array_equal(load_truth(seq).corners["pose001"], truth.corners["pose001"])
    True

On disk (the layout of rotstar_mrcal.dataset, plus the truth):

    seq/pattern.json          write_pattern(seq, layout)
    seq/poseNNN/<file>.png    every entry of layout.frames() (the identity frames
                              too when the layout has them), 8- or 16-bit
    seq/truth.cameramodel     the true camera (mrcal's .write)
    seq/truth.json            per pose: rt_cam_board and the true corners

truth.json:

    {"format": "rotstar-truth/1",
     "camera_model": "truth.cameramodel",
     "settings": {...every simulation setting, the PSF, the seed...},
     "poses": {"pose000": {"rt_cam_board": [6 numbers],
                           "corners": [[[x, y], ...nx], ...ny]}, ...}}

corners[j][i] is the mrcal projection of board point (i, j, 0) * spacing,
mrcal image coordinates (centre of the top-left pixel = (0, 0)). A camera
that moved during the sequence has rt_cam_board of shape (nframes, 6) and
corners of shape (nframes, ny, nx, 2), one per entry of layout.frames().

Noise is seeded per pose from (seed, pose index), so the images do not depend
on how many processes render them.
"""

from __future__ import annotations

import dataclasses
import json
import multiprocessing
import os
import time

import cv2
import mrcal
import numpy as np

from rotstar_mrcal import dataset as ds
from rotstar_mrcal.optics.refraction import DEFAULT_INDEX, Glass
from rotstar_mrcal.parallel import process_map
from rotstar_mrcal.pattern.layout import Layout
from rotstar_mrcal.simulate.camera import RayGrid, camera_rays, remember_rays
from rotstar_mrcal.simulate.exposure import expose
from rotstar_mrcal.optics.blur import describe_psf
from rotstar_mrcal.simulate.display import centred_maps, homogeneous, identity_maps, offset_maps, show_frames
from rotstar_mrcal.simulate.irradiance import render_irradiance
from rotstar_mrcal.simulate.screen import Screen, exact_frames, make_screen

TRUTH_FORMAT = "rotstar-truth/1"


@dataclasses.dataclass(frozen=True)
class Settings:
    """Rendering and exposure settings of a simulated dataset"""

    supersample: int = 4  # s x s sub-pixels per camera pixel
    blur_px: float = 1.0  # Gaussian PSF sigma, camera pixels (0: none); see write_dataset(psf=)
    sampling: str = "area"  # "area" or "point"; see irradiance.py
    room: float = 0.02  # luminance seen off the screen
    gain: float = 0.9  # full-scale fraction per unit irradiance (white screen head-on)
    black: float = 0.0  # black level, fraction of full scale
    noise: float = 0.01  # additive noise sigma, fraction of full scale
    shot: float = 0.0  # signal-dependent noise variance per unit signal
    bits: int = 16  # 8 or 16-bit PNG
    value_bits: int | None = None  # 10 or 12: that many bits scaled into 16
    seed: int = 0
    glass_mm: float = 0.0  # cover glass over the emitting layer, mm (0: none); see irradiance.py
    glass_index: float = DEFAULT_INDEX  # its refractive index

    @property
    def glass(self) -> Glass | None:
        """The cover glass the screen is seen through (None without)"""
        return Glass.mm(self.glass_mm, self.glass_index) if self.glass_mm else None


@dataclasses.dataclass
class Truth:
    """The ground truth of a simulated dataset"""

    model: mrcal.cameramodel
    layout: Layout
    rt_cam_board: dict[str, np.ndarray]  # (6,) or (nframes, 6)
    corners: dict[str, np.ndarray]  # (ny, nx, 2) or (nframes, ny, nx, 2)
    settings: dict

    @property
    def poses(self) -> list[str]:
        return sorted(self.rt_cam_board)


def pose_names(n: int) -> list[str]:
    """['pose000', 'pose001', ...]"""
    return [f"pose{i:03d}" for i in range(n)]


def true_corners(model: mrcal.cameramodel, layout: Layout, rt_cam_board) -> np.ndarray:
    """mrcal.project of the board points: (..., 6) poses -> (..., ny, nx, 2)

    SYNOPSIS

        >>> from rotstar_mrcal.pattern.layout import make_layout
        >>> from rotstar_mrcal.simulate.camera import preset_model
        >>> layout = make_layout(screen=(800, 600), pitch=100, band=24)
        >>> c = true_corners(preset_model("pinhole-small"), layout, np.array((0, 0, 0, 0, 0, 0.2)))
        >>> c.shape, c[0, 0]                    # corner (0, 0) on the optical axis
        ((4, 6, 2), array([319.5, 199.5]))
    """
    rt = np.asarray(rt_cam_board, float)
    p = mrcal.transform_point_rt(rt[..., None, None, :], layout.board_points())
    return mrcal.project(p, *model.intrinsics())


def render_pose(
    screen: Screen,
    model: mrcal.cameramodel,
    rt_cam_board,
    settings: Settings,
    rng,
    psf=None,
    rays: RayGrid | None = None,
) -> np.ndarray:
    """Rendered and exposed images of one pose: (nframes, H, W) uint8 or uint16"""
    E = render_irradiance(
        screen,
        model,
        rt_cam_board,
        supersample=settings.supersample,
        psf=settings.blur_px if psf is None else psf,
        sampling=settings.sampling,
        rays=rays,
        glass=settings.glass,
    )
    return expose(
        E,
        gain=settings.gain,
        black=settings.black,
        noise=settings.noise,
        shot=settings.shot,
        bits=settings.bits,
        value_bits=settings.value_bits,
        rng=rng,
    )


def pose_rng(seed: int, index: int) -> np.random.Generator:
    """The noise generator of pose number `index`"""
    return np.random.default_rng([1, int(seed), int(index)])


# ---- one pose, in this process or a worker --------------------------------
_STATE: dict = {}


def _setup(layout, frames, model_args, grid, settings, psf):
    model = mrcal.cameramodel(intrinsics=model_args[0], imagersize=model_args[1])
    if grid is not None:
        remember_rays(model, grid)
    _STATE.update(
        screen=make_screen(frames, layout, settings.room),
        model=model,
        settings=settings,
        psf=psf,
        frames=layout.frames(),
    )
    if multiprocessing.parent_process() is not None:
        cv2.setNumThreads(1)


def _do_pose(seq: str, index: int, name: str, rt: np.ndarray) -> tuple[str, float]:
    t0 = time.perf_counter()
    st = _STATE
    imgs = render_pose(st["screen"], st["model"], rt, st["settings"], pose_rng(st["settings"].seed, index), st["psf"])
    ds.write_pose(seq, name, {f["file"]: img for f, img in zip(st["frames"], imgs)})
    return name, time.perf_counter() - t0


def write_dataset(
    seq: str,
    layout: Layout,
    model: mrcal.cameramodel,
    rt_cam_board,
    settings: Settings = Settings(),
    *,
    frames: np.ndarray | None = None,
    psf=None,
    jobs: int = 1,
    progress=None,
    extra: dict | None = None,
    display_offsets=None,
    display_maps=None,
) -> Truth:
    """Render, expose and write every pose; write and return the truth

    rt_cam_board: (npose, 6), or a sequence of (6,) / (nframes, 6) arrays
    (nframes = len(layout.frames())). frames: the screen frames, (nframes, Hs,
    Ws) linear luminance (default: exact_frames(layout)). psf overrides
    settings.blur_px (anything render_irradiance takes; must pickle for
    jobs > 1). progress(message) is called once per pose. extra: more entries
    for the truth's settings (e.g. the camera preset name).
    display_offsets: (n, 2) display pixels by which the screen shows each of
    the n rotating-star frames displaced; display_maps: (n, 2, 3) affine
    maps, display px, by which it shows them shifted, scaled or stretched
    (simulate.display; composed after the offsets). Both are the same in
    every pose (a player or screen that is not pixel-exact); the truth is
    the board at the maps' mean (display.centred_maps), the position the
    joint refinement measures.
    """
    rts = [np.asarray(r, float) for r in rt_cam_board]
    nfr = len(layout.frames())
    for r in rts:
        if r.shape not in ((6,), (nfr, 6)):
            raise ValueError(f"a pose must be (6,) or ({nfr}, 6), not {r.shape}")
    names = pose_names(len(rts))
    frames = exact_frames(layout) if frames is None else np.asarray(frames, np.float32)
    if frames.shape[0] != nfr:
        raise ValueError(f"{frames.shape[0]} screen frames for the layout's {nfr}")
    maps = frame_maps(layout, display_offsets, display_maps)
    if maps is not None:
        frames = show_frames(frames, maps)

    os.makedirs(seq, exist_ok=True)
    ds.write_pattern(seq, layout)
    model.write(os.path.join(seq, "truth.cameramodel"))
    truth = Truth(
        model=model,
        layout=layout,
        rt_cam_board=dict(zip(names, rts)),
        corners={n: true_corners(model, layout, r) for n, r in zip(names, rts)},
        settings={
            **dataclasses.asdict(settings),
            "psf": describe_psf(settings.blur_px if psf is None else psf),
            **(extra or {}),
            **({} if display_offsets is None else {"display_offsets": np.asarray(display_offsets, float).tolist()}),
            **({} if display_maps is None else {"display_maps": np.asarray(display_maps, float).tolist()}),
        },
    )
    write_truth(seq, truth)

    grid = camera_rays(model)
    init = (layout, frames, (model.intrinsics(), model.imagersize()), grid, settings, psf)
    t0 = time.perf_counter()
    done = 0

    def report(name, dt):
        nonlocal done
        done += 1
        if progress:
            progress(f"{name} ({done}/{len(names)}) {dt:.1f} s, {time.perf_counter() - t0:.0f} s total")

    try:
        for r in process_map(_do_pose, [(seq, i, n, r) for i, (n, r) in enumerate(zip(names, rts))], jobs,
                             _setup, init):
            report(*r)
    finally:
        _STATE.clear()  # with jobs <= 1 the screen was set up in this process
    return truth


def frame_maps(layout: Layout, display_offsets=None, display_maps=None) -> np.ndarray | None:
    """(nframes, 2, 3) maps by which the screen shows every entry of layout.frames(), or None for none

    The rotating-star frames get the offsets, then the maps, both relative to
    their mean (display.centred_maps); the frames of other kinds (the
    identity frames, the checkerboard) are shown at the mean.

        >>> from rotstar_mrcal.pattern.layout import make_layout
        >>> layout = make_layout(screen=(800, 600), pitch=100, band=24)
        >>> off = np.zeros((8, 2)); off[1] = (2, 0)
        >>> m = frame_maps(layout, off)                # 8 rotating-star, 10 identity frames, checkerboard
        >>> m.shape, m[1, :, 2].tolist(), m[0, :, 2].tolist(), bool(np.all(m[8:] == np.eye(2, 3)))
        ((19, 2, 3), [1.75, 0.0], [-0.25, 0.0], True)
    """
    if display_offsets is None and display_maps is None:
        return None
    kinds = [f["kind"] for f in layout.frames()]
    star = np.array([k == "rotstar" for k in kinds])
    n = int(star.sum())
    rot = identity_maps(n)
    if display_offsets is not None:
        off = np.asarray(display_offsets, float)
        if off.shape != (n, 2):
            raise ValueError(f"display offsets must be ({n}, 2), one per rotating-star frame, not {off.shape}")
        rot = offset_maps(off)
    if display_maps is not None:
        m = np.asarray(display_maps, float)
        if m.shape != (n, 2, 3):
            raise ValueError(f"display maps must be ({n}, 2, 3), one per rotating-star frame, not {m.shape}")
        rot = (homogeneous(m) @ homogeneous(rot))[:, :2]
    out = identity_maps(len(kinds))
    out[star] = centred_maps(rot)
    return out


# ---- truth.json ---------------------------------------------------------------
def truth_to_dict(truth: Truth) -> dict:
    return {
        "format": TRUTH_FORMAT,
        "camera_model": "truth.cameramodel",
        "coordinates": "rt_cam_board maps board points (origin at corner (0, 0), x right, y down, "
        "metres) to the camera: p_cam = mrcal.transform_point_rt(rt, p_board); corners[j][i] "
        "is the projection of corner (i, j) in mrcal image coordinates (top-left pixel centre = (0, 0))",
        "settings": truth.settings,
        "poses": {
            n: {"rt_cam_board": truth.rt_cam_board[n].tolist(), "corners": truth.corners[n].tolist()}
            for n in truth.poses
        },
    }


def write_truth_json(seq: str, d: dict) -> str:
    """Write the dict d as seq/truth.json; its path"""
    fn = os.path.join(seq, "truth.json")
    with open(fn, "w") as f:
        json.dump(d, f, indent=1)
        f.write("\n")
    return fn


def read_truth_json(seq: str, fmt: str, other: str = "") -> dict:
    """seq/truth.json as a dict; DatasetError unless readable and of format fmt (other: what else it may be)"""
    fn = os.path.join(seq, "truth.json")
    try:
        with open(fn) as f:
            d = json.load(f)
    except (OSError, json.JSONDecodeError) as e:
        raise ds.DatasetError(f"{fn}: cannot read the truth ({e})") from None
    if d.get("format") != fmt:
        raise ds.DatasetError(f"{fn}: not a {fmt} file{f' ({other})' if other else ''}")
    return d


def write_truth(seq: str, truth: Truth) -> str:
    """Write seq/truth.json (the model goes to seq/truth.cameramodel separately)"""
    return write_truth_json(seq, truth_to_dict(truth))


def load_truth(seq: str) -> Truth:
    """Read seq/truth.json, seq/truth.cameramodel and seq/pattern.json"""
    d = read_truth_json(seq, TRUTH_FORMAT)
    model = mrcal.cameramodel(os.path.join(seq, d.get("camera_model", "truth.cameramodel")))
    _, layout = ds.read_pattern(seq)
    poses = d["poses"]
    return Truth(
        model=model,
        layout=layout,
        rt_cam_board={n: np.array(p["rt_cam_board"], float) for n, p in poses.items()},
        corners={n: np.array(p["corners"], float) for n, p in poses.items()},
        settings=d.get("settings", {}),
    )

"""The benchmark's scene: camera, layouts, poses, and the rendered images of each pose

SYNOPSIS

    >>> from rotstar_lab.benchmark.scene import make_scene
    >>> sc = make_scene(npose=2, seed=0, bits=16)
    >>> sc.rts.shape, (sc.layout.nx, sc.layout.ny), (sc.square.nx, sc.square.ny)
    ((2, 6), (14, 9), (9, 9))

    poses = render_all(sc, jobs=2)        # [RenderedPose], in pose order

The `d435` camera preset (1280x800, LENSMODEL_OPENCV8), the default screen
layout (make_layout(): 14 x 9 corners), random_poses with its defaults (the
poses from default_rng([0, seed])), a Gaussian PSF of sigma 1 px, 4x4 area
supersampling, read noise 1% of full scale, 16- or 8-bit. Per pose, each
image with its own noise from default_rng([1, seed, i]) (so the images do not
depend on the number of processes):

- the 8 rotating-star frames, one capture each;
- the checkerboard frame, CAPTURES captures averaged (the paper's fairness rule);
- the checkerboard of a square SQUARE_N x SQUARE_N layout for mrgingham, seen
  with the same rotation and its centre where the 14 x 9 board's centre is,
  CAPTURES captures averaged;
- the identity frames of the layout (none for make_layout(identity=False)),
  one capture each, exposed last so that the images above do not depend on
  whether the layout has them.
"""

from __future__ import annotations

import dataclasses
import os
import time

import mrcal
import numpy as np
import cv2

from rotstar_mrcal import simulate
from rotstar_mrcal.parallel import process_map
from rotstar_mrcal.pattern.layout import Layout, make_layout
from rotstar_mrcal.simulate.captures import averaged_captures
from rotstar_mrcal.simulate.poses import board_centre_m, centred_pose, tilt_angle

SQUARE_N = 9  # mrgingham's board: SQUARE_N x SQUARE_N inner corners
CAPTURES = 8  # checkerboard captures averaged (= rotating-star frames)


@dataclasses.dataclass
class Scene:
    model: mrcal.cameramodel
    layout: Layout  # the default rotating-star layout (14x9)
    square: Layout  # the 9x9 variant for mrgingham (its checkerboard only)
    rts: np.ndarray  # (npose, 6) rt_cam_board of the default layout
    rts_square: np.ndarray  # (npose, 6) the same views of the square board
    settings: simulate.Settings

    def layout_for(self, needs: str) -> Layout:
        """The board a method with this `needs` (rotstar_mrcal.peers.registry) looks for"""
        return self.square if needs == "square" else self.layout

    def truth(self, needs: str) -> list[np.ndarray]:
        """Per pose, the true corners (ny, nx, 2) of that board"""
        layout, rts = (self.square, self.rts_square) if needs == "square" else (self.layout, self.rts)
        return [simulate.true_corners(self.model, layout, rt) for rt in rts]

    def tilts_deg(self) -> np.ndarray:
        return np.degrees(tilt_angle(self.rts, self.layout))

    def distances_m(self) -> np.ndarray:
        c = board_centre_m(self.layout)
        return np.linalg.norm([mrcal.transform_point_rt(rt, c) for rt in self.rts], axis=-1)


def make_scene(npose: int, seed: int, bits: int, camera: str = "d435", layout: Layout | None = None,
               square: Layout | None = None) -> Scene:
    """The benchmark's scene (see the module doc); camera, layout and square: smaller ones for tests"""
    model = simulate.preset_model(camera)
    layout = make_layout() if layout is None else layout
    square = make_layout(nx=SQUARE_N, ny=SQUARE_N) if square is None else square
    rts = simulate.random_poses(model, layout, npose, np.random.default_rng([0, seed]))
    settings = simulate.Settings(blur_px=1.0, noise=0.01, bits=bits, seed=seed)
    return Scene(model, layout, square, rts, centred_pose(rts, layout, square), settings)


@dataclasses.dataclass
class RenderedPose:
    index: int
    rotstar: np.ndarray  # (8, H, W) uint8/uint16, one capture per frame
    checker: np.ndarray  # (H, W) float32, mean of CAPTURES captures
    checker_square: np.ndarray  # (H, W) float32, the 9x9 board, mean of CAPTURES captures
    seconds: float
    identity: np.ndarray | None = None  # (nidentity, H, W) uint8/uint16, one capture per frame, or None


_W: dict = {}  # the worker's scene, rays and screens (init_renderer)


def init_renderer(scene: Scene, rays) -> None:
    cv2.setNumThreads(1)
    cb = [f for f in scene.square.frames() if f["kind"] == "checkerboard"]
    room = scene.settings.room
    _W.update(scene=scene, rays=rays,
              screen=simulate.make_screen(simulate.exact_frames(scene.layout), scene.layout, room),
              screen_square=simulate.make_screen(simulate.exact_frames(scene.square, cb), scene.square, room))


def render_pose(i: int) -> RenderedPose:
    """Every image of pose i (after init_renderer); the noise comes from default_rng([1, seed, i])"""
    t0 = time.perf_counter()
    sc, st = _W["scene"], _W["scene"].settings
    rng = np.random.default_rng([1, st.seed, i])

    def expose(E):
        return simulate.expose(E, gain=st.gain, black=st.black, noise=st.noise, bits=st.bits, rng=rng)

    kw = dict(supersample=st.supersample, psf=st.blur_px, sampling=st.sampling, rays=_W["rays"])
    E = simulate.render_irradiance(_W["screen"], sc.model, sc.rts[i], **kw)  # rotstar, identity, checkerboard
    Es = simulate.render_irradiance(_W["screen_square"], sc.model, sc.rts_square[i], **kw)
    n = sc.layout.nframes
    rot = expose(E[:n])
    checker, square = averaged_captures(E[-1], expose, CAPTURES), averaged_captures(Es[0], expose, CAPTURES)
    identity = expose(E[n:-1]) if len(E) > n + 1 else None  # last: the images above as without identity frames
    return RenderedPose(i, rot, checker, square, time.perf_counter() - t0, identity)


def render_all(scene: Scene, jobs: int, log=None) -> list[RenderedPose]:
    """Every pose's images, in `jobs` processes; log(message) per pose"""
    n = len(scene.rts)
    t0 = time.perf_counter()
    if log:
        log(f"rendering {n} poses ({jobs} process(es)): ray grid ...")
    rays = simulate.camera_rays(scene.model)
    out: list[RenderedPose | None] = [None] * n
    try:
        for done, p in enumerate(process_map(render_pose, [(i,) for i in range(n)], jobs, init_renderer,
                                             (scene, rays)), 1):
            out[p.index] = p
            if log:
                log(f"  pose {p.index:3d} rendered in {p.seconds:.1f} s ({done}/{n}, "
                    f"{time.perf_counter() - t0:.0f} s)")
    finally:
        _W.clear()  # with jobs <= 1 the screens were set up in this process
    return out


def write_square_png(folder: str, p: RenderedPose, full_scale: float) -> str:
    """The averaged square checkerboard as an 8-bit PNG (mrgingham works on 8 bits); its path"""
    fn = os.path.join(folder, f"square{p.index:03d}.png")
    cv2.imwrite(fn, np.clip(np.round(p.checker_square * (255.0 / full_scale)), 0, 255).astype(np.uint8))
    return fn

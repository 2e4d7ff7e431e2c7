"""One pose of the demo: rendered once, then per exposure its noise, every method's corners and the square board

SYNOPSIS

    results = capture_all(jobs, layout, square, model, rts, rts_square, seed, out, keep_images, methods, log)
    results[("A", 0)].found["4000 us"]["saddle"]     # (corners or None, weights or None, why, None)
    results[("A", 0)].found["4000 us"]["rotstar-psf-sim"][3]   # its PoseCorners (registry.pooled pools a group)
    results[("A", 0)].found["4000 us"]["charuco"]    # OpenCV's ChArUco detector (charuco=True)
    results[("A", 0)].rejected["4000 us"]["phase"]   # (ny, nx) why each phase corner is missing ('' = found)
    results[("B", 0)].crops                          # close-ups of one corner, per exposure

Per exposure k of pose i of group g, the noise comes from
default_rng([seed, ord(g), i, k]): one capture of each rotating-star frame,
then CAPTURES captures of the checkerboard frame and of the square board
averaged over the screen's part of the image (simulate.captures), then one
capture of each identity frame, then (charuco=True) CAPTURES captures of the
ChArUco board of pattern.charuco averaged (the images before it are those of
a run without it), then, when the pattern is the paper's sequence
(rotstar-pattern --paper-sequence), one capture of each phase-shift frame
(as the rotating star) and CAPTURES captures of the star frame averaged (as
the checkerboard: the paper's same-photons rule). The screen shows frames
encoded for a display gamma of PATTERN_GAMMA with its own SCREEN_GAMMA
(simulate.screen.shown_light: 8 bits, a mismatch that bends the phase
shifts' sinusoids and leaves the binary frames alone), its pixels under the
cover glass of scene.screen_glass (every board: the pattern's, the square one). The square board goes to
<exposure>/<g>-square/poseNNN/checkerboard.png as 8 bits, for mrgingham;
with keep_images every frame of the sequence is written as a rotstar dataset.
"""

from __future__ import annotations

import dataclasses
import os
import time

import numpy as np
import mrcal
import cv2

from rotstar_mrcal.parallel import process_map
from rotstar_lab.demo.scene import (
    CAPTURES, EXPOSURES, NOISE, PATTERN_GAMMA, SCREEN_GAMMA, SHOT, coma_psf, exposure_dir, screen_glass,
)
from rotstar_mrcal.peers.cornersets import detect_methods
from rotstar_mrcal.simulate.captures import averaged_captures, lit_box
from rotstar_mrcal.peers.charuco import detect_charuco, render_charuco
from rotstar_mrcal import dataset, simulate
from rotstar_mrcal.simulate.screen import shown_light


@dataclasses.dataclass
class Job:
    group: str
    index: int
    rt: np.ndarray
    rt_square: np.ndarray
    seed: int
    out: str
    keep_images: bool
    methods: tuple  # rotstar_mrcal.peers.registry names that run on the frames of one pose
    charuco: bool = False  # also OpenCV's ChArUco detector on a ChArUco board at the same pose


@dataclasses.dataclass
class PoseResult:
    group: str
    index: int
    found: dict  # exposure label -> method -> (corners or None, weights or None, why)
    crops: dict  # exposure label -> (rotating-star crop, checkerboard crop), pose 0 only
    seconds: float
    rejected: dict = dataclasses.field(default_factory=dict)  # label -> method -> (ny, nx) reasons, '' = found


_W: dict = {}  # the worker's layouts, model, rays, PSF and screens (init_worker)


def init_worker(layout, square, model_args, rays, charuco: bool = False) -> None:
    cv2.setNumThreads(1)
    model = mrcal.cameramodel(intrinsics=model_args[0], imagersize=model_args[1])
    simulate.camera.remember_rays(model, rays)
    cb = [f for f in square.frames() if f["kind"] == "checkerboard"]
    frames = simulate.exact_frames(layout)  # layout.frames(): rotating-star, identity, (phase), checkerboard, (star)
    if charuco:
        frames = np.concatenate((frames, render_charuco(layout)[None].astype(np.float32)))
    _W.update(layout=layout, square=square, model=model, rays=rays, psf=coma_psf(model.imagersize()),
              screen=simulate.make_screen(shown_light(frames, PATTERN_GAMMA, SCREEN_GAMMA), layout),
              screen_square=simulate.make_screen(shown_light(simulate.exact_frames(square, cb), PATTERN_GAMMA,
                                                             SCREEN_GAMMA), square))


def capture_pose(job: Job) -> PoseResult:
    """Render one pose once; per exposure: expose, detect every method, write the square board PNG"""
    t0 = time.perf_counter()
    layout, model = _W["layout"], _W["model"]
    kw = dict(supersample=2, psf=_W["psf"], rays=_W["rays"], glass=screen_glass())  # every board under the glass
    E = simulate.render_irradiance(_W["screen"], model, job.rt, **kw)  # layout.frames() (+ the ChArUco board)
    Ech = E[-1] if job.charuco else None
    E = E[:-1] if job.charuco else E
    kinds = np.array([f["kind"] for f in layout.frames()])
    Es = simulate.render_irradiance(_W["screen_square"], model, job.rt_square, **kw)[0]
    pose = f"pose{job.index:03d}"
    results, crops, rejected = {}, {}, {}
    truth = simulate.true_corners(model, layout, job.rt)
    for k, (label, gain) in enumerate(EXPOSURES):
        rng = np.random.default_rng([job.seed, ord(job.group), job.index, k])

        def expose(img):
            return simulate.expose(img, gain=gain, noise=NOISE, shot=SHOT, bits=16, rng=rng)

        rot = expose(E[kinds == "rotstar"])
        Ec = E[np.flatnonzero(kinds == "checkerboard")[0]]
        cb = averaged_captures(Ec, expose, CAPTURES, roi=lit_box(Ec))
        sq = averaged_captures(Es, expose, CAPTURES, roi=lit_box(Es))
        ident = expose(E[kinds == "identity"]) if layout.identity else None  # (last: the others' noise as before)
        ch = averaged_captures(Ech, expose, CAPTURES, roi=lit_box(Ech)) if job.charuco else None
        # the paper's sequence: one capture of each phase shift (as the rotating star), the star averaged
        phase = expose(E[kinds == "phase"]).reshape(2, -1, *E.shape[1:]) if layout.phase else None
        Est = E[np.flatnonzero(kinds == "star")[0]] if layout.star_segments else None
        star = averaged_captures(Est, expose, CAPTURES, roi=lit_box(Est)) if layout.star_segments else None
        found = detect_methods(rot, layout, 65535.0, cb, job.methods, identity=ident, phase=phase, star=star)
        results[label] = {m: (f.corners, f.weights, f.why, f.pose) for m, f in found.items()}
        rejected[label] = {m: f.reasons for m, f in found.items() if f.reasons is not None}
        if job.charuco:
            c = detect_charuco(ch, layout, 65535.0)
            ok = np.isfinite(c).all(axis=-1).any()
            results[label]["charuco"] = (c if ok else None, None, "" if ok else "ChArUco found no corner")
        edir = exposure_dir(job.out, label)
        sqdir = os.path.join(edir, f"{job.group}-square", pose)
        os.makedirs(sqdir, exist_ok=True)
        cv2.imwrite(os.path.join(sqdir, "checkerboard.png"), np.clip(np.round(sq / 257.0), 0, 255).astype(np.uint8))
        if job.keep_images:
            imgs = {"rotstar": iter(rot), "identity": iter(() if ident is None else ident),
                    "checkerboard": iter([np.round(cb).astype(np.uint16)]),
                    "phase": iter(() if phase is None else phase.reshape(-1, *E.shape[1:])),
                    "star": iter(() if star is None else [np.round(star).astype(np.uint16)])}
            dataset.write_pose(os.path.join(edir, job.group), pose,
                               {f["file"]: next(imgs[f["kind"]]) for f in layout.frames()})
        if job.index == 0:  # close-ups for the report: the corner nearest an image corner
            d = np.linalg.norm(truth - (0, 0), axis=-1)
            j, i = np.unravel_index(np.argmin(d), d.shape)
            x, y = np.round(truth[j, i]).astype(int)
            r = 20
            crops[label] = (rot[1, y - r:y + r + 1, x - r:x + r + 1], cb[y - r:y + r + 1, x - r:x + r + 1])
    return PoseResult(job.group, job.index, results, crops, time.perf_counter() - t0, rejected)


def capture_all(jobs: int, layout, square, model, rts: dict, rts_square: dict, seed: int, out: str,
                keep_images: bool, methods, log=None, charuco: bool = False) -> dict:
    """{(group, index): PoseResult} over every pose of every group, in `jobs` processes

    charuco: also OpenCV's ChArUco detector, found[label]["charuco"].
    """
    todo = [Job(g, i, rts[g][i], rts_square[g][i], seed, out, keep_images, tuple(methods), charuco)
            for g in rts for i in range(len(rts[g]))]
    init = (layout, square, (model.intrinsics(), model.imagersize()), simulate.camera_rays(model), charuco)
    t = time.monotonic()
    out = {}
    try:
        for r in process_map(capture_pose, [(j,) for j in todo], jobs, init_worker, init):
            out[(r.group, r.index)] = r
            if log:
                n_ok = sum(f[0] is not None for e in r.found.values() for f in e.values())
                log(f"  {r.group} pose{r.index:03d}: {n_ok} of {len(r.found) * (len(methods) + charuco)} boards "
                    f"({r.seconds:.1f} s; {len(out)}/{len(todo)}, {time.monotonic() - t:.0f} s)")
    finally:
        _W.clear()  # with jobs <= 1 the worker state was set up in this process
    return out

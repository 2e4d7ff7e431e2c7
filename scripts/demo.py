#!/usr/bin/env python3
"""make demo: the paper's real-world experiment on a simulated D435, validated with mrcal

SYNOPSIS

    python scripts/demo.py --out demo-out          # what `make demo` runs (~4 min on 2 cores)
    python scripts/demo.py --out /tmp/d --quick    # fewer poses, for a smoke run

The camera: the `d435` preset (Intel RealSense D435 left IR, 1280x800 Y16,
OPENCV8 lens, fx = 640) with a wavefront PSF from rotstar_mrcal.optics: Seidel
coma growing linearly with the field radius (COMA_WAVES at the image
corners, its centroid put back on the chief ray by an equal and opposite
tilt, so the true model is where the light's centroid lands), plus field
curvature (FOCUS_WAVES x h^2) and diffraction at F/2 with 3 um pixels. The
screen: the default layout (iPad 2360x1640, 14 x 9 corners).

The experiment (paper 4.2): two groups of poses, each the iPad turned about
a fixed axis in 30-degree steps from 0 to 60 degrees (the paper: 10-degree
steps) at three places of the field of view; group B starts rolled by 30
degrees, turns about the other axis and is closer, so its corners reach
farther from the image centre.
Three exposures, named after the paper's (2000, 4000, 8000 us): gains 0.35,
0.7 and 1.4 of full scale for a white screen, the last one saturating the
white. Every pose is rendered once; each exposure gets its own noise: one
capture of each rotating-star frame, and eight captures of the checkerboard
frame averaged (the paper's fairness rule).

The chain, each step printed before it runs:

1. rotstar-pattern (the screen's frames and pattern.json);
2. rendering and detection (here, in --jobs processes): rotstar and the
   checkerboard baselines of rotstar_mrcal.validate.cornersets on every pose
   and exposure, written as corners.vnl files next to each group's truth;
   mrgingham on a square 9 x 9 checkerboard seen from the same poses;
3. rotstar-crossval per exposure: every corner set calibrated on A and on B
   with mrcal-calibrate-cameras, tested both ways (held-out MRE),
   cross-validated (projection diff vs uncertainty) and compared with the
   true camera;
4. rotstar-report over the three exposures.

The report's path and its headline table are printed at the end (stdout).
The images are not kept (3 exposures x 24 poses x 9 frames of 16-bit PNG
would be ~1 GB); --keep-images writes them as rotstar datasets.
"""

from __future__ import annotations

import os

# one BLAS thread per process: the work is spread over processes, and
# OpenBLAS threads spinning on the same cores made small SVDs 50x slower here
for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import concurrent.futures as cf  # noqa: E402
import dataclasses  # noqa: E402
import math  # noqa: E402
import multiprocessing  # noqa: E402
import shlex  # noqa: E402
import shutil  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

COMA_WAVES = 1.5  # Seidel coma at the image corners (h = 1), waves
FOCUS_WAVES = 0.3  # field curvature: defocus at the image corners, waves
EXPOSURES = (("2000 us", 0.35), ("4000 us", 0.7), ("8000 us (saturated)", 1.4))
NOISE = 0.01  # read noise, fraction of full scale
SHOT = 1e-4  # shot noise variance per unit signal (a 10000 e- full well)
CAPTURES = 8  # checkerboard captures averaged
TILTS = (0, 30, 60)
LENSMODEL = "LENSMODEL_OPENCV5"
SQUARE_N = 9  # mrgingham's board
METHODS = ("rotstar", "rotstar-weighted", "opencv-sb", "cornersubpix", "saddle")


def short_path(p: str) -> str:
    """p relative to the working directory if it lies below it, else absolute (for printed commands)"""
    r = os.path.relpath(p)
    return os.path.abspath(p) if r.startswith("..") else r


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def run(cmd, **kw) -> subprocess.CompletedProcess:
    log("$ " + shlex.join(cmd))
    t = time.monotonic()
    r = subprocess.run(cmd, **kw)
    if r.returncode != 0:
        sys.exit(f"demo: step failed ({cmd[0]}, exit {r.returncode})")
    log(f"  ({time.monotonic() - t:.0f} s)")
    return r


# ---------------------------------------------------------------------------
# the scene
# ---------------------------------------------------------------------------
GROUPS = {
    # name: (targets (x, y, sign of the turn), distance m, tilt axis deg, roll deg)
    "A": (((430, 400, 1), (640, 400, -1), (850, 400, -1)), 0.30, 90.0, 0.0),
    "B": (((250, 200, 1), (1030, 600, -1), (250, 600, 1)), 0.26, 0.0, 30.0),
}


def pose_group(model, layout, targets, distance, tilt_axis_deg, roll_deg, tilts=TILTS, margin=20.0):
    """The board turned about one axis at each target; a target moves toward the centre until it fits"""
    from rotstar_mrcal.simulate import look_at_pose, pose_ok

    W, H = model.imagersize()
    c = np.array(((W - 1) / 2, (H - 1) / 2))
    out = []
    for x, y, sign in targets:
        for tilt in tilts:
            for k in np.linspace(0, 1, 41):
                t = np.array((x, y)) + (c - (x, y)) * k
                rt = look_at_pose(model, layout, t, distance, math.radians(tilt) * sign,
                                  math.radians(tilt_axis_deg), math.radians(roll_deg))
                if pose_ok(model, layout, rt, margin):
                    out.append(rt)
                    break
            else:
                raise RuntimeError(f"no valid pose near {x, y} at {tilt} degrees")
    return np.array(out)


def coma_psf(imagersize):
    from rotstar_mrcal.optics import Optics, Seidel, radial_psf

    W, H = imagersize
    centre = ((W - 1) / 2, (H - 1) / 2)
    return radial_psf(Seidel(coma=COMA_WAVES, tilt=-COMA_WAVES, focus=FOCUS_WAVES), centre, Optics(),
                      tile_px=64, field_radius_px=math.hypot(*centre))


# ---------------------------------------------------------------------------
# rendering and detection, one pose per task
# ---------------------------------------------------------------------------
@dataclasses.dataclass
class Job:
    group: str
    index: int
    rt: np.ndarray
    rt_square: np.ndarray
    seed: int
    out: str
    keep_images: bool


_W: dict = {}


def _init(layout, square, model_args, rays):
    import cv2
    import mrcal

    from rotstar_mrcal import simulate

    cv2.setNumThreads(1)
    model = mrcal.cameramodel(intrinsics=model_args[0], imagersize=model_args[1])
    simulate.camera.remember_rays(model, rays)
    cb = [f for f in square.frames() if f["kind"] == "checkerboard"]
    _W.update(layout=layout, square=square, model=model, rays=rays, psf=coma_psf(model.imagersize()),
              screen=simulate.make_screen(simulate.exact_frames(layout), layout),
              screen_square=simulate.make_screen(simulate.exact_frames(square, cb), square))


def exposure_dir(out, label):
    return os.path.join(out, "e" + label.split()[0])


def _bbox(img, room=0.02, margin=8):
    """((y0, y1), (x0, x1)): the pixels that see more than the room level, grown by margin"""
    ys, xs = np.nonzero(np.abs(img - room) > 1e-4)
    H, W = img.shape
    if len(ys) == 0:
        return (0, H), (0, W)
    return ((max(ys.min() - margin, 0), min(ys.max() + margin + 1, H)),
            (max(xs.min() - margin, 0), min(xs.max() + margin + 1, W)))


def _do_pose(job: Job):
    """Render one pose once; per exposure: expose, detect every method, write the square board PNG"""
    import cv2

    from rotstar_mrcal import dataset, simulate
    from rotstar_mrcal.detect.baselines import average_frames
    from rotstar_mrcal.validate.cornersets import detect_methods

    t0 = time.perf_counter()
    W = _W
    layout, model = W["layout"], W["model"]
    kw = dict(supersample=2, psf=W["psf"], rays=W["rays"])
    E = simulate.render_irradiance(W["screen"], model, job.rt, **kw)  # 8 rotating-star frames + checkerboard
    Es = simulate.render_irradiance(W["screen_square"], model, job.rt_square, **kw)[0]
    pose = f"pose{job.index:03d}"
    results, crops = {}, {}
    truth = simulate.true_corners(model, layout, job.rt)
    for k, (label, gain) in enumerate(EXPOSURES):
        rng = np.random.default_rng([job.seed, ord(job.group), job.index, k])

        def expose(img):
            return simulate.expose(img, gain=gain, noise=NOISE, shot=SHOT, bits=16, rng=rng)

        def averaged(img):
            """CAPTURES captures averaged over the screen's part of the image; one capture elsewhere"""
            out = expose(img).astype(np.float32)
            (y0, y1), (x0, x1) = _bbox(img)
            roi = np.repeat(img[None, y0:y1, x0:x1], CAPTURES, axis=0)
            out[y0:y1, x0:x1] = average_frames(expose(roi))
            return out

        rot = expose(E[:-1])
        cb = averaged(E[-1])
        sq = averaged(Es)
        found = detect_methods(rot, layout, 65535.0, cb, METHODS)
        results[label] = {m: (f.corners, f.weights, f.why) for m, f in found.items()}
        edir = exposure_dir(job.out, label)
        sqdir = os.path.join(edir, f"{job.group}-square", pose)
        os.makedirs(sqdir, exist_ok=True)
        cv2.imwrite(os.path.join(sqdir, "checkerboard.png"), np.clip(np.round(sq / 257.0), 0, 255).astype(np.uint8))
        if job.keep_images:
            dataset.write_pose(os.path.join(edir, job.group), pose,
                               {f["file"]: img for f, img in zip(layout.frames(),
                                                                 list(rot) + [np.round(cb).astype(np.uint16)])})
        if job.index == 0:  # close-ups for the report: the corner nearest an image corner
            d = np.linalg.norm(truth - (0, 0), axis=-1)
            j, i = np.unravel_index(np.argmin(d), d.shape)
            x, y = np.round(truth[j, i]).astype(int)
            r = 20
            crops[label] = (rot[1, y - r:y + r + 1, x - r:x + r + 1], cb[y - r:y + r + 1, x - r:x + r + 1])
    return job.group, job.index, results, crops, time.perf_counter() - t0


# ---------------------------------------------------------------------------
# writing the corner sets and the truth
# ---------------------------------------------------------------------------
def write_group(edir, group, layout, model, rts, corners_by_method, square, rts_square):
    """edir/<group>/: pattern.json, truth.*, <method>.vnl; edir/<group>-square/: the same for mrgingham"""
    from rotstar_mrcal import dataset, simulate
    from rotstar_mrcal.simulate.dataset import Truth, write_truth
    from rotstar_mrcal.vnl import write_corners

    for name, lay, poses in ((group, layout, rts), (f"{group}-square", square, rts_square)):
        seq = os.path.join(edir, name)
        os.makedirs(seq, exist_ok=True)
        dataset.write_pattern(seq, lay)
        model.write(os.path.join(seq, "truth.cameramodel"))
        names = simulate.pose_names(len(poses))
        write_truth(seq, Truth(model, lay, dict(zip(names, poses)),
                               {n: simulate.true_corners(model, lay, r) for n, r in zip(names, poses)},
                               {"camera": "d435", "psf": "demo coma (scripts/demo.py)"}))
    vnls = {}
    seq = os.path.join(edir, group)
    for m, per_pose in corners_by_method.items():
        first = "rotstar_00.png" if m.startswith("rotstar") else "checkerboard.png"
        boards = [(f"pose{i:03d}/{first}", c) for i, (c, w) in enumerate(per_pose)]
        weights = [w for c, w in per_pose] if m == "rotstar-weighted" else None
        vnls[m] = os.path.join(seq, f"{m}.vnl")
        with open(vnls[m], "w") as f:
            write_corners(f, boards, weights)
    return vnls


def mrgingham_sets(out, npose):
    """Run mrgingham once over every square-board image; write edir/<g>-square/mrgingham.vnl"""
    from rotstar_mrcal.detect.baselines import mrgingham_detect
    from rotstar_mrcal.vnl import write_corners

    paths = {}
    for label, _ in EXPOSURES:
        for g, n in npose.items():
            for i in range(n):
                paths[(label, g, i)] = os.path.join(exposure_dir(out, label), f"{g}-square", f"pose{i:03d}",
                                                    "checkerboard.png")
    log(f"$ mrgingham --jobs {os.cpu_count()} --gridn {SQUARE_N} <{len(paths)} square-board images>")
    t = time.monotonic()
    found = mrgingham_detect(list(paths.values()), SQUARE_N, jobs=os.cpu_count() or 1)
    log(f"  ({time.monotonic() - t:.0f} s, {sum(v is not None for v in found.values())} of {len(found)} boards)")
    vnls = {}
    for label, _ in EXPOSURES:
        for g, n in npose.items():
            fn = os.path.join(exposure_dir(out, label), f"{g}-square", "mrgingham.vnl")
            with open(fn, "w") as f:
                write_corners(f, [(f"pose{i:03d}/checkerboard.png", found[paths[(label, g, i)]]) for i in range(n)])
            vnls[(label, g)] = fn
    return vnls


def exposure_figure(crops, fn):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, len(crops), figsize=(2.2 * len(crops), 4.4), constrained_layout=True)
    for k, (label, (rot, cb)) in enumerate(crops.items()):
        for row, (img, what) in enumerate(((rot, "rotating-star frame 1"), (cb, "checkerboard, 8 averaged"))):
            ax = axes[row, k]
            ax.imshow(img, cmap="gray", vmin=0, vmax=65535, interpolation="nearest")
            ax.set_title(f"{label}\n{what}", fontsize=7)
            ax.axis("off")
    fig.savefig(fn, dpi=110)
    plt.close(fig)


def setup_notes(npose, reach):
    return f"""\
Simulated Intel RealSense D435 infrared camera (1280x800 Y16, `OPENCV8` lens with fx = 640) looking at an
iPad (2360x1640, 264 ppi) showing the rotating-star sequence (14 x 9 corners, 8 frames) and a checkerboard.
The lens has a wavefront PSF (rotstar_mrcal.optics): coma growing with the field radius to {COMA_WAVES} waves
at the image corners (a comet about {3 * 2 * 0.367 * COMA_WAVES:.1f} px long there; its centroid is kept on the
chief ray, so the true model is where the light's centroid lands), field curvature ({FOCUS_WAVES} waves of
defocus at the corners), diffraction at F/2. Noise: read noise {NOISE:.0%} of full scale plus shot noise;
16-bit values.

Two pose groups as in the paper: in each, the iPad is turned about a fixed axis in 30-degree steps from 0
to 60 degrees (the paper: 10-degree steps), at three places in the field of view ({npose['A']} poses in A,
{npose['B']} in B). Group B is rolled by 30 degrees, turns about the other axis, is closer and spread wider:
90% of its corners lie within {reach['B']:.0f} px of the image centre, against {reach['A']:.0f} px for A.
Three exposures (gains 0.35, 0.7 and 1.4 of full scale for white; the last saturates the white).
Each method detects its own corners on the same poses: rotstar on the 8 rotating-star frames (one capture
each); the checkerboard methods on the checkerboard frame averaged over 8 captures; mrgingham on a square
9 x 9 checkerboard seen from the same poses. Every corner set is calibrated with mrcal
(`{LENSMODEL}`: the true lens has no rational terms, and the splined model needs more poses than a group
has) on group A and on group B.
"""


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="demo-out", help="output folder (default demo-out)")
    p.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="parallel processes")
    p.add_argument("--seed", type=int, default=1, help="noise seed")
    p.add_argument("--quick", action="store_true", help="two turn angles per place instead of three (smoke run)")
    p.add_argument("--keep-images", action="store_true", help="also write every frame (16-bit PNG, ~1 GB)")
    a = p.parse_args()

    from rotstar_mrcal import dataset, simulate
    from rotstar_mrcal.pattern.layout import make_layout
    from rotstar_mrcal.simulate.poses import centred_pose

    t0 = time.monotonic()
    out = os.path.abspath(a.out)
    os.makedirs(out, exist_ok=True)
    for k, _ in EXPOSURES:  # a previous run's square-board images would be read by mrgingham again
        shutil.rmtree(exposure_dir(out, k), ignore_errors=True)
    pat = os.path.join(out, "pattern")
    run(["rotstar-pattern", "--out", pat], stdout=subprocess.DEVNULL)
    _, layout = dataset.read_pattern(pat)
    square = make_layout(screen=(layout.screen_width, layout.screen_height), pixel_pitch_m=layout.pixel_pitch_m,
                         pitch=layout.pitch, band=layout.band, nx=SQUARE_N, ny=SQUARE_N)
    model = simulate.preset_model("d435")
    tilts = TILTS[::2] if a.quick else TILTS
    rts = {g: pose_group(model, layout, *spec, tilts=tilts) for g, spec in GROUPS.items()}
    rts_sq = {g: centred_pose(v, layout, square) for g, v in rts.items()}
    npose = {g: len(v) for g, v in rts.items()}
    c = (np.array(model.imagersize()) - 1) / 2
    reach = {g: float(np.percentile(np.linalg.norm(simulate.true_corners(model, layout, v) - c, axis=-1), 90))
             for g, v in rts.items()}

    # ---- render and detect -------------------------------------------------
    log(f"rendering {sum(npose.values())} poses once, exposing and detecting at {len(EXPOSURES)} exposures "
        f"({', '.join(METHODS)}) in {a.jobs} processes")
    rays = simulate.camera_rays(model)
    jobs = [Job(g, i, rts[g][i], rts_sq[g][i], a.seed, out, a.keep_images) for g in rts for i in range(npose[g])]
    res = {}
    crops = {}
    t = time.monotonic()
    init = (layout, square, (model.intrinsics(), model.imagersize()), rays)

    def done(r):
        g, i, found, cr, dt = r
        res[(g, i)] = found
        if g == "B" and cr:
            crops.update(cr)
        n_ok = sum(f[0] is not None for e in found.values() for f in e.values())
        log(f"  {g} pose{i:03d}: {n_ok} of {len(found) * len(METHODS)} boards ({dt:.1f} s; "
            f"{len(res)}/{len(jobs)}, {time.monotonic() - t:.0f} s)")

    if a.jobs > 1:
        ctx = multiprocessing.get_context("spawn")
        with cf.ProcessPoolExecutor(a.jobs, mp_context=ctx, initializer=_init, initargs=init) as ex:
            for f in cf.as_completed([ex.submit(_do_pose, j) for j in jobs]):
                done(f.result())
    else:
        _init(*init)
        for j in jobs:
            done(_do_pose(j))

    sets = {}
    for label, _ in EXPOSURES:
        edir = exposure_dir(out, label)
        for g in rts:
            per = {m: [res[(g, i)][label][m][:2] for i in range(npose[g])] for m in METHODS}
            for m, vnl in write_group(edir, g, layout, model, rts[g], per, square, rts_sq[g]).items():
                sets.setdefault(label, {}).setdefault(m, {})[g] = vnl
    if shutil.which("mrgingham"):
        for (label, g), vnl in mrgingham_sets(out, npose).items():
            sets[label].setdefault("mrgingham", {})[g] = vnl
    else:
        log("demo: mrgingham not installed; its baseline is left out")
    if crops:
        exposure_figure(crops, os.path.join(out, "exposures.png"))
    with open(os.path.join(out, "setup.md"), "w") as f:
        f.write(setup_notes(npose, reach))

    # ---- calibrate, cross-validate, report --------------------------------
    xdirs = []
    for label, _ in EXPOSURES:
        xdir = os.path.join(exposure_dir(out, label), "xval")
        cmd = ["rotstar-crossval", "--lensmodel", LENSMODEL, "--label", label, "--outdir", short_path(xdir),
               "--jobs", str(a.jobs)]
        for m, v in sets[label].items():
            cmd += ["--set", m, short_path(v["A"]), short_path(v["B"])]
        run(cmd, stdout=subprocess.DEVNULL)
        xdirs.append(xdir)
    rep = os.path.join(out, "report")
    cmd = ["rotstar-report", *[short_path(x) for x in xdirs], "--out", short_path(rep),
           "--title", "rotstar-mrcal demo: simulated D435 with coma, two pose groups, three exposures",
           "--notes", short_path(os.path.join(out, "setup.md"))]
    if crops:
        cmd += ["--figure", short_path(os.path.join(out, "exposures.png"))
                + ":Close-ups of one corner near the image corner at the three exposures"]
    r = run(cmd, stdout=subprocess.PIPE, text=True)
    print()
    print(f"rotstar-mrcal demo ({time.monotonic() - t0:.0f} s): report {os.path.join(rep, 'index.html')} "
          f"(also index.md)")
    print()
    print(r.stdout.rstrip())
    return 0


if __name__ == "__main__":
    sys.exit(main())

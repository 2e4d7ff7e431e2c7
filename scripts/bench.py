#!/usr/bin/env python3
"""make bench: corner accuracy and speed of rotstar against OpenCV and mrgingham

SYNOPSIS

    python scripts/bench.py                 # 20 poses, 16-bit, results in bench-out/
    python scripts/bench.py --quick         # 4 poses, a smoke run
    python scripts/bench.py --poses 40 --bits 8 --jobs 2 --out /tmp/b

Prints one Markdown table (stdout) with the goals evaluated beneath it; writes
bench.json, bench.md and error-cdf.png into --out. Progress goes to stderr.
See doc/benchmark.md.

The scene. The `d435` camera preset (1280x800, LENSMODEL_OPENCV8), the
default screen layout (make_layout(): 14x9 corners), random_poses with its
defaults (board anywhere on the imager, 0.3-0.6 m, tilts up to 60 degrees),
a Gaussian PSF of sigma 1 px, 4x4 area supersampling, read noise 1% of full
scale, 16-bit (or 8-bit) quantisation. Truth: simulate.true_corners, the
mrcal projection of the board points.

Per pose, all with independent noise:

- the 8 rotating-star frames, one capture each: rotstar's input;
- the checkerboard frame (the same nx x ny screen points as inner corners),
  8 captures averaged with baselines.average_frames: the paper's fairness
  rule (4.1), every method gets 8 exposures' worth of photons;
- the checkerboard of a square 9x9 layout, 8 captures averaged the same way,
  for mrgingham, which only finds N x N boards. It is rendered with the same
  rotation and its board centre where the 14x9 board centre is.

Methods (see METHODS):

1. rotstar (symmetric): detect_pose on the 8 frames, default options.
2. OpenCV findChessboardCornersSB with CALIB_CB_ACCURACY (|EXHAUSTIVE).
3. OpenCV findChessboardCorners + cornerSubPix (win 5), baselines' flags.
4. cornerSubPix and the Lucchese-Mitra saddle fit on the averaged
   checkerboard, refinement only: they start from rotstar's labelled corners
   moved 0.5 px in a random direction, with rotstar's per-corner window
   (0.65 x the element's inscribed half-side, 2..10 px, floored).
5. mrgingham (Debian CLI, --jobs 1) on the 9x9 board, written as an
   8-bit PNG: with its defaults, and with --noclahe (its CLAHE histogram
   equalisation on by default, off).

Scoring. rotstar labels its board itself (the orientation marker), so its
corners are compared with the truth as labelled. OpenCV and mrgingham
number a board from whichever corner they like; match_to_reference picks
the grid symmetry that fits the truth with every corner within MATCH_PX.
A returned board is *correct* if every corner it returns lies within
MATCH_PX of its true corner under that labelling; otherwise it is *wrong*
(mislabelled: a flipped/rotated or shifted grid; or a gross outlier corner)
and counts as a failure. Errors are pooled over the corners of correct
boards. A pose is *complete* when its board is correct and has all corners.

Timing. All images are rendered first (--jobs processes). Then every
detector runs in this process, pinned to one CPU (sched_setaffinity) with
one OpenCV and one BLAS thread, after one untimed warm-up call on the first
pose. Each call is timed twice: CPU time (time.process_time, plus the
user + system time of finished children for mrgingham's process, start-up
included) and wall time (time.perf_counter). The table's seconds and the
speed goal use CPU time, which other work on a shared machine does not
inflate; the wall times are printed next to it.

Memory. For each in-process method, a fresh Python process loads one pose
(the first that every method got right), calls the method once (warm-up), resets the peak-RSS mark
(/proc/self/clear_refs) and calls it again: peak RSS minus RSS before the
call is the working memory of one call, native (OpenCV) allocations
included. glibc's mmap threshold is fixed at 64 kB in that process
(MALLOC_MMAP_THRESHOLD_) so that freed buffers go back to the system and a
call cannot hide in memory an earlier call left behind. For mrgingham: the
peak RSS of its whole process, from GNU time (/usr/bin/time -f %M).
"""

from __future__ import annotations

# One BLAS thread: the detectors are timed on one core, and BLAS threads
# spinning on that same core would only slow them down.  Set before numpy loads.
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse
import concurrent.futures
import dataclasses
import datetime
import importlib.metadata
import json
import multiprocessing
import platform
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time

import cv2
import numpy as np

from rotstar_mrcal import simulate
from rotstar_mrcal.benchmark import speed
from rotstar_mrcal.detect import baselines
from rotstar_mrcal.detect.pipeline import detect_pose
from rotstar_mrcal.pattern.layout import Layout, make_layout
from rotstar_mrcal.simulate.poses import board_centre_m, centred_pose, tilt_angle
from rotstar_mrcal.focal import estimate_focal
from rotstar_mrcal.validate import calibrate as calib
from rotstar_mrcal.validate.truth import truth_error, truth_poses_of
from rotstar_mrcal.vnl import write_corners

import mrcal

MATCH_PX = 3.0  # a returned corner farther than this from its true corner makes the board wrong
START_PERTURB_PX = 0.5  # method 4 starts this far from rotstar's corners
SQUARE_N = 9  # mrgingham's board: SQUARE_N x SQUARE_N inner corners
CAPTURES = 8  # checkerboard captures averaged (= rotating-star frames)
GOAL_RATIO = 0.5
GOAL_SECONDS = 0.5
CAL_LENSMODEL = "LENSMODEL_OPENCV8"  # the d435 preset's own lens family


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


# ---------------------------------------------------------------------------
# the scene
# ---------------------------------------------------------------------------
@dataclasses.dataclass
class Scene:
    model: mrcal.cameramodel
    layout: Layout  # the default rotating-star layout (14x9)
    square: Layout  # the 9x9 variant for mrgingham (its checkerboard only)
    rts: np.ndarray  # (npose, 6) rt_cam_board of the default layout
    rts_square: np.ndarray  # (npose, 6) the same views of the square board
    settings: simulate.Settings


def make_scene(npose: int, seed: int, bits: int) -> Scene:
    model = simulate.preset_model("d435")
    layout = make_layout()
    square = make_layout(nx=SQUARE_N, ny=SQUARE_N)
    rts = simulate.random_poses(model, layout, npose, np.random.default_rng([0, seed]))
    rts_square = centred_pose(rts, layout, square)
    settings = simulate.Settings(blur_px=1.0, noise=0.01, bits=bits, seed=seed)
    return Scene(model, layout, square, rts, rts_square, settings)


# ---------------------------------------------------------------------------
# rendering (in worker processes with --jobs > 1)
# ---------------------------------------------------------------------------
@dataclasses.dataclass
class PoseImages:
    index: int
    rotstar: np.ndarray  # (8, H, W) uint8/uint16, one capture per frame
    checker: np.ndarray  # (H, W) float32, mean of CAPTURES captures
    checker_square: np.ndarray  # (H, W) float32, the 9x9 board, mean of CAPTURES captures
    seconds: float


_W: dict = {}


def _init_renderer(scene: Scene, rays) -> None:
    cv2.setNumThreads(1)
    cb = [f for f in scene.square.frames() if f["kind"] == "checkerboard"]
    _W.update(
        scene=scene,
        rays=rays,
        screen=simulate.make_screen(simulate.exact_frames(scene.layout), scene.layout, scene.settings.room),
        screen_square=simulate.make_screen(simulate.exact_frames(scene.square, cb), scene.square,
                                           scene.settings.room),
    )


def _expose(E: np.ndarray, st: simulate.Settings, rng) -> np.ndarray:
    return simulate.expose(E, gain=st.gain, black=st.black, noise=st.noise, bits=st.bits, rng=rng)


def averaged_captures(E: np.ndarray, st: simulate.Settings, rng) -> np.ndarray:
    """CAPTURES independently noisy exposures of one irradiance image, averaged"""
    return baselines.average_frames(_expose(np.repeat(E[None], CAPTURES, axis=0), st, rng))


def render_one(i: int) -> PoseImages:
    """Every image of pose i; the noise comes from default_rng([1, seed, i])"""
    t0 = time.perf_counter()
    sc, st = _W["scene"], _W["scene"].settings
    rng = np.random.default_rng([1, st.seed, i])
    kw = dict(supersample=st.supersample, psf=st.blur_px,
              sampling=st.sampling, rays=_W["rays"])
    E = simulate.render_irradiance(_W["screen"], sc.model, sc.rts[i], **kw)  # 8 rotstar + checkerboard
    Es = simulate.render_irradiance(_W["screen_square"], sc.model, sc.rts_square[i], **kw)
    return PoseImages(
        index=i,
        rotstar=_expose(E[:-1], st, rng),
        checker=averaged_captures(E[-1], st, rng),
        checker_square=averaged_captures(Es[0], st, rng),
        seconds=time.perf_counter() - t0,
    )


def render_all(scene: Scene, jobs: int) -> list[PoseImages]:
    n = len(scene.rts)
    t0 = time.perf_counter()
    log(f"rendering {n} poses ({jobs} process(es)): ray grid ...")
    rays = simulate.camera_rays(scene.model)
    out: list[PoseImages | None] = [None] * n

    def done(p: PoseImages):
        out[p.index] = p
        log(f"  pose {p.index:3d} rendered in {p.seconds:.1f} s ({sum(o is not None for o in out)}/{n}, "
            f"{time.perf_counter() - t0:.0f} s)")

    if jobs <= 1:
        _init_renderer(scene, rays)
        for i in range(n):
            done(render_one(i))
        _W.clear()
    else:
        ctx = multiprocessing.get_context("spawn")
        with concurrent.futures.ProcessPoolExecutor(jobs, mp_context=ctx, initializer=_init_renderer,
                                                    initargs=(scene, rays)) as ex:
            for f in concurrent.futures.as_completed([ex.submit(render_one, i) for i in range(n)]):
                done(f.result())
    return out


# ---------------------------------------------------------------------------
# the methods: run(images of one pose, context) -> (corners or None, reason)
# ---------------------------------------------------------------------------
@dataclasses.dataclass
class Context:
    layout: Layout
    full_scale: float
    start: np.ndarray | None = None  # (ny, nx, 2) method 4's start, NaN = none
    window: np.ndarray | None = None  # (ny, nx) method 4's half-windows, px
    png: str | None = None  # the 9x9 checkerboard as a PNG, for mrgingham
    window_out: np.ndarray | None = None  # rotstar leaves its refinement windows here
    weights_out: np.ndarray | None = None  # and its per-corner weights (1/sigma, median 1)


def run_rotstar(p: PoseImages, c: Context):
    r = detect_pose(p.rotstar, c.layout, full_scale=c.full_scale)
    c.window_out, c.weights_out = r.window, (r.weights() if r.found else None)
    return (None, r.error) if r.error else (r.corners, "")


def run_sb(p: PoseImages, c: Context):
    q = baselines.opencv_find_chessboard(p.checker, c.layout.nx, c.layout.ny, c.full_scale, method="sb")
    return q, "" if q is not None else "no board found"


def run_classic(p: PoseImages, c: Context):
    q = baselines.opencv_find_chessboard(p.checker, c.layout.nx, c.layout.ny, c.full_scale, method="classic")
    return q, "" if q is not None else "no board found"


def run_subpix(p: PoseImages, c: Context):
    if c.start is None:
        return None, "no start (rotstar found no board)"
    return baselines.refine_by_window(lambda im, x, w: baselines.opencv_subpix(im, x, win=w), p.checker,
                                      c.start, c.window), ""


def run_saddle(p: PoseImages, c: Context):
    if c.start is None:
        return None, "no start (rotstar found no board)"
    return baselines.refine_by_window(lambda im, x, w: baselines.saddle_refine(im, x, win=w), p.checker,
                                      c.start, c.window), ""


MRGINGHAM_ARGS = {"mrgingham": (), "mrgingham-noclahe": ("--noclahe",)}


def run_mrgingham(p: PoseImages, c: Context, key: str = "mrgingham"):
    q = baselines.mrgingham_detect([c.png], SQUARE_N, jobs=1, extra_args=MRGINGHAM_ARGS[key])[c.png]
    return q, "" if q is not None else "no board found"


def run_mrgingham_noclahe(p: PoseImages, c: Context):
    return run_mrgingham(p, c, "mrgingham-noclahe")


@dataclasses.dataclass(frozen=True)
class Method:
    key: str
    name: str
    start: str  # what the method sees and starts from, for the table
    run: object
    relabel: bool  # labelled only up to the grid symmetries (no orientation marker)
    square: bool = False  # runs on, and is scored against, the 9x9 board


START4 = f"rotstar's corners + {START_PERTURB_PX} px, rotstar's window"
METHODS = [
    Method("rotstar", "rotstar (symmetric)", "8 rotating-star frames", run_rotstar, False),
    Method("sb", "OpenCV findChessboardCornersSB (ACCURACY)", "own search", run_sb, True),
    Method("classic", "OpenCV findChessboardCorners + cornerSubPix", "own search, win 5", run_classic, True),
    Method("subpix", "cornerSubPix from rotstar's rough corners", START4, run_subpix, False),
    Method("saddle", "saddle fit (Lucchese-Mitra)", START4, run_saddle, False),
    Method("mrgingham", "mrgingham", "own search, 9x9 board, 8-bit PNG", run_mrgingham, True, square=True),
    Method("mrgingham-noclahe", "mrgingham --noclahe", "own search, 9x9 board, 8-bit PNG", run_mrgingham_noclahe,
           True, square=True),
]
STANDALONE = ("sb", "classic", "mrgingham", "mrgingham-noclahe")  # detectors that need no start from rotstar
BY_KEY = {m.key: m for m in METHODS}


def method4_start(corners: np.ndarray | None, seed: int, i: int) -> np.ndarray | None:
    """rotstar's labelled corners of pose i, each moved START_PERTURB_PX in a random direction"""
    if corners is None:
        return None
    phi = np.random.default_rng([2, seed, i]).uniform(0, 2 * np.pi, corners.shape[:-1])
    return corners + START_PERTURB_PX * np.stack((np.cos(phi), np.sin(phi)), axis=-1)


# ---------------------------------------------------------------------------
# scoring
# ---------------------------------------------------------------------------
def score_board(corners, truth: np.ndarray, relabel: bool) -> tuple[str, np.ndarray | None]:
    """('ok' | 'not found' | 'mislabelled' | 'outlier', corners in the truth's labelling)

    relabel: the method has no orientation of its own; take the grid symmetry
    that puts every corner within MATCH_PX of the truth (match_to_reference),
    or failing that the closest one, to say what went wrong. Otherwise the
    labelling is the method's. 'mislabelled': some corner lies nearer another
    true corner than its own (a flipped, turned or shifted grid);
    'outlier': labelled right, but some corner is more than MATCH_PX off.
    """
    if corners is None:
        return "not found", None
    c = np.asarray(corners, float)
    if relabel:
        m = baselines.match_to_reference(c, truth, MATCH_PX)
        if m is None:
            m = baselines.match_to_reference(c, truth, np.inf)
        if m is None:
            return "mislabelled", None
        c = m
    if c.shape != truth.shape:
        return "mislabelled", None
    d = np.linalg.norm(c - truth, axis=-1)
    have = np.isfinite(d)
    if not have.any():
        return "not found", None
    if np.max(d[have]) <= MATCH_PX:
        return "ok", c
    flat = c[have]
    nearest = np.argmin(np.linalg.norm(flat[:, None] - truth.reshape(1, -1, 2), axis=-1), axis=1)
    return ("mislabelled" if np.any(nearest != np.flatnonzero(have.ravel())) else "outlier"), c


def pose_row(i: int, status: str, corners, truth: np.ndarray, why: str, cpu: float, wall: float) -> dict:
    ok = status == "ok"
    err = np.linalg.norm(corners - truth, axis=-1) if ok else np.full(truth.shape[:-1], np.nan)
    e = err[np.isfinite(err)]
    return {
        "pose": i,
        "status": status,
        "reason": why if status == "not found" else "",
        "complete": bool(ok and e.size == err.size),
        "n_corners": int(e.size),
        "rms_px": float(np.sqrt(np.mean(e**2))) if e.size else None,
        "max_px": float(e.max()) if e.size else None,
        "cpu_seconds": cpu,
        "wall_seconds": wall,
        "errors_px": [round(float(v), 6) for v in e],
    }


def summarize(rows: list[dict], n_board: int) -> dict:
    e = np.concatenate([r["errors_px"] for r in rows]) if rows else np.empty(0)
    cpu = np.array([r["cpu_seconds"] for r in rows])
    wall = np.array([r["wall_seconds"] for r in rows])
    count = lambda s: sum(r["status"] == s for r in rows)  # noqa: E731
    return {
        "poses": len(rows),
        "complete": sum(r["complete"] for r in rows),
        "not_found": count("not found"),
        "mislabelled": count("mislabelled"),
        "outlier": count("outlier"),
        "corners": int(e.size),
        "corners_possible": n_board * len(rows),
        "rms_px": float(np.sqrt(np.mean(e**2))) if e.size else None,
        "p95_px": float(np.percentile(e, 95)) if e.size else None,
        "max_px": float(e.max()) if e.size else None,
        "cpu_seconds_median": float(np.median(cpu)),
        "cpu_seconds_max": float(cpu.max()),
        "wall_seconds_median": float(np.median(wall)),
        "wall_seconds_max": float(wall.max()),
    }


# ---------------------------------------------------------------------------
# timing and memory
# ---------------------------------------------------------------------------
def pin_one_cpu() -> int:
    """Run this process on one CPU, with one OpenCV thread; returns the CPU"""
    cpu = min(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {cpu})
    cv2.setNumThreads(1)
    return cpu


def cpu_seconds() -> float:
    """CPU time of this process and of its finished children (mrgingham), user + system"""
    ch = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + ch.ru_utime + ch.ru_stime


def timed(fn, *args):
    """(fn(*args), CPU seconds, wall seconds)

    On one pinned CPU and one thread, CPU time is the work of the call; the
    wall time also holds whatever else the machine made this CPU do.
    """
    c0, w0 = cpu_seconds(), time.perf_counter()
    out = fn(*args)
    return out, cpu_seconds() - c0, time.perf_counter() - w0


def proc_status_kb(key: str) -> int:
    with open("/proc/self/status") as f:
        return int(re.search(rf"^{key}:\s+(\d+)", f.read(), re.M).group(1))


def memory_probe(key: str, data: str) -> dict:
    """In a fresh process: the peak RSS one call of a method adds, after a warm-up call"""
    m = BY_KEY[key]
    z = np.load(data)
    p = PoseImages(0, z["rotstar"], z["checker"], z["checker_square"], 0.0)
    c = Context(make_layout(nx=SQUARE_N, ny=SQUARE_N) if m.square else make_layout(), float(z["full_scale"]),
                start=z["start"] if z["start"].size else None, window=z["window"] if z["window"].size else None,
                png=str(z["png"]))
    pin_one_cpu()
    m.run(p, c)
    before = proc_status_kb("VmRSS")
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")  # VmHWM := VmRSS
    m.run(p, c)
    peak = proc_status_kb("VmHWM")
    return {"rss_before_kb": before, "peak_kb": peak, "added_kb": peak - before}


def mrgingham_maxrss_kb(png: str, extra: tuple, tmp: str) -> int | None:
    """Peak RSS of one mrgingham run, from GNU time (None if /usr/bin/time is missing)

    Not os.wait4 on a child of this process: a child forked from a big
    process starts with its RSS, and ru_maxrss keeps that across exec.
    """
    gnu_time = "/usr/bin/time"
    if not os.access(gnu_time, os.X_OK):
        return None
    fn = os.path.join(tmp, "maxrss.txt")
    r = subprocess.run([gnu_time, "-f", "%M", "-o", fn, shutil.which("mrgingham"), "--jobs", "1", "--gridn",
                        str(SQUARE_N), *extra, png], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        with open(fn) as f:
            return int(f.read().split()[-1]) if r.returncode == 0 else None
    except (OSError, ValueError, IndexError):
        return None


def measure_memory(p: PoseImages, ctx: dict[str, Context], tmp: str) -> dict[str, dict]:
    """Peak memory of every method on pose p (see the module docstring)"""
    c4 = ctx.get("subpix")
    data = os.path.join(tmp, "memory-pose.npz")
    np.savez(data, rotstar=p.rotstar, checker=p.checker, checker_square=p.checker_square,
             full_scale=next(iter(ctx.values())).full_scale,
             start=c4.start if c4 is not None and c4.start is not None else np.empty(0),
             window=c4.window if c4 is not None and c4.window is not None else np.empty(0),
             png=ctx["mrgingham"].png if "mrgingham" in ctx else "")
    log(f"memory: pose {p.index}, one fresh process per method ...")
    env = dict(os.environ, MALLOC_MMAP_THRESHOLD_="65536", MALLOC_TRIM_THRESHOLD_="65536")
    out = {}
    for key, c in ctx.items():
        if key in MRGINGHAM_ARGS:
            kb = mrgingham_maxrss_kb(c.png, MRGINGHAM_ARGS[key], tmp)
            if kb is not None:
                out[key] = {"how": "ru_maxrss of the mrgingham process (GNU time %M)", "mb": kb / 1024}
            continue
        if key in ("subpix", "saddle") and c.start is None:
            continue
        r = subprocess.run([sys.executable, os.path.abspath(__file__), "--memory-probe", key, data],
                           env=env, capture_output=True, text=True)
        if r.returncode != 0:
            log(f"  memory probe of {key} failed: {r.stderr.strip()[-500:]}")
            continue
        d = json.loads(r.stdout)
        out[key] = {"how": "peak RSS added by one call (fresh process, after a warm-up call)",
                    "mb": d["added_kb"] / 1024, **d}
    return out


# ---------------------------------------------------------------------------
# the run
# ---------------------------------------------------------------------------
def write_png(folder: str, p: PoseImages, full_scale: float) -> str:
    """The averaged 9x9 checkerboard as an 8-bit PNG (mrgingham works on 8 bits)"""
    fn = os.path.join(folder, f"square{p.index:03d}.png")
    cv2.imwrite(fn, np.clip(np.round(p.checker_square * (255.0 / full_scale)), 0, 255).astype(np.uint8))
    return fn


def detect_all(scene: Scene, poses: list[PoseImages], tmp: str, have_mrgingham: bool) -> dict:
    """Every method on every pose, one timed call at a time on one CPU; then memory"""
    full_scale = float(simulate.full_scale_code(scene.settings.bits))
    cpu = pin_one_cpu()
    log(f"detecting on CPU {cpu} alone, one OpenCV/BLAS thread, after a warm-up call per method")
    truth = {False: [simulate.true_corners(scene.model, scene.layout, rt) for rt in scene.rts],
             True: [simulate.true_corners(scene.model, scene.square, rt) for rt in scene.rts_square]}
    pngs = [write_png(tmp, p, full_scale) for p in poses] if have_mrgingham else [None] * len(poses)
    found = {"corners": [None] * len(poses), "window": [None] * len(poses)}  # rotstar's, for method 4
    labelled = {}  # method -> per pose: corners in the truth's labelling where the board is right, else None
    rotstar_weights = [None] * len(poses)

    def context(m: Method, i: int) -> Context:
        c = Context(scene.square if m.square else scene.layout, full_scale, png=pngs[i])
        if m.key in ("subpix", "saddle"):
            c.start = method4_start(found["corners"][i], scene.settings.seed, i)
            c.window = found["window"][i]
        return c

    results = {}
    for m in METHODS:
        if m.key in MRGINGHAM_ARGS and not have_mrgingham:
            continue
        m.run(poses[0], context(m, 0))  # warm-up
        rows = []
        for i, p in enumerate(poses):
            c = context(m, i)
            (q, why), cpu, wall = timed(m.run, p, c)
            status, q = score_board(q, truth[m.square][i], m.relabel)
            rows.append(pose_row(i, status, q, truth[m.square][i], why, cpu, wall))
            if m.key == "rotstar" and status != "not found":
                found["corners"][i], found["window"][i] = q, c.window_out
                rotstar_weights[i] = c.weights_out
            labelled.setdefault(m.key, []).append(q if status == "ok" else None)
        results[m.key] = rows
        s = summarize(rows, 1)
        log(f"  {m.name}: {s['complete']}/{s['poses']} complete, {s['mislabelled'] + s['outlier']} wrong, "
            f"median {s['cpu_seconds_median']:.3f} CPU s/pose ({s['wall_seconds_median']:.3f} s wall)")
    batch = {}
    if have_mrgingham:  # mrgingham's own way: one process for all the images
        for key, extra in MRGINGHAM_ARGS.items():
            _, cpu, wall = timed(baselines.mrgingham_detect, pngs, SQUARE_N, 1, extra)
            batch[key] = {"cpu_s_per_image": cpu / len(pngs), "wall_s_per_image": wall / len(pngs)}
    # memory on the first pose every method got right (a failed search is no typical call)
    good = [i for i in range(len(poses)) if all(results[k][i]["status"] == "ok" for k in results)]
    i = good[0] if good else 0
    memory = measure_memory(poses[i], {k: context(BY_KEY[k], i) for k in results}, tmp)
    return {"results": results, "memory": memory, "memory_pose": i, "cpu": cpu, "mrgingham_batch_s": batch,
            "labelled": labelled, "rotstar_weights": rotstar_weights}


# ---------------------------------------------------------------------------
# calibration against the true camera
# ---------------------------------------------------------------------------
def calibrate_one(boards: list, weights: list | None, layout: Layout, rts: np.ndarray, model: mrcal.cameramodel,
                  outdir: str) -> dict:
    """mrcal-calibrate-cameras (CAL_LENSMODEL) on one method's boards; its error against the true camera

    boards: per pose (ny, nx, 2) or None. The calibrated model is compared
    with the truth over the imager after aligning the solved board poses
    with the true ones (validate.truth.truth_error, 'procrustes').
    """
    use = [i for i, b in enumerate(boards) if b is not None]
    if len(use) < calib.MIN_BOARDS:
        return {"boards": len(use), "error": f"{len(use)} boards: too few to calibrate"}
    os.makedirs(outdir, exist_ok=True)
    vnl = os.path.join(outdir, "corners.vnl")
    names = [f"pose{i:03d}/frame.png" for i in use]
    with open(vnl, "w") as f:
        write_corners(f, [(n, boards[i]) for n, i in zip(names, use)],
                      None if weights is None else [weights[i] for i in use])
    focal = estimate_focal([boards[i] for i in use], layout.board_points()[..., :2], model.imagersize())
    argv = calib.calibrate_argv(vnl, layout, model.imagersize(), focal, CAL_LENSMODEL, outdir, "*/frame.png",
                                weights=weights is not None)
    try:
        m = calib.run_calibration(argv, in_process=True)
    except calib.CalibrationError as e:
        return {"boards": len(use), "error": str(e).splitlines()[0]}
    e = truth_error(m, model, truth_poses_of(m, {f"pose{i:03d}": rts[i] for i in use}))
    return {"boards": len(use), "fit_rms_px": calib.calibration_stats(m)["rms_px"], **e.summary()}


def calibrate_all(scene: Scene, run: dict, tmp: str) -> dict[str, dict]:
    """Each method's right boards calibrated with mrcal, against the truth; rotstar also with weights"""
    out = {}
    jobs = [(k, k, None) for k in run["labelled"]]
    if "rotstar" in run["labelled"]:
        jobs.insert(1, ("rotstar-weighted", "rotstar", run["rotstar_weights"]))
    for key, src, weights in jobs:
        square = BY_KEY[src].square
        layout, rts = (scene.square, scene.rts_square) if square else (scene.layout, scene.rts)
        log(f"  calibrating {key} ({CAL_LENSMODEL})")
        out[key] = calibrate_one(run["labelled"][src], weights, layout, rts, scene.model, os.path.join(tmp, key))
    return out


def calibration_table(cal: dict[str, dict]) -> str:
    names = {**{k: BY_KEY[k].name for k in BY_KEY}, "rotstar-weighted": "rotstar, weighted (--weights)"}
    lines = ["| corners from | boards | fit RMS px | vs true camera: median px | p95 px | max px |",
             "|---|---|---|---|---|---|"]
    for k, c in cal.items():
        if "error" in c:
            lines.append(f"| {names[k]} | {c['boards']} | {c['error']} | - | - | - |")
        else:
            lines.append(f"| {names[k]} | {c['boards']} | {fmt(c['fit_rms_px'])} | {fmt(c['median_px'])} | "
                         f"{fmt(c['p95_px'])} | {fmt(c['max_px'])} |")
    return "\n".join(lines)


# ---------------------------------------------------------------------------
# report
# ---------------------------------------------------------------------------
def fmt(v, spec: str = ".4f", none: str = "-") -> str:
    return none if v is None else format(v, spec)


def table(summary: dict[str, dict], memory: dict[str, dict]) -> str:
    head = ("| method | input, start | poses complete | wrong boards (mislabelled/outlier) | corners found "
            "| RMS px | p95 px | max px | CPU s/pose (median, 1 core) | wall s/pose (median) | peak MB |")
    lines = [head, "|" + "---|" * head.count(" | ") + "---|"]
    for key, s in summary.items():
        m = BY_KEY[key]
        inp = "8 rotating-star frames" if key == "rotstar" else f"averaged checkerboard: {m.start}"
        mem = memory.get(key, {}).get("mb")
        mem_s = fmt(mem, ".1f") + (" (process)" if key in MRGINGHAM_ARGS and mem is not None else "")
        lines.append(
            f"| {m.name} | {inp} | {s['complete']}/{s['poses']} | {s['mislabelled'] + s['outlier']} "
            f"({s['mislabelled']}/{s['outlier']}) | {s['corners']}/{s['corners_possible']} | {fmt(s['rms_px'])} "
            f"| {fmt(s['p95_px'])} | {fmt(s['max_px'])} | {fmt(s['cpu_seconds_median'], '.3f')} "
            f"| {fmt(s['wall_seconds_median'], '.3f')} | {mem_s} |")
    return "\n".join(lines)


def goals(summary: dict[str, dict], results: dict[str, list[dict]]) -> dict:
    base = {k: s["rms_px"] for k, s in summary.items() if k != "rotstar" and s["rms_px"] is not None}
    rot = summary["rotstar"]
    out = {}
    if base and rot["rms_px"] is not None:
        best = min(base, key=base.get)
        ratio = rot["rms_px"] / base[best]
        # the same comparison on the poses both got right (the easy poses favour a method that fails the hard ones)
        both = [(a, b) for a, b in zip(results["rotstar"], results[best]) if a["status"] == b["status"] == "ok"]
        ea = np.concatenate([a["errors_px"] for a, _ in both]) if both else np.empty(0)
        eb = np.concatenate([b["errors_px"] for _, b in both]) if both else np.empty(0)
        paired = float(np.sqrt(np.mean(ea**2)) / np.sqrt(np.mean(eb**2))) if both else None
        out["accuracy"] = {"goal": f"rotstar corner RMS <= {GOAL_RATIO:g} x the best baseline's RMS",
                           "best_baseline": BY_KEY[best].name, "rotstar_rms_px": rot["rms_px"],
                           "baseline_rms_px": base[best], "ratio": ratio, "pass": bool(ratio <= GOAL_RATIO),
                           "paired_poses": len(both), "paired_ratio": paired}
    alone = {k: v for k, v in base.items() if k in STANDALONE}
    if alone and rot["rms_px"] is not None:
        best = min(alone, key=alone.get)
        out["accuracy_standalone"] = {
            "goal": "the same against the best detector that finds the board by itself (no start from rotstar)",
            "best_baseline": BY_KEY[best].name, "baseline_rms_px": alone[best],
            "ratio": rot["rms_px"] / alone[best], "pass": bool(rot["rms_px"] / alone[best] <= GOAL_RATIO)}
    n = int(np.median([r["n_corners"] for r in results["rotstar"]])) if results["rotstar"] else 0
    out["speed"] = {"goal": f"rotstar detection of one 8-frame 1280x800 pose (~126 corners) < {GOAL_SECONDS:g} s "
                            "on one core",
                    "measure": "CPU time of one detect_pose call on one pinned CPU, one thread",
                    "median_s": rot["cpu_seconds_median"], "max_s": rot["cpu_seconds_max"],
                    "wall_median_s": rot["wall_seconds_median"], "median_corners": n,
                    "pass": bool(rot["cpu_seconds_median"] < GOAL_SECONDS)}
    return out


def goal_lines(g: dict) -> str:
    lines = []
    a = g.get("accuracy")
    if a:
        paired = (f"; on the {a['paired_poses']} poses both got right: {a['paired_ratio']:.3f}"
                  if a["paired_ratio"] is not None else "")
        lines.append(f"- {a['goal']}: rotstar {a['rotstar_rms_px']:.4f} px / {a['best_baseline']} "
                     f"{a['baseline_rms_px']:.4f} px = **{a['ratio']:.3f}** -> **{'PASS' if a['pass'] else 'FAIL'}**"
                     f"{paired}")
    else:
        lines.append("- rotstar corner RMS <= 1/2 of the best baseline's RMS: not evaluated (no corners)")
    a = g.get("accuracy_standalone")
    if a:
        lines.append(f"  - (for information) {a['goal']}: {a['best_baseline']} {a['baseline_rms_px']:.4f} px, "
                     f"ratio {a['ratio']:.3f} ({'would pass' if a['pass'] else 'would fail'})")
    s = g["speed"]
    lines.append(f"- {s['goal']}: median {s['median_s']:.3f} CPU s (max {s['max_s']:.3f}; wall median "
                 f"{s['wall_median_s']:.3f} s) -> **{'PASS' if s['pass'] else 'FAIL'}**")
    return "\n".join(lines)


def failures(results: dict[str, list[dict]]) -> str:
    """One line per pose a method did not get right"""
    lines = []
    for key, rows in results.items():
        for r in rows:
            if r["status"] != "ok" or not r["complete"]:
                what = r["status"] if r["status"] != "ok" else f"incomplete ({r['n_corners']} corners)"
                lines.append(f"- {BY_KEY[key].name}, pose {r['pose']}: {what}"
                             + (f" ({r['reason']})" if r["reason"] else ""))
    return "\n".join(lines) if lines else "- none"


def notes(run: dict, have_mrgingham: bool) -> str:
    out = [
        f"- Peak MB: peak RSS that one call adds, on pose {run['memory_pose']} (fresh process, after a warm-up "
        "call, glibc mmap threshold 64 kB); mrgingham: peak RSS of its whole process (GNU time).",
        "- CPU s/pose: CPU time (user + system) of one call per pose, pinned to one CPU with one thread, after a "
        "warm-up call; mrgingham's is its process's, start-up included. Wall s/pose: the same calls by the clock "
        "(it grows when other work shares the machine).",
        f"- Errors: the corners of correct boards only; a board with a corner > {MATCH_PX:g} px off or "
        "mislabelled is a wrong board.",
    ]
    for key, b in run["mrgingham_batch_s"].items():
        out.append(f"- {BY_KEY[key].name}, one process for all the images (--jobs 1): "
                   f"{b['cpu_s_per_image']:.3f} CPU s ({b['wall_s_per_image']:.3f} s wall) per image.")
    if not have_mrgingham:
        out.append("- mrgingham is not installed (Debian package 'mrgingham'): its rows are skipped.")
    return "\n".join(out)


def package_version(name: str) -> str:
    try:
        return importlib.metadata.version(name)
    except importlib.metadata.PackageNotFoundError:
        return "?"


def machine() -> dict:
    cpu = "?"
    try:
        with open("/proc/cpuinfo") as f:
            cpu = re.search(r"^model name\s*:\s*(.*)$", f.read(), re.M).group(1)
    except (OSError, AttributeError):
        pass
    mg = None
    if shutil.which("dpkg-query"):
        r = subprocess.run(["dpkg-query", "-W", "-f", "${Version}", "mrgingham"], capture_output=True, text=True)
        mg = r.stdout.strip() or None
    return {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(), "numpy": np.__version__,
            "opencv": cv2.__version__, "mrcal": package_version("mrcal"), "mrgingham": mg,
            "platform": platform.platform()}


def plot_cdf(results: dict[str, list[dict]], fn: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.2))
    for key, rows in results.items():
        e = np.sort(np.concatenate([r["errors_px"] for r in rows]) if rows else np.empty(0))
        if e.size:
            ax.step(e, np.arange(1, e.size + 1) / e.size, where="post", label=f"{BY_KEY[key].name} ({e.size})")
    ax.set_xscale("log")
    ax.set_xlabel("corner error against truth, px")
    ax.set_ylabel("fraction of the detected corners")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="upper left")
    ax.set_title("Corner error CDF (correct boards only)", fontsize=10)
    fig.tight_layout()
    fig.savefig(fn, dpi=110)
    plt.close(fig)


# ---------------------------------------------------------------------------
def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--poses", type=int, default=20, help="random poses (default 20)")
    p.add_argument("--quick", action="store_true", help="smoke run: 4 poses")
    p.add_argument("--seed", type=int, default=0, help="poses and noise (default 0)")
    p.add_argument("--bits", type=int, choices=(8, 16), default=16, help="image depth (default 16)")
    p.add_argument("--jobs", type=int, default=os.cpu_count() or 1,
                   help="processes for rendering only; detectors are always timed on one core (default: all cores)")
    p.add_argument("--out", default="bench-out", help="folder for bench.json, bench.md, error-cdf.png")
    p.add_argument("--doc", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "doc", "benchmark.md"),
                   help="rewrite the speed section (between <!-- speed:begin/end --> markers) of this file "
                        "(default: doc/benchmark.md; '' for none)")
    p.add_argument("--memory-probe", nargs=2, metavar=("METHOD", "NPZ"), help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.quick:
        a.poses = 4
    if a.poses < 1:
        p.error("--poses must be at least 1")
    return a


def main(argv=None) -> int:
    a = parse_args(argv)
    if a.memory_probe:
        print(json.dumps(memory_probe(*a.memory_probe)))
        return 0
    t0 = time.perf_counter()
    started = datetime.datetime.now().astimezone()
    have_mrgingham = shutil.which("mrgingham") is not None
    if not have_mrgingham:
        log("note: mrgingham is not installed (Debian package 'mrgingham'); its row is skipped")
    scene = make_scene(a.poses, a.seed, a.bits)
    tilts = np.degrees(tilt_angle(scene.rts, scene.layout))
    dist = np.linalg.norm([mrcal.transform_point_rt(rt, board_centre_m(scene.layout)) for rt in scene.rts], axis=-1)
    poses = render_all(scene, max(1, a.jobs))
    t_render = time.perf_counter() - t0
    with tempfile.TemporaryDirectory(prefix="rotstar-bench-") as tmp:
        run = detect_all(scene, poses, tmp, have_mrgingham)
        log("calibrating with mrcal from each method's boards")
        cal = calibrate_all(scene, run, tmp)
        speed_md, speed_run = speed.bench_speed(os.path.join(tmp, "speed-seq"), scene.layout,
                                                [(p.rotstar, p.checker) for p in poses], a.bits, log=log)
    results, memory = run["results"], run["memory"]
    sizes = {k: (scene.square if BY_KEY[k].square else scene.layout) for k in results}
    summary = {k: summarize(rows, sizes[k].nx * sizes[k].ny) for k, rows in results.items()}
    g = goals(summary, results)
    wall = time.perf_counter() - t0
    mach = machine()

    tab = table(summary, memory)
    gl = goal_lines(g)
    cal_title = (f"Calibration with mrcal ({CAL_LENSMODEL}) from each method's correct boards, against the "
                 "true camera over the imager (at infinity, board poses aligned with the true ones):")
    cal_tab = calibration_table(cal)
    print(tab)
    print()
    print(gl)
    print()
    print(cal_title)
    print()
    print(cal_tab)
    print()
    print(speed_md)
    sys.stdout.flush()

    os.makedirs(a.out, exist_ok=True)
    setup = (f"{a.poses} poses, seed {a.seed}, {a.bits}-bit, d435 preset (1280x800 OPENCV8), layout "
             f"{scene.layout.nx}x{scene.layout.ny} (mrgingham: {SQUARE_N}x{SQUARE_N}), Gaussian PSF sigma "
             f"{scene.settings.blur_px} px, noise {scene.settings.noise:.0%} of full scale, checkerboard = mean of "
             f"{CAPTURES} captures; tilt {tilts.min():.0f}-{tilts.max():.0f} deg, distance "
             f"{dist.min():.2f}-{dist.max():.2f} m")
    when = (f"{started:%Y-%m-%d %H:%M %Z}, {mach['cpu']}, {mach['cores']} cores; wall time {wall:.0f} s "
            f"(rendering {t_render:.0f} s with {a.jobs} process(es))")
    md = "\n\n".join([
        "# rotstar-mrcal benchmark", setup, when, tab, gl, cal_title, cal_tab,
        "Poses a method did not get complete and right:\n\n" + failures(results),
        notes(run, have_mrgingham), speed_md,
    ]) + "\n"
    with open(os.path.join(a.out, "bench.md"), "w") as f:
        f.write(md)
    doc = {
        "format": "rotstar-bench/1",
        "date": started.isoformat(timespec="seconds"),
        "machine": mach,
        "wall_seconds": wall,
        "render_seconds": t_render,
        "config": {"poses": a.poses, "seed": a.seed, "bits": a.bits, "jobs": a.jobs, "camera": "d435",
                   "layout": [scene.layout.nx, scene.layout.ny], "square_layout": [SQUARE_N, SQUARE_N],
                   "settings": dataclasses.asdict(scene.settings), "captures_averaged": CAPTURES,
                   "match_px": MATCH_PX, "start_perturb_px": START_PERTURB_PX, "timing_cpu": run["cpu"],
                   "memory_pose": run["memory_pose"]},
        "mrgingham_batch_seconds_per_image": run["mrgingham_batch_s"],
        "poses": [{"pose": i, "rt_cam_board": rt.tolist(), "tilt_deg": float(t), "distance_m": float(d)}
                  for i, (rt, t, d) in enumerate(zip(scene.rts, tilts, dist))],
        "methods": {k: {"name": BY_KEY[k].name, "start": BY_KEY[k].start, **summary[k],
                        "memory": memory.get(k), "per_pose": results[k]} for k in results},
        "goals": g,
        "calibration": {"lensmodel": CAL_LENSMODEL, "methods": cal},
        "speed": speed_run,
    }
    with open(os.path.join(a.out, "bench.json"), "w") as f:
        json.dump(doc, f, indent=1)
        f.write("\n")
    plot_cdf(results, os.path.join(a.out, "error-cdf.png"))
    if a.doc and speed.write_block(a.doc, "speed", f"{setup}.\n\n{when}.\n\n{speed_md}"):
        log(f"wrote the speed section of {a.doc}")
    log(f"wrote {a.out}/bench.json, bench.md, error-cdf.png; wall time {wall:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())

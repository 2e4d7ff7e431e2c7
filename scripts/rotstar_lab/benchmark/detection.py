"""Every method on every pose, one timed call at a time on one CPU, scored against the truth

SYNOPSIS

    run = detect_all(scene, poses, tmp, log=print)
    run.results["rotstar"][0]["status"]        # per method, per pose: a scoring.pose_row
    run.labelled["opencv-sb"][0]               # its corners in the truth's labelling, or None
    run.weights["rotstar-weighted"][0]         # a variant's per-corner weights
    run.memory["saddle"]["mb"]                 # memory.measure_memory on one pose

The methods are rotstar_mrcal.peers.registry.METHODS (a variant, which gives
another method's corners with weights, is not timed: its weights are kept
for the calibration). A method's input (methods.PoseImages) holds only what
it needs: the 8 rotating-star frames (and the identity frames, when the
layout has them), the averaged checkerboard, or the
square board as an 8-bit PNG. The methods that start from rotstar start from
its labelled corners moved START_PERTURB_PX (scoring.perturbed_start), with
its per-corner windows; rotstar runs first. Each method gets one untimed
warm-up call on the first pose. mrgingham is also timed its own way: one
process for all the images.
"""

from __future__ import annotations

import dataclasses
import shutil


from rotstar_mrcal import simulate
from rotstar_mrcal.peers.checkerboard import mrgingham_detect
from rotstar_mrcal.peers.registry import METHODS, PoseImages, method_names
from rotstar_lab.benchmark import memory, scoring
from rotstar_lab.benchmark.scene import RenderedPose, Scene, write_square_png
from rotstar_lab.benchmark.timing import pin_one_cpu, timed


@dataclasses.dataclass
class DetectionRun:
    results: dict  # method -> [pose_row]
    labelled: dict  # method -> per pose: corners in the truth's labelling where the board is ok, else None
    weights: dict  # variant -> per pose: (ny, nx) weights or None
    memory: dict  # method -> memory.measure_memory's entry
    memory_pose: int
    cpu: int  # the CPU the calls ran on
    batch: dict  # program method -> CPU and wall s per image, one process for all images


def benchmarked_methods(have_programs: bool = True) -> list[str]:
    """The methods the benchmark times: every method but the variants (and the programs, when missing)"""
    needs = ("rotstar", "checkerboard") + (("square",) if have_programs else ())
    return method_names(needs=needs, variants=False)  # (its scene renders no phase-shift or star frames)


def pose_inputs(name: str, scene: Scene, p: RenderedPose, full_scale: float, png: str | None,
                start=None, window=None) -> PoseImages:
    """What method `name` sees of pose p"""
    m = METHODS[name]
    q = PoseImages(scene.layout_for(m.needs), full_scale)
    if m.needs == "rotstar":
        q.frames, q.identity = p.rotstar, p.identity
    elif m.needs == "checkerboard":
        q.checkerboard = p.checker
    else:
        q.png = png
    if m.start == "rotstar":
        q.start, q.start_window = start, window
    return q


def detect_all(scene: Scene, poses: list[RenderedPose], tmp: str, log=None,
               measure_memory: bool = True) -> DetectionRun:
    """Every method on every pose, one timed call at a time on one CPU; then memory (see the module doc)"""
    log = log or (lambda msg: None)
    full_scale = float(simulate.full_scale_code(scene.settings.bits))
    have_programs = shutil.which("mrgingham") is not None
    names = benchmarked_methods(have_programs)
    cpu = pin_one_cpu()
    log(f"detecting on CPU {cpu} alone, one OpenCV/BLAS thread, after a warm-up call per method")
    truth = {needs: scene.truth(needs) for needs in {METHODS[n].needs for n in names}}
    pngs = [write_square_png(tmp, p, full_scale) if have_programs else None for p in poses]
    n = len(poses)
    start, window = [None] * n, [None] * n  # rotstar's, for the methods that start from it
    variants = [v for v, m in METHODS.items() if m.variant_of == "rotstar"]
    weights = {v: [None] * n for v in variants}

    def inputs(name, i):
        return pose_inputs(name, scene, poses[i], full_scale, pngs[i], start[i], window[i])

    results, labelled = {}, {}
    for name in names:
        m = METHODS[name]
        m(inputs(name, 0))  # warm-up
        rows = []
        for i in range(n):
            q = inputs(name, i)
            f, c, w = timed(m, q)
            status, corners = scoring.score_board(f.corners, truth[m.needs][i], m.relabel)
            rows.append(scoring.pose_row(i, status, corners, truth[m.needs][i], f.why, c, w))
            if name == "rotstar" and status != "not found":
                start[i] = scoring.perturbed_start(corners, scene.settings.seed, i)
                window[i] = q.detection.window
                for v in variants:
                    weights[v][i] = METHODS[v](q).weights  # the same detection, cached in q
            labelled.setdefault(name, []).append(corners if status == "ok" else None)
        results[name] = rows
        s = scoring.summarize(rows, 1)
        log(f"  {m.title}: {s['complete']}/{s['poses']} complete, {s['mislabelled'] + s['outlier']} wrong, "
            f"median {s['cpu_seconds_median']:.3f} CPU s/pose ({s['wall_seconds_median']:.3f} s wall)")
    batch = {}
    for name in names:  # a program's own way: one process for all the images
        if METHODS[name].needs == "square":
            _, c, w = timed(mrgingham_detect, pngs, scene.square.nx, 1, METHODS[name].args)
            batch[name] = {"cpu_s_per_image": c / n, "wall_s_per_image": w / n}
    # memory on the first pose every method got right (a failed search is no typical call)
    good = [i for i in range(n) if all(results[k][i]["status"] == "ok" for k in results)]
    i = good[0] if good else 0
    mem = {}
    if measure_memory:
        log(f"memory: pose {i}, one fresh process per method ...")
        mem = memory.measure_memory({k: inputs(k, i) for k in names}, tmp, log)
    return DetectionRun(results, labelled, weights, mem, i, cpu, batch)

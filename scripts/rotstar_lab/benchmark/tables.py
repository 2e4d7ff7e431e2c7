"""The benchmark's Markdown tables, goal lines, notes and the sentence in README.md

SYNOPSIS

    >>> from rotstar_lab.benchmark.tables import fmt, input_text
    >>> fmt(0.012345), fmt(None), fmt(0.5, ".1f")
    ('0.0123', '-', '0.5')
    >>> input_text("saddle")
    "averaged checkerboard: rotstar's corners + 0.5 px, rotstar's window"
    >>> input_text("mrgingham")
    'averaged checkerboard: own search, 9x9 board, 8-bit PNG'

Every function returns text from the numbers of scoring, detection and
calibration; scripts/bench.py prints it, writes it to bench.md and into the
marked blocks of doc/benchmark.md and README.md (rotstar_lab.docblock).
"""

from __future__ import annotations

import importlib.metadata
import os
import platform
import re
import shutil
import dataclasses

import numpy as np
import cv2

from rotstar_mrcal.peers.registry import METHODS
from rotstar_mrcal.programs import run_tool
from rotstar_lab.benchmark.scene import SQUARE_N
from rotstar_lab.benchmark.scoring import MATCH_PX, START_PERTURB_PX


def fmt(v, spec: str = ".4f", none: str = "-") -> str:
    return none if v is None else format(v, spec)


def input_text(name: str) -> str:
    """What a method sees and where it starts, for the table's second column"""
    m = METHODS[name]
    if m.needs == "rotstar":
        return "8 rotating-star frames"
    if m.needs in ("phase", "star"):
        what = "4-step phase shifts along x and y" if m.needs == "phase" else "the star frame"
        return f"{what}: rotstar's corners" + (f", {m.detail}" if m.detail else ", rotstar's window")
    if m.start == "rotstar":
        start = f"rotstar's corners + {START_PERTURB_PX} px, rotstar's window"
    else:
        start = ", ".join(["own search"] + ([m.detail] if m.detail else [])
                          + ([f"{SQUARE_N}x{SQUARE_N} board, 8-bit PNG"] if m.needs == "square" else []))
    return f"averaged checkerboard: {start}"


def accuracy_table(summary: dict[str, dict], memory: dict[str, dict]) -> str:
    head = ("| method | input, start | poses complete | wrong boards (mislabelled/outlier) | corners found "
            "| RMS px | p95 px | max px | CPU s/pose (median, 1 core) | wall s/pose (median) | peak MB |")
    lines = [head, "|" + "---|" * head.count(" | ") + "---|"]
    for key, s in summary.items():
        m = METHODS[key]
        mem = memory.get(key, {}).get("mb")
        mem_s = fmt(mem, ".1f") + (" (process)" if m.needs == "square" and mem is not None else "")
        lines.append(
            f"| {m.title} | {input_text(key)} | {s['complete']}/{s['poses']} | {s['mislabelled'] + s['outlier']} "
            f"({s['mislabelled']}/{s['outlier']}) | {s['corners']}/{s['corners_possible']} | {fmt(s['rms_px'])} "
            f"| {fmt(s['p95_px'])} | {fmt(s['max_px'])} | {fmt(s['cpu_seconds_median'], '.3f')} "
            f"| {fmt(s['wall_seconds_median'], '.3f')} | {mem_s} |")
    return "\n".join(lines)


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


def calibration_table(cal: dict[str, dict]) -> str:
    lines = ["| corners from | boards | fit RMS px | vs true camera: median px | p95 px | max px |",
             "|---|---|---|---|---|---|"]
    for k, c in cal.items():
        if "error" in c:
            lines.append(f"| {METHODS[k].title} | {c['boards']} | {c['error']} | - | - | - |")
        else:
            lines.append(f"| {METHODS[k].title} | {c['boards']} | {fmt(c['fit_rms_px'])} | {fmt(c['median_px'])} | "
                         f"{fmt(c['p95_px'])} | {fmt(c['max_px'])} |")
    return "\n".join(lines)


def failures(results: dict[str, list[dict]]) -> str:
    """One line per pose a method did not get right"""
    lines = []
    for key, rows in results.items():
        for r in rows:
            if r["status"] != "ok" or not r["complete"]:
                what = r["status"] if r["status"] != "ok" else f"incomplete ({r['n_corners']} corners)"
                lines.append(f"- {METHODS[key].title}, pose {r['pose']}: {what}"
                             + (f" ({r['reason']})" if r["reason"] else ""))
    return "\n".join(lines) if lines else "- none"


def batch_lines(batch: dict, npose: int) -> str:
    """mrgingham's time when one process handles all the images"""
    return "\n".join(f"- {METHODS[k].title}, one process for all {npose} images (--jobs 1): "
                     f"{b['cpu_s_per_image']:.3f} CPU s ({b['wall_s_per_image']:.3f} s wall) per image."
                     for k, b in batch.items())


def notes(memory_pose: int, batch: dict, npose: int, have_mrgingham: bool) -> str:
    out = [
        f"- Peak MB: peak RSS that one call adds, on pose {memory_pose} (fresh process, after a warm-up "
        "call, glibc mmap threshold 64 kB); mrgingham: peak RSS of its whole process (GNU time).",
        "- CPU s/pose: CPU time (user + system) of one call per pose, pinned to one CPU with one thread, after a "
        "warm-up call; mrgingham's is its process's, start-up included. Wall s/pose: the same calls by the clock "
        "(it grows when other work shares the machine).",
        f"- Errors: the corners of correct boards only; a board with a corner > {MATCH_PX:g} px off or "
        "mislabelled is a wrong board.",
    ]
    if batch:
        out.append(batch_lines(batch, npose))
    if not have_mrgingham:
        out.append("- mrgingham is not installed (Debian package 'mrgingham'): its rows are skipped.")
    return "\n".join(out)


def summary_sentence(summary: dict[str, dict], cal: dict[str, dict], npose: int) -> str:
    """One sentence for README.md: rotstar against the others, corners and calibrated models

    >>> s = {"rotstar": {"rms_px": 0.006, "cpu_seconds_median": 0.44}, "saddle": {"rms_px": 0.0085},
    ...      "opencv-sb": {"rms_px": 0.12}}
    >>> c = {"rotstar": {"median_px": 0.007}, "saddle": {"median_px": 0.026}, "opencv-sb": {"error": "few"}}
    >>> print(summary_sentence(s, c, 20))
    20 simulated poses: rotstar's corners are 0.0060 px RMS from the truth in 0.44 CPU s per pose on one core, the other methods' 0.0085-0.1200 px (best: saddle fit (Lucchese-Mitra)); calibrated with mrcal, rotstar's model is 0.0070 px from the true camera (median over the imager), the best other method's 0.0260 px.
    """
    rot = summary["rotstar"]
    others = {k: s["rms_px"] for k, s in summary.items() if k != "rotstar" and s["rms_px"] is not None
              and METHODS[k].peer}  # the peers: rotstar's own variants are not "the other methods"
    text = f"{npose} simulated poses: rotstar's corners are {fmt(rot['rms_px'])} px RMS from the truth in " \
           f"{fmt(rot['cpu_seconds_median'], '.2f')} CPU s per pose on one core"
    if others:
        best = min(others, key=others.get)
        text += (f", the other methods' {min(others.values()):.4f}-{max(others.values()):.4f} px "
                 f"(best: {METHODS[best].title})")
    med = {k: c["median_px"] for k, c in cal.items() if "median_px" in c and (k == "rotstar" or METHODS[k].peer)}
    if "rotstar" in med:
        rest = [v for k, v in med.items() if k != "rotstar"]
        text += f"; calibrated with mrcal, rotstar's model is {med['rotstar']:.4f} px from the true camera " \
                "(median over the imager)" + (f", the best other method's {min(rest):.4f} px" if rest else "")
    return text + "."


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
        r = run_tool(["dpkg-query", "-W", "-f", "${Version}", "mrgingham"], capture_output=True, text=True)
        mg = r.stdout.strip() or None
    return {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(), "numpy": np.__version__,
            "opencv": cv2.__version__, "mrcal": package_version("mrcal"), "mrgingham": mg,
            "platform": platform.platform()}


def setup_line(scene, tilts, dist, captures: int) -> str:
    """The settings of a run, one paragraph"""
    st = scene.settings
    return (f"{len(scene.rts)} poses, seed {st.seed}, {st.bits}-bit, d435 preset (1280x800 OPENCV8), layout "
            f"{scene.layout.nx}x{scene.layout.ny} (mrgingham: {SQUARE_N}x{SQUARE_N}), Gaussian PSF sigma "
            f"{st.blur_px} px, noise {st.noise:.0%} of full scale, checkerboard = mean of {captures} captures; "
            f"tilt {tilts.min():.0f}-{tilts.max():.0f} deg, distance {dist.min():.2f}-{dist.max():.2f} m")


def run_line(started, mach: dict, scene, tilts, dist, wall: float, render: float, jobs: int) -> str:
    """When, where and what, for doc/benchmark.md's result"""
    st = scene.settings
    mem_gb = ""
    try:
        mem_gb = f", {os.sysconf('SC_PAGE_SIZE') * os.sysconf('SC_PHYS_PAGES') / 1e9:.0f} GB"
    except (ValueError, OSError):
        pass
    return (f"{started:%Y-%m-%d %H:%M %Z}; {mach['cores']} cores ({mach['cpu']}{mem_gb}), Python {mach['python']}, "
            f"OpenCV {mach['opencv']}, mrcal {mach['mrcal']}, mrgingham {mach['mrgingham'] or 'not installed'}; "
            f"{len(scene.rts)} poses, seed {st.seed}, {st.bits}-bit; tilts {tilts.min():.0f}-{tilts.max():.0f} "
            f"degrees, {dist.min():.2f}-{dist.max():.2f} m. Wall time {wall:.0f} s, of which rendering "
            f"{render:.0f} s with {jobs} process(es).")


def bench_json(started, mach: dict, wall: float, render: float, jobs: int, scene, run, summary: dict,
               goals: dict, cal: dict, cal_lensmodel: str, captures: int) -> dict:
    """Everything of a run, for bench.json ('rotstar-bench/2'; methods keyed by their registry names)"""
    from rotstar_lab.benchmark.scoring import MATCH_PX, START_PERTURB_PX

    st = scene.settings
    tilts, dist = scene.tilts_deg(), scene.distances_m()
    return {
        "format": "rotstar-bench/2",
        "date": started.isoformat(timespec="seconds"),
        "machine": mach,
        "wall_seconds": wall,
        "render_seconds": render,
        "config": {"poses": len(scene.rts), "seed": st.seed, "bits": st.bits, "jobs": jobs, "camera": "d435",
                   "layout": [scene.layout.nx, scene.layout.ny], "square_layout": [scene.square.nx, scene.square.ny],
                   "settings": dataclasses.asdict(st), "captures_averaged": captures, "match_px": MATCH_PX,
                   "start_perturb_px": START_PERTURB_PX, "timing_cpu": run.cpu, "memory_pose": run.memory_pose},
        "mrgingham_batch_seconds_per_image": run.batch,
        "poses": [{"pose": i, "rt_cam_board": rt.tolist(), "tilt_deg": float(t), "distance_m": float(d)}
                  for i, (rt, t, d) in enumerate(zip(scene.rts, tilts, dist))],
        "methods": {k: {"name": METHODS[k].title, "input": input_text(k), **summary[k],
                        "memory": run.memory.get(k), "per_pose": rows} for k, rows in run.results.items()},
        "goals": goals,
        "calibration": {"lensmodel": cal_lensmodel, "methods": cal},
    }

"""Speed of rotstar-detect against the cost of reading its input, and against mrgingham

SYNOPSIS

    from rotstar_lab.benchmark import speed
    r = speed.measure_speed("seq")          # a dataset folder (pattern.json + pose folders)
    print(r.table())                        # Markdown: decode, detect, ratio, start-up, mrgingham
    r.to_dict()                             # everything, for bench.json
    rewrite_block("doc/benchmark.md", "speed", r.table())   # rotstar_lab.docblock

Everything runs on one CPU (this process is pinned to one CPU for the
measurement, and the child processes inherit it) with one OpenCV thread;
all times are CPU seconds (user + system). Per pose: the median of `repeats`
passes over all poses; the whole runs (the command's, mrgingham's, and the
sum of all poses' decode + detect in this process, from which the command's
start-up is the difference): the fastest of `repeats`.

Per pose of the dataset, in this process:

* decode: `dataset.load_pose`, i.e. reading and decoding every PNG of the
  pose folder into float32 arrays (what rotstar-detect does first);
* detect: `detect_pose` on those frames with the default options (the
  identity frames included, when the pattern has them);
* detect without identity: the same call without the identity frames, when
  the pattern has them: what decoding them adds (`identity_share`).

For the whole dataset, in child processes:

* the command: `rotstar-detect SEQ -o FILE` (one job), start-up, all poses,
  the focal estimate and the output; its start-up and fixed cost is what
  it spends beyond the per-pose decode + detect: `startup_s`;
* mrgingham: one `mrgingham --jobs 1` process on the same images (every PNG
  of every pose), start-up included.

The goals of issue 11: detection, with the command's start-up spread over
the poses of the run, at most 2x the decoding (`ratio_with_startup`), and at
most 0.5x mrgingham's time per pose on the same images (`vs_mrgingham`;
mrgingham's time includes reading its images, as the issue's 0.63 s did).
The whole rotstar-detect run against the whole mrgingham run, decoding on
both sides, is given beside it (`command_vs_mrgingham`). Issue 13's goal:
reading the identity frames adds at most GOAL_IDENTITY to the detection
time per pose (median over poses of detect / detect without identity - 1).
"""

from __future__ import annotations

import contextlib
import cProfile
import dataclasses
import glob
import os
import pstats
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np
import cv2

from rotstar_mrcal.programs import run_tool
from rotstar_mrcal.detect.pipeline import detect_pose
from rotstar_mrcal import dataset

GOAL_RATIO = 2.0  # detect (start-up included) / decode
GOAL_VS_MRGINGHAM = 0.5  # rotstar-detect / mrgingham on the same images
GOAL_IDENTITY = 0.10  # detect / detect without the identity frames - 1


@dataclasses.dataclass
class PoseSpeed:
    pose: str
    decode_s: float  # CPU s, dataset.load_pose
    detect_s: float  # CPU s, detect_pose
    found: bool
    detect_plain_s: float | None = None  # CPU s, detect_pose without the identity frames (None: the pose has none)

    @property
    def ratio(self) -> float:
        return self.detect_s / self.decode_s

    @property
    def identity_share(self) -> float | None:
        """What the identity frames add to detect_pose, as a fraction of its time without them"""
        return self.detect_s / self.detect_plain_s - 1 if self.detect_plain_s else None


@dataclasses.dataclass
class SpeedResult:
    poses: list[PoseSpeed]
    command_s: float  # CPU s of one rotstar-detect process over the whole dataset
    mrgingham_s: float | None  # CPU s of one mrgingham process over the same images, None if not installed
    n_images: int  # PNG files read per run (all poses)
    repeats: int
    in_process_s: float | None = None  # CPU s of decode + detect of all poses in this process (fastest pass)

    @property
    def n(self) -> int:
        return len(self.poses)

    @property
    def decode_s(self) -> float:
        """median over poses"""
        return float(np.median([p.decode_s for p in self.poses]))

    @property
    def detect_s(self) -> float:
        """median over poses"""
        return float(np.median([p.detect_s for p in self.poses]))

    @property
    def ratio(self) -> float:
        """median over poses of detect / decode, start-up not included"""
        return float(np.median([p.ratio for p in self.poses]))

    @property
    def startup_s(self) -> float:
        """What the command spends beyond decoding and detecting: start-up, focal estimate, output"""
        work = self.in_process_s
        if work is None:
            work = sum(p.decode_s + p.detect_s for p in self.poses)
        return max(self.command_s - work, 0.0)

    @property
    def ratio_with_startup(self) -> float:
        """median over poses of (detect + start-up / poses) / decode"""
        s = self.startup_s / self.n
        return float(np.median([(p.detect_s + s) / p.decode_s for p in self.poses]))

    @property
    def detect_with_startup_s(self) -> float:
        """median over poses of detect + start-up / poses"""
        return float(np.median([p.detect_s for p in self.poses])) + self.startup_s / self.n

    @property
    def vs_mrgingham(self) -> float | None:
        """rotstar's detection (start-up share included) / mrgingham's time, per pose"""
        return self.detect_with_startup_s / (self.mrgingham_s / self.n) if self.mrgingham_s else None

    @property
    def identity_share(self) -> float | None:
        """median over poses of detect / detect without the identity frames - 1; None without identity frames"""
        v = [p.identity_share for p in self.poses if p.identity_share is not None]
        return float(np.median(v)) if v else None

    @property
    def command_vs_mrgingham(self) -> float | None:
        """the whole rotstar-detect run (decoding included) / the whole mrgingham run"""
        return self.command_s / self.mrgingham_s if self.mrgingham_s else None

    def goals(self) -> dict:
        out = {"ratio": {"goal": f"detection (start-up included) <= {GOAL_RATIO:g} x decoding",
                         "value": self.ratio_with_startup, "pass": bool(self.ratio_with_startup <= GOAL_RATIO)}}
        if self.vs_mrgingham is not None:
            out["mrgingham"] = {"goal": f"detection (start-up included) <= {GOAL_VS_MRGINGHAM:g} x mrgingham's time "
                                        "on the same images",
                                "value": self.vs_mrgingham, "pass": bool(self.vs_mrgingham <= GOAL_VS_MRGINGHAM)}
        if self.identity_share is not None:
            out["identity"] = {"goal": f"the identity frames add <= {GOAL_IDENTITY:.0%} to detection (detect / "
                                       "detect without them - 1, median per pose)",
                               "value": self.identity_share, "pass": bool(self.identity_share <= GOAL_IDENTITY)}
        return out

    def table(self) -> str:
        """Markdown: the per-pose medians, the command, mrgingham and the goals"""
        n, ipp = self.n, self.n_images / self.n
        mg = "-" if self.mrgingham_s is None else f"{self.mrgingham_s / n:.3f}"
        vs = "-" if self.vs_mrgingham is None else f"{self.vs_mrgingham:.2f}"
        cvs = "-" if self.command_vs_mrgingham is None else f"{self.command_vs_mrgingham:.2f}"
        lines = [
            "| per pose, CPU s on one core | decode | detect | detect / decode | start-up / poses "
            "| (detect + start-up) / decode | mrgingham | (detect + start-up) / mrgingham | rotstar-detect "
            "| rotstar-detect / mrgingham |",
            "|---|---|---|---|---|---|---|---|---|---|",
            f"| median of {n} poses ({ipp:.0f} PNGs each) | {self.decode_s:.3f} | {self.detect_s:.3f} "
            f"| {self.ratio:.2f} | {self.startup_s / n:.3f} | **{self.ratio_with_startup:.2f}** | {mg} | **{vs}** "
            f"| {self.command_s / n:.3f} | {cvs} |",
            "",
        ]
        for k, g in self.goals().items():
            v = f"{g['value']:+.1%}" if k == "identity" else f"{g['value']:.2f}"
            lines.append(f"- {g['goal']}: {v} -> **{'PASS' if g['pass'] else 'FAIL'}**")
        if self.identity_share is not None:
            plain = float(np.median([p.detect_plain_s for p in self.poses if p.detect_plain_s]))
            lines.append(f"- detect without the identity frames: {plain:.3f} s per pose (median), with them "
                         f"{self.detect_s:.3f} s")
        lines.append(f"- rotstar-detect's start-up and fixed cost (one process, {n} poses): {self.startup_s:.3f} s; "
                     f"the whole run {self.command_s:.2f} s, decoding included; slowest pose: decode "
                     f"{max(p.decode_s for p in self.poses):.3f} s, detect {max(p.detect_s for p in self.poses):.3f} s")
        return "\n".join(lines)

    def to_dict(self) -> dict:
        return {"poses": [dataclasses.asdict(p) | {"ratio": p.ratio} for p in self.poses],
                "command_s": self.command_s, "mrgingham_s": self.mrgingham_s, "n_images": self.n_images,
                "repeats": self.repeats, "in_process_s": self.in_process_s, "decode_s_median": self.decode_s, "detect_s_median": self.detect_s,
                "ratio_median": self.ratio, "startup_s": self.startup_s,
                "ratio_with_startup": self.ratio_with_startup, "detect_with_startup_s": self.detect_with_startup_s,
                "identity_share": self.identity_share,
                "vs_mrgingham": self.vs_mrgingham, "command_vs_mrgingham": self.command_vs_mrgingham,
                "goals": self.goals()}


@contextlib.contextmanager
def one_cpu():
    """Pin this process (and the children it starts) to one CPU with one OpenCV thread"""
    before, threads = os.sched_getaffinity(0), cv2.getNumThreads()
    cpu = min(before)
    os.sched_setaffinity(0, {cpu})
    cv2.setNumThreads(1)
    try:
        yield cpu
    finally:
        os.sched_setaffinity(0, before)
        cv2.setNumThreads(threads)


def _child_cpu() -> float:
    ch = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ch.ru_utime + ch.ru_stime


def _run_child(argv: list[str]) -> float:
    """CPU seconds (user + system) of one child process"""
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    c0 = _child_cpu()
    r = run_tool(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env)
    if r.returncode not in (0, 1):  # 1: no pose gave a board, still a complete run
        raise RuntimeError(f"{' '.join(argv[:3])} ... failed ({r.returncode}): {r.stderr.strip()[-300:]}")
    return _child_cpu() - c0


def detect_command() -> list[str]:
    """rotstar-detect as installed next to this Python, or python -m rotstar_mrcal.cli.detect"""
    exe = os.path.join(os.path.dirname(sys.executable), "rotstar-detect")
    return [exe] if os.access(exe, os.X_OK) else [sys.executable, "-m", "rotstar_mrcal.cli.detect"]


def measure_speed(seq: str, repeats: int = 3, mrgingham: bool = True, log=None) -> SpeedResult:
    """Time decoding and detection per pose, the command and mrgingham; see the module doc"""
    log = log or (lambda msg: None)
    pattern, layout = dataset.read_pattern(seq)
    frames = pattern["frames"]
    names = dataset.list_poses(seq, frames)
    if not names:
        raise ValueError(f"{seq}: no poses")
    images = sorted(glob.glob(os.path.join(glob.escape(seq), "*", "*.png")))
    with one_cpu():
        p = dataset.load_pose(seq, names[0], frames)
        detect_pose(p.rotstar, layout, full_scale=p.full_scale, identity=p.identity)  # warm-up
        t = np.full((repeats, len(names), 3), np.nan)  # (run, pose, decode | detect | detect without identity)
        found = []
        for k in range(repeats):  # whole passes over the poses, as the command makes one
            for i, name in enumerate(names):
                t0 = time.process_time()
                p = dataset.load_pose(seq, name, frames)
                t1 = time.process_time()
                r = detect_pose(p.rotstar, layout, full_scale=p.full_scale, identity=p.identity)
                t[k, i, :2] = t1 - t0, time.process_time() - t1
                if p.identity is not None:
                    t2 = time.process_time()
                    detect_pose(p.rotstar, layout, full_scale=p.full_scale)
                    t[k, i, 2] = time.process_time() - t2
                if k == 0:
                    found.append(r.found)
        med = np.median(t, axis=0)
        poses = [PoseSpeed(name, float(d), float(e), f, None if np.isnan(e0) else float(e0))
                 for name, (d, e, e0), f in zip(names, med, found)]
        in_process_s = float(t[..., :2].sum(axis=(1, 2)).min())
        log(f"  speed: decode + detect of {len(names)} poses in this process, {repeats} runs each")
        with tempfile.TemporaryDirectory(prefix="rotstar-speed-") as tmp:
            cmd = detect_command() + [seq, "-q", "--no-hint", "-o", os.path.join(tmp, "corners.vnl")]
            command_s = min(_run_child(cmd) for _ in range(repeats))
        log(f"  speed: rotstar-detect on {len(names)} poses, {repeats} runs")
        mg = None
        exe = shutil.which("mrgingham") if mrgingham else None
        if exe:
            # each path as a glob that matches only itself (mrgingham expands globs)
            args = [exe, "--jobs", "1"] + [re.sub(r"([*?\[\]])", r"[\1]", f) for f in images]
            mg = min(_run_child(args) for _ in range(repeats))
            log(f"  speed: mrgingham on the same {len(images)} images, {repeats} runs")
    return SpeedResult(poses, command_s, mg, len(images), repeats, in_process_s)


def profile_pose(seq: str, pose: str | None = None, top: int = 12, runs: int = 5) -> list[dict]:
    """The top entries of a cProfile of detect_pose on one pose, by own time, per call

    Each entry: function ('module.py:line(name)' or '{builtin}'), calls,
    own ms and cumulative ms per detect_pose call (the mean over `runs`).
    """
    pattern, layout = dataset.read_pattern(seq)
    pose = pose or dataset.list_poses(seq, pattern["frames"])[0]
    p = dataset.load_pose(seq, pose, pattern["frames"])
    with one_cpu():
        detect_pose(p.rotstar, layout, full_scale=p.full_scale, identity=p.identity)  # warm-up
        prof = cProfile.Profile()
        prof.enable()
        for _ in range(runs):
            detect_pose(p.rotstar, layout, full_scale=p.full_scale, identity=p.identity)
        prof.disable()
    st = pstats.Stats(prof).stats  # {(file, line, name): (cc, nc, tt, ct, callers)}
    rows = sorted(st.items(), key=lambda kv: -kv[1][2])[:top]
    out = []
    for (fn, line, name), (_, nc, tt, ct, _) in rows:
        if fn == "~":
            where = name
        else:
            parts = fn.replace(os.sep, "/").split("/")
            where = f"{'/'.join(parts[-2:])}:{line}({name})"
        out.append({"function": where, "calls": nc / runs, "own_ms": 1e3 * tt / runs, "cum_ms": 1e3 * ct / runs})
    return out


def profile_table(entries: list[dict]) -> str:
    lines = ["| function | calls | own ms | cumulative ms |", "|---|---|---|---|"]
    for e in entries:
        lines.append(f"| `{e['function']}` | {e['calls']:.0f} | {e['own_ms']:.1f} | {e['cum_ms']:.1f} |")
    return "\n".join(lines)


def write_dataset(folder: str, layout, poses: list[tuple], bits: int) -> str:
    """A dataset folder from in-memory captures: [(rotstar (8, H, W), checkerboard (H, W) or None[, identity])]

    identity: the identity frames (n, H, W) of a pose, or None. When a pose
    has none, the dataset's pattern.json lists none (the layout without
    identity frames), so that every pose holds every frame it lists. Frames
    are written as 8- or 16-bit PNGs (values rounded and clipped), one folder
    per pose named pose000, pose001, ...
    """
    poses = [tuple(p) + (None,) * (3 - len(p)) for p in poses]
    if any(p[2] is None for p in poses):
        layout = dataclasses.replace(layout, identity=False)
    dtype, top = (np.uint8, 255) if bits == 8 else (np.uint16, 65535)
    names = {f["kind"]: f["file"] for f in layout.frames() if f["kind"] == "checkerboard"}
    rot = [f["file"] for f in layout.frames() if f["kind"] == "rotstar"]
    ids = [f["file"] for f in layout.frames() if f["kind"] == "identity"]
    dataset.write_pattern(folder, layout)

    def q(a):
        return np.clip(np.round(a), 0, top).astype(dtype)

    for i, (frames, checker, identity) in enumerate(poses):
        imgs = {fn: q(f) for fn, f in zip(rot, frames)}
        if checker is not None and "checkerboard" in names:
            imgs[names["checkerboard"]] = q(checker)
        if ids:
            if len(identity) != len(ids):
                raise ValueError(f"pose {i}: {len(identity)} identity frames, the layout has {len(ids)}")
            imgs.update({fn: q(f) for fn, f in zip(ids, identity)})
        dataset.write_pose(folder, f"pose{i:03d}", imgs)
    return folder


def bench_speed(folder: str, layout, poses: list[tuple], bits: int,
                repeats: int = 3, log=None) -> tuple[str, dict]:
    """make bench's speed section: (Markdown, dict for bench.json)

    The benchmark's captures are written as a dataset (write_dataset), then
    measured (measure_speed) and one pose profiled (profile_pose).
    """
    log = log or (lambda msg: None)
    write_dataset(folder, layout, poses, bits)
    log(f"speed: {len(poses)} poses written as {bits}-bit PNGs; timing decode, detect, rotstar-detect, mrgingham")
    r = measure_speed(folder, repeats=repeats, log=log)
    prof = profile_pose(folder)
    md = "\n\n".join([
        f"Speed on one core ({len(poses)} poses, {bits}-bit PNGs; CPU seconds; per pose the median of {repeats} "
        f"runs, whole runs the fastest of {repeats}):",
        r.table(),
        "Profile of `detect_pose` on pose000 (cProfile, the top entries by own time, per call):",
        profile_table(prof),
    ])
    return md, {**r.to_dict(), "profile": prof}

"""Is rotstar-calibrate's default model as good as the command rotstar-detect prints? (simulated captures)

SYNOPSIS

    from rotstar_lab.modelcheck import run_case, table
    row = run_case("work", 12, seed=0, jobs=2)     # simulate, detect, calibrate three ways
    row["default"]["median_px"], row["printed"]["median_px"], row["ok"]
    print(table([row]))

For one simulated D435 capture of n poses (rotstar-simulate): rotstar-detect
writes the corners and prints the mrcal-calibrate-cameras command, which is
run as printed (the lean model); rotstar-calibrate runs with its defaults;
and, for reference, mrcal's splined model is forced on the same corners
(rotstar-calibrate's previous default). Each model is compared with the true
camera (truth.truth_error: the median and the worst error over the imager,
px, at infinity, after aligning the board poses). A default run passes when
its median is within 2x the better of the default and the printed command's
model, or when it exits non-zero with a reason.

Everything runs as the user runs it: the programs, in a work folder.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys

import mrcal
import numpy as np

from rotstar_mrcal.programs import run_tool
from rotstar_mrcal.evaluate.truth import truth_error, truth_poses_of
from rotstar_mrcal.simulate.dataset import load_truth

TOLERANCE = 2.0
"""A default model passes within this factor of the better of the two"""


def _tool(name: str) -> str:
    here = os.path.join(os.path.dirname(sys.executable), name)
    return here if os.path.exists(here) else name


def _run(argv, cwd, stdout=None) -> subprocess.CompletedProcess:
    return run_tool([_tool(argv[0]), *map(str, argv[1:])], cwd=cwd, text=True,
                          stdout=stdout if stdout is not None else subprocess.PIPE, stderr=subprocess.PIPE)


def printed_command(stderr: str) -> list[str]:
    """The mrcal-calibrate-cameras command rotstar-detect printed (argv)"""
    m = re.search(r"next, calibrate with:\n\s+(mrcal-calibrate-cameras .*)", stderr)
    if not m:
        raise RuntimeError("rotstar-detect printed no mrcal-calibrate-cameras command:\n" + stderr[-2000:])
    return shlex.split(m.group(1))


def vs_truth(model_path: str, seq: str) -> dict:
    """{'median_px', 'worst_px'} of a model against the dataset's true camera"""
    model = mrcal.cameramodel(model_path)
    t = load_truth(seq)
    e = truth_error(model, t.model, truth_poses_of(model, t.rt_cam_board))
    return {"median_px": float(e.median), "worst_px": float(np.nanmax(e.error)), "lensmodel": model.intrinsics()[0]}


def run_case(work: str, n: int, seed: int = 0, jobs: int = 1, log=print) -> dict:
    """Simulate n poses, detect, calibrate three ways; the row of the table (module doc)"""
    name = f"d435-{n}poses-seed{seed}"
    seq = os.path.join(work, name)
    if not os.path.exists(os.path.join(seq, "truth.json")):
        log(f"$ rotstar-simulate --out {seq} --poses {n} --seed {seed} --jobs {jobs}")
        r = _run(["rotstar-simulate", "--out", name, "--poses", n, "--seed", seed, "--jobs", jobs, "--force"], work)
        if r.returncode:
            raise RuntimeError(r.stderr[-2000:])
    vnl = os.path.join(name, "corners.vnl")
    log(f"$ rotstar-detect {name} --jobs {jobs} > {vnl}")
    with open(os.path.join(work, vnl), "w") as f:
        r = _run(["rotstar-detect", name, "--jobs", jobs, "--quiet"], work, stdout=f)
    if r.returncode:
        raise RuntimeError(r.stderr[-2000:])
    row = {"poses": n, "seed": seed, "boards": int(re.search(r"(\d+) of \d+ poses gave a board", r.stderr).group(1))}

    # 1. the printed command, verbatim, where the user would run it (it writes to --outdir .)
    cmd = printed_command(r.stderr)
    log("$ " + shlex.join(cmd))
    written = os.path.join(work, "camera-0.cameramodel")
    if os.path.exists(written):
        os.remove(written)
    p = _run(cmd, work)
    pdir = os.path.join(work, f"{name}-printed")
    if p.returncode == 0:
        os.makedirs(pdir, exist_ok=True)
        os.replace(written, os.path.join(pdir, "camera-0.cameramodel"))
        row["printed"] = vs_truth(os.path.join(pdir, "camera-0.cameramodel"), seq)
    else:
        row["printed"] = {"error": p.stderr.strip().splitlines()[-1]}
    row["printed"]["command"] = shlex.join(cmd)

    # 2. rotstar-calibrate with its defaults
    cdir = f"{name}-cal"
    log(f"$ rotstar-calibrate {name} --corners {vnl} --outdir {cdir}")
    c = _run(["rotstar-calibrate", name, "--corners", vnl, "--outdir", cdir], work)
    if c.returncode == 0:
        row["default"] = vs_truth(os.path.join(work, cdir, "camera-0.cameramodel"), seq)
    else:
        why = [x for x in c.stderr.splitlines() if "FAILED" in x or x.startswith("rotstar-calibrate: ")]
        row["default"] = {"error": (why[-1] if why else c.stderr.strip().splitlines()[-1]), "exit": c.returncode}
    row["default"]["reason"] = next((x.split("model: ", 1)[1] for x in c.stderr.splitlines()
                                     if x.startswith("rotstar-calibrate: model: ")), "")

    # 3. the splined model forced on the same corners (the previous default)
    sdir = f"{name}-splined"
    log(f"$ rotstar-calibrate {name} --corners {vnl} --outdir {sdir} --lensmodel splined --force --keep")
    s = _run(["rotstar-calibrate", name, "--corners", vnl, "--outdir", sdir, "--lensmodel", "splined", "--force",
              "--keep"], work)
    row["splined"] = (vs_truth(os.path.join(work, sdir, "camera-0.cameramodel"), seq) if s.returncode == 0
                      else {"error": s.stderr.strip().splitlines()[-1]})

    d, pr = row["default"], row["printed"]
    if "median_px" in d and "median_px" in pr:
        row["ok"] = d["median_px"] <= TOLERANCE * min(d["median_px"], pr["median_px"])
    else:
        row["ok"] = "error" in d  # a non-zero exit with a reason passes; a missing printed model does not count
    return row


def _cell(d: dict) -> str:
    if "median_px" not in d:
        return "exit " + str(d.get("exit", "")) + ": " + d.get("error", "?")
    return f"{d['median_px']:.4f} / {d['worst_px']:.3f}"


def table(rows) -> str:
    """The Markdown table of run_case rows"""
    out = ["| poses (boards) | rotstar-calibrate default: model | default vs truth, px: median / worst | "
           "rotstar-detect's printed command (OPENCV8) vs truth | splined, forced (the old default) vs truth | "
           f"default within {TOLERANCE:g}x the better |",
           "|---|---|---|---|---|---|"]
    for r in rows:
        d = r["default"]
        out.append(f"| {r['poses']} ({r['boards']}) | {d.get('lensmodel', '-').replace('LENSMODEL_', '')} | "
                   f"{_cell(d)} | {_cell(r['printed'])} | {_cell(r['splined'])} | {'yes' if r['ok'] else 'NO'} |")
    out.append("")
    out += [f"- {r['poses']} poses, rotstar-calibrate's reason: {r['default'].get('reason') or '-'}" for r in rows]
    return "\n".join(out)

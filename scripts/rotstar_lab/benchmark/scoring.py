"""A returned board against the truth: status, per-pose rows, summaries and the goals

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_lab.benchmark.scoring import score_board, pose_row, summarize
    >>> truth = np.stack(np.meshgrid(np.arange(4.0) * 20, np.arange(3.0) * 20), axis=-1)   # (3, 4, 2)
    >>> score_board(truth[::-1, ::-1] + 0.1, truth, relabel=True)[0]      # a half turn, relabelled
    'ok'
    >>> score_board(truth[::-1, ::-1] + 0.1, truth, relabel=False)[0]     # labelled by the method: wrong
    'mislabelled'
    >>> status, q = score_board(truth + 0.1, truth, relabel=False)
    >>> row = pose_row(0, status, q, truth, "", cpu=0.5, wall=0.6)
    >>> row["complete"], round(row["rms_px"], 4)
    (True, 0.1414)
    >>> s = summarize([row], n_board=12)
    >>> s["complete"], s["corners"], s["cpu_seconds_median"]
    (1, 12, 0.5)

A method that numbers its board from whichever corner it likes (relabel) is
relabelled by match_to_reference: the grid symmetry that puts every corner
within MATCH_PX of its true corner. A returned board is 'ok' if every corner
lies within MATCH_PX of its own true corner; otherwise 'mislabelled' (some
corner nearer another true corner than its own: a flipped, turned or shifted
grid) or 'outlier' (labelled right, a corner more than MATCH_PX off). A wrong
board is a failure, never an error value. A pose is complete when its board
is ok and has all its corners.
"""

from __future__ import annotations

import numpy as np

from rotstar_mrcal.peers.checkerboard import match_to_reference
from rotstar_mrcal.peers.registry import METHODS

MATCH_PX = 3.0  # a returned corner farther than this from its true corner makes the board wrong
START_PERTURB_PX = 0.5  # the refiners that start from rotstar start this far from its corners
GOAL_RATIO = 0.5  # rotstar's RMS at most this times the best baseline's
GOAL_SECONDS = 0.5  # rotstar's CPU time per pose on one core


def perturbed_start(corners: np.ndarray | None, seed: int, i: int) -> np.ndarray | None:
    """rotstar's labelled corners of pose i, each moved START_PERTURB_PX in a random direction

    >>> q = perturbed_start(np.zeros((2, 3, 2)), 0, 1)
    >>> np.allclose(np.linalg.norm(q, axis=-1), START_PERTURB_PX)
    True
    """
    if corners is None:
        return None
    phi = np.random.default_rng([2, seed, i]).uniform(0, 2 * np.pi, corners.shape[:-1])
    return corners + START_PERTURB_PX * np.stack((np.cos(phi), np.sin(phi)), axis=-1)


def score_board(corners, truth: np.ndarray, relabel: bool) -> tuple[str, np.ndarray | None]:
    """('ok' | 'not found' | 'mislabelled' | 'outlier', corners in the truth's labelling); see the module doc

    relabel: take the grid symmetry that puts every corner within MATCH_PX of
    the truth, or failing that the closest one, to say what went wrong.
    """
    if corners is None:
        return "not found", None
    c = np.asarray(corners, float)
    if relabel:
        m = match_to_reference(c, truth, MATCH_PX)
        if m is None:
            m = match_to_reference(c, truth, np.inf)
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
    """One method on pose i: status, corner errors (ok boards only), CPU and wall seconds"""
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
    """One method over all poses: counts by status, pooled corner errors, median and max seconds"""
    e = np.concatenate([r["errors_px"] for r in rows]) if rows else np.empty(0)
    cpu = np.array([r["cpu_seconds"] for r in rows])
    wall = np.array([r["wall_seconds"] for r in rows])

    def count(s):
        return sum(r["status"] == s for r in rows)

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


def _rms(rows) -> float:
    e = np.concatenate([r["errors_px"] for r in rows]) if rows else np.empty(0)
    return float(np.sqrt(np.mean(e**2))) if e.size else np.nan


def goals(summary: dict[str, dict], results: dict[str, list[dict]], titles: dict[str, str],
          standalone: set[str]) -> dict:
    """The accuracy goal (against the best baseline, and the best that finds the board itself) and the speed goal

    summary, results: by method name, rotstar's under 'rotstar'; titles: the
    names for the text; standalone: the methods that find the board by themselves.

    >>> rows = {"rotstar": [{"status": "ok", "errors_px": [0.01], "n_corners": 1}],
    ...         "b": [{"status": "ok", "errors_px": [0.04], "n_corners": 1}]}
    >>> s = {"rotstar": {"rms_px": 0.01, "cpu_seconds_median": 0.3, "cpu_seconds_max": 0.4,
    ...                  "wall_seconds_median": 0.3}, "b": {"rms_px": 0.04}}
    >>> g = goals(s, rows, {"b": "B"}, {"b"})
    >>> g["accuracy"]["ratio"], g["accuracy"]["pass"], g["speed"]["pass"]
    (0.25, True, True)
    """
    base = {k: s["rms_px"] for k, s in summary.items() if k != "rotstar" and s["rms_px"] is not None
            and (k not in METHODS or METHODS[k].peer)}  # the baselines: the peers, not rotstar's own variants
    rot = summary["rotstar"]
    out = {}
    if base and rot["rms_px"] is not None:
        best = min(base, key=base.get)
        ratio = rot["rms_px"] / base[best]
        # the same comparison on the poses both got right (the easy poses favour a method that fails the hard ones)
        both = [(a, b) for a, b in zip(results["rotstar"], results[best]) if a["status"] == b["status"] == "ok"]
        paired = _rms([a for a, _ in both]) / _rms([b for _, b in both]) if both else None
        out["accuracy"] = {"goal": f"rotstar corner RMS <= {GOAL_RATIO:g} x the best baseline's RMS",
                           "best_baseline": titles[best], "rotstar_rms_px": rot["rms_px"],
                           "baseline_rms_px": base[best], "ratio": ratio, "pass": bool(ratio <= GOAL_RATIO),
                           "paired_poses": len(both), "paired_ratio": paired}
    alone = {k: v for k, v in base.items() if k in standalone}
    if alone and rot["rms_px"] is not None:
        best = min(alone, key=alone.get)
        out["accuracy_standalone"] = {
            "goal": "the same against the best detector that finds the board by itself (no start from rotstar)",
            "best_baseline": titles[best], "baseline_rms_px": alone[best],
            "ratio": rot["rms_px"] / alone[best], "pass": bool(rot["rms_px"] / alone[best] <= GOAL_RATIO)}
    n = int(np.median([r["n_corners"] for r in results["rotstar"]])) if results["rotstar"] else 0
    out["speed"] = {"goal": f"rotstar detection of one 8-frame 1280x800 pose (~126 corners) < {GOAL_SECONDS:g} s "
                            "on one core",
                    "measure": "CPU time of one detect_pose call on one pinned CPU, one thread",
                    "median_s": rot["cpu_seconds_median"], "max_s": rot["cpu_seconds_max"],
                    "wall_median_s": rot["wall_seconds_median"], "median_corners": n,
                    "pass": bool(rot["cpu_seconds_median"] < GOAL_SECONDS)}
    return out

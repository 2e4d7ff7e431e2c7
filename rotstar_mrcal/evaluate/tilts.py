"""The tilt of a board from its true pose, and the held-out error grouped by the tilt of the test poses

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.evaluate.tilts import tilt_deg, by_tilt
    >>> rt = np.array([[0, 0, 0, 0, 0, 1.0], [0, np.radians(30), 0, 0, 0, 1.0]])
    >>> tilt_deg(rt, (0.0, 0.0, 0.0)).round(6).tolist()
    [0.0, 30.0]
    >>> ho = {"A->B": {"per_pose": {"p0": 0.1, "p1": 0.3}, "tilt_deg": {"p0": 0.4, "p1": 29.2}},
    ...       "B->A": {"per_pose": {"p0": 0.2, "p1": None}, "tilt_deg": {"p0": 1.1, "p1": 30.3}}}
    >>> {k: round(v, 3) for k, v in by_tilt(ho).items()}
    {0: 0.15, 30: 0.3}

The paper's real-world table reports the held-out error by the tilt of the
test poses (0 to 60 degrees): the star pattern should suffer at large tilt.
A pose's tilt is the angle between the board's normal and the line of sight
to its centre (simulate.look_at_pose's tilt), from the truth of simulated
data. rotstar-crossval writes it per test pose beside the per-pose held-out
error (heldout -> "A->B" -> tilt_deg); by_tilt pools both directions' test
poses into bins of STEP degrees (mean per-pose MRE of the poses in a bin).
"""

from __future__ import annotations

import math

import mrcal
import numpy as np

STEP = 10  # tilt bins, degrees


def tilt_deg(rt_cam_board, centre_board) -> np.ndarray:
    """(...,) the angle between the board normal and the line of sight to board point centre_board, degrees"""
    rt = np.asarray(rt_cam_board, float)
    normal = mrcal.rotate_point_r(rt[..., :3], np.array((0.0, 0.0, 1.0)))
    c = mrcal.transform_point_rt(rt, np.asarray(centre_board, float))
    cos = np.abs(np.sum(normal * c, axis=-1)) / np.linalg.norm(c, axis=-1)
    return np.degrees(np.arccos(np.clip(cos, 0.0, 1.0)))


def tilts_of(rt_by_pose: dict, names, centre_board) -> dict:
    """{pose name: tilt in degrees} of the named poses whose true pose is known"""
    known = [n for n in names if rt_by_pose.get(n) is not None and np.ndim(rt_by_pose[n]) == 1]
    if not known:
        return {}
    t = tilt_deg(np.array([rt_by_pose[n] for n in known]), centre_board)
    return {n: float(v) for n, v in zip(known, t)}


def by_tilt(heldout: dict, step: int = STEP) -> dict[int, float]:
    """{tilt bin, degrees: mean held-out MRE of the test poses in it} over both directions; {} without tilts"""
    pooled: dict[int, list] = {}
    for d in (heldout or {}).values():
        tilts, errs = (d or {}).get("tilt_deg") or {}, (d or {}).get("per_pose") or {}
        for name, t in tilts.items():
            e = errs.get(name)
            if e is not None and math.isfinite(e):
                pooled.setdefault(int(step * round(t / step)), []).append(e)
    return {k: float(np.mean(pooled[k])) for k in sorted(pooled)}

"""The experiment's table: one row per configuration, pattern and refiner; the mean over tilts

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.synth.experiment import quick_protocol
    >>> from rotstar_mrcal.synth.table import tabulate, over_tilts, markdown
    >>> p = quick_protocol(aberrations=("coma",), noises=(1.0,), phis_deg=(30,), alphas_deg=(0, 90),
    ...                    repeats=2, patterns=("rotstar",), refiners=("symmetric",))
    >>> det = np.zeros((2, 2, 1, 1, 2), np.float32) + p.truth    # perfect detections
    >>> res = {("coma", 1.0, 30): {"detections": det, "truth": p.truth,
    ...                           "fisher": np.tile(np.eye(2) * 1e4, (2, 1, 1, 1))}}
    >>> row = tabulate(p, res)[0]
    >>> row["range"], row["rms"], round(row["bound"], 4)
    (0.0, 0.0, 0.0141)
    >>> print(markdown(over_tilts(tabulate(p, res))).splitlines()[2])
    | coma | 1 | rotstar | symmetric | 0.0000 | 0.0000 | 0.0000 | 0.0000 | 0.0141 | 0.00 | 0.00 | 0 |

Columns (pixels unless said):

- range: the pairwise-distance range (metrics.pairwise_range) over the views
  of one tilt, averaged over the repeats: the paper's metric;
- rms: 2-D RMS error against the truth, all views and repeats;
- bias: RMS over views of |mean over repeats - truth| (the part of rms the
  noise does not cause; under Seidel coma it includes the comet's offset
  from the paraxial image point);
- scatter: RMS over views of the spread over repeats (the part of rms the
  noise and the start cause), sqrt(mean_v sum_xy var_r) (unbiased variance
  over the repeats);
- bound: the Cramer-Rao bound on the 2-D RMS error at this noise level, RMS
  over views (0 without noise);
- rms/bound, scatter/bound: the issue asks for rms / bound; the bound holds
  for unbiased estimators, so scatter / bound (>= 1 up to the sampling of 50
  repeats) is the efficiency and rms / bound also counts the bias;
- fail: fraction of detections that failed.

over_tilts averages the rows of every (aberration, noise, pattern, refiner)
over the tilts: range, rms and scatter as means (rms and scatter as root mean
squares), bound as an RMS.

A refiner that does not apply to a pattern (refiners.applies: the phase
refiner and the fringes, the wedge refiners and the stars) has no row; grid
shows the pattern x refiner structure with those cells "n/a":

    >>> g = grid([dict(aberration="coma", noise=0.0, pattern="rotstar", refiner="symmetric", range=0.03, fail=0.0),
    ...           dict(aberration="coma", noise=0.0, pattern="phase", refiner="phase", range=0.1, fail=0.0)], 0.0)
    >>> print(g.splitlines()[3])
    | coma | phase | n/a | 0.1000 |
"""

from __future__ import annotations

import json
import math
import warnings

import numpy as np

from rotstar_mrcal.optics.crlb import crlb_rms
from rotstar_mrcal.synth.metrics import failure_rate, pairwise_range, rms_error
from rotstar_mrcal.synth.refiners import applies

COLUMNS = ("aberration", "noise", "phi", "pattern", "refiner", "range", "rms", "bias", "scatter", "bound",
           "rms_over_bound", "scatter_over_bound", "fail")


def _ratio(a, b):
    return a / b if b > 0 and math.isfinite(a) else float("nan")


def tabulate(protocol, results: dict) -> list[dict]:
    """Rows for every (aberration, noise, phi) of `results` (sweep.run_sweep), pattern and refiner"""
    rows = []
    for (a, noise, phi), res in sorted(results.items(), key=lambda kv: (kv[0][0], kv[0][1], kv[0][2])):
        det, truth, fisher = res["detections"].astype(float), res["truth"], res["fisher"]
        for j, pat in enumerate(protocol.patterns):
            b = float(noise) * float(np.sqrt(np.mean(crlb_rms(fisher[:, j]) ** 2)))
            for i, ref in enumerate(protocol.refiners):
                if not applies(pat, ref):
                    continue  # n/a
                x = det[:, :, j, i]  # (R, V, 2)
                with np.errstate(invalid="ignore"), _quiet():
                    rng = float(np.nanmean(pairwise_range(x))) if np.isfinite(pairwise_range(x)).any() else float("nan")
                    mean_v = np.nanmean(x, axis=0)
                    bias = float(np.sqrt(np.nanmean(np.sum((mean_v - truth) ** 2, axis=-1))))
                    scatter = float(np.sqrt(np.nanmean(np.sum(np.nanvar(x, axis=0, ddof=1), axis=-1))))
                rms = rms_error(x, truth)
                rows.append(dict(aberration=a, noise=float(noise), phi=float(phi), pattern=pat, refiner=ref,
                                 range=rng, rms=rms, bias=bias, scatter=scatter, bound=b,
                                 rms_over_bound=_ratio(rms, b), scatter_over_bound=_ratio(scatter, b),
                                 fail=failure_rate(x)))
    return rows


class _quiet:
    """Silence numpy's 'mean of empty slice' warnings (all-NaN columns are expected: failures)"""

    def __enter__(self):
        self._w = warnings.catch_warnings()
        self._w.__enter__()
        warnings.simplefilter("ignore", RuntimeWarning)

    def __exit__(self, *exc):
        return self._w.__exit__(*exc)


def over_tilts(rows: list[dict]) -> list[dict]:
    """Rows averaged over phi, one per (aberration, noise, pattern, refiner), in first-seen order"""
    groups: dict = {}
    for r in rows:
        groups.setdefault((r["aberration"], r["noise"], r["pattern"], r["refiner"]), []).append(r)
    out = []
    for (a, n, pat, ref), g in groups.items():
        def col(name):
            return np.array([r[name] for r in g], float)

        with _quiet():
            rms = float(np.sqrt(np.nanmean(col("rms") ** 2)))
            scatter = float(np.sqrt(np.nanmean(col("scatter") ** 2)))
            bound = float(np.sqrt(np.mean(col("bound") ** 2)))
            out.append(dict(aberration=a, noise=n, phi="all", pattern=pat, refiner=ref,
                            range=float(np.nanmean(col("range"))), rms=rms,
                            bias=float(np.sqrt(np.nanmean(col("bias") ** 2))), scatter=scatter, bound=bound,
                            rms_over_bound=_ratio(rms, bound), scatter_over_bound=_ratio(scatter, bound),
                            fail=float(np.mean(col("fail")))))
    return out


def lookup(rows: list[dict], **key) -> dict | None:
    """The first row matching every key=value"""
    for r in rows:
        if all(r[k] == v for k, v in key.items()):
            return r
    return None


def _fmt(v, digits=4):
    if isinstance(v, str):
        return v
    if v is None or not math.isfinite(v):
        return "n/a"
    return f"{v:.{digits}f}"


def markdown(rows: list[dict], with_phi: bool = False) -> str:
    """A Markdown table of rows (tabulate or over_tilts)"""
    head = ["aberration", "sigma_n"] + (["phi"] if with_phi else []) + [
        "pattern", "refiner", "range", "rms", "bias", "scatter", "bound", "rms/bound", "scatter/bound", "fail %"]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    for r in rows:
        cells = [r["aberration"], f"{r['noise']:g}"] + ([f"{r['phi']:g}"] if with_phi else []) + [
            r["pattern"], r["refiner"], _fmt(r["range"]), _fmt(r["rms"]), _fmt(r["bias"]), _fmt(r["scatter"]),
            _fmt(r["bound"]), _fmt(r["rms_over_bound"], 2), _fmt(r["scatter_over_bound"], 2),
            f"{100 * r['fail']:.0f}" if math.isfinite(r["fail"]) else "n/a"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def grid(mean_rows: list[dict], noise: float) -> str:
    """Markdown: mean range (px) per (aberration, pattern) row and refiner column at one noise level

    "n/a" where the refiner does not apply to the pattern (no row for it),
    "fails (N%)" where more than half of its detections failed.
    """
    rows = [r for r in mean_rows if r["noise"] == noise]
    if not rows:
        return "(no pattern-refiner pair that applies)\n"
    refs = list(dict.fromkeys(r["refiner"] for r in rows))
    cell = {(r["aberration"], r["pattern"], r["refiner"]): r for r in rows}
    keys = list(dict.fromkeys((r["aberration"], r["pattern"]) for r in rows))
    lines = ["| aberration | pattern | " + " | ".join(refs) + " |", "|---|---|" + "---|" * len(refs)]
    for a, pat in keys:
        cells = []
        for ref in refs:
            r = cell.get((a, pat, ref))
            if r is None:
                cells.append("n/a")
            elif math.isfinite(r["fail"]) and r["fail"] > 0.5:
                cells.append(f"fails ({100 * r['fail']:.0f}%)")
            else:
                cells.append(_fmt(r["range"]))
        lines.append(f"| {a} | {pat} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def to_json(protocol, rows: list[dict], mean_rows: list[dict]) -> str:
    """The table as JSON (NaN -> null)"""
    def clean(r):
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in r.items()}

    return json.dumps({"format": "rotstar-synth/1", "protocol": protocol.to_dict(),
                       "columns": list(COLUMNS), "rows": [clean(r) for r in rows],
                       "over_tilts": [clean(r) for r in mean_rows]}, indent=1, default=list) + "\n"

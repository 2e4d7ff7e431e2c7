"""Does a run reproduce the paper's three findings (4.1)? Decided from the table, not by hand

SYNOPSIS

    >>> from rotstar_mrcal.synth.verdicts import verdicts
    >>> rows = [dict(aberration=a, noise=0.0, pattern=p, refiner=r, range=v * k)
    ...         for a, k in (("spherical", 1.0), ("coma", 10.0))
    ...         for p in ("checkerboard", "rotstar") for r, v in (("opencv", 0.02), ("saddle", 0.03), ("symmetric", 0.01))]
    >>> v = verdicts(rows)
    >>> [x.status for x in v]
    ['reproduced', 'partly reproduced', 'reproduced']
    >>> v[1].checks[-1].text
    'asymmetric PSF, symmetric, sigma_n = 0: checkerboard 0.1000 px, rotstar 0.1000 px: improvement x1.0 (>= 1.5 needed)'

(In that made-up table coma multiplies every range by 10 and the rotating
star is no better than the checkerboard.)

The evidence is the mean pairwise-distance range over the tilts (table.
over_tilts) of every (aberration, noise, pattern, refiner). Aberrations are
grouped by PSF symmetry (experiment.SYMMETRIC: coma is asymmetric, the
others are point-symmetric); a group's range is the mean over its
aberrations. Each finding is a set of checks; the verdict is "reproduced"
if every check passes, "partly reproduced" if some do, "not reproduced" if
none do, "not testable" if the run lacks what the finding needs (each needs a
symmetric and an asymmetric PSF). Thresholds (module constants):

1. "In the noise-free case, the asymmetry of the PSF significantly affects
   the stability of the corner refinement algorithms." For every refiner on
   the checkerboard at sigma_n = 0: range(asymmetric) >= SIGNIFICANT x
   range(symmetric).
2. "Under symmetric PSFs, the rotating-star pattern performs almost
   equivalently to the averaged checkerboard images. In contrast, under
   asymmetric PSFs, it brings significant improvements for all algorithms."
   For every refiner and noise level: under the symmetric PSFs the ranges of
   rotstar and checkerboard are within a factor EQUIVALENT of each other or
   closer than EQUIVALENT_PX; under the asymmetric PSF range(checkerboard)
   >= IMPROVEMENT x range(rotstar).
3. "With a symmetric PSF, the saddle surface fitting method is more robust
   to noise than the gradient-based method. Otherwise, saddle surface
   fitting is worse. The proposed refinement algorithm achieves the best
   results under both types of PSFs." For the checkerboard and the rotating
   star at every noise level > 0: saddle < opencv under the symmetric PSFs,
   saddle > opencv under the asymmetric one; and at every noise level
   (including 0) symmetric <= min(opencv, saddle) + TIE_PX under both.

The paper's synthetic section makes no claim about phase shifting (it
compares the phase pattern only in its real experiment, 4.2), so the phase
pattern enters no verdict. phase_observation states, plainly labelled as
ours, how the phase-shift corner (phase refiner) compares with the rotating
star's symmetric refinement under the symmetric and the asymmetric PSFs,
from the same mean ranges:

    >>> rows += [dict(aberration=a, noise=0.0, pattern="phase", refiner="phase", range=v)
    ...          for a, v in (("spherical", 0.002), ("coma", 0.4))]
    >>> o = phase_observation(rows)
    >>> o.lines[0]
    'symmetric PSF, sigma_n = 0: phase 0.0020 px, rotstar (symmetric) 0.0100 px: phase x0.20'
    >>> o.conclusion
    'Under the symmetric PSF, noise-free, the phase-shift corner is more stable than the rotating star (x0.20 its range). Under the asymmetric PSF, noise-free, it is less stable (x4.00 its range).'

Cells without a number (a refiner that does not apply to a pattern, or a
pattern the run lacks) are skipped by every finding and by the observation.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from rotstar_mrcal.synth.experiment import SYMMETRIC

SIGNIFICANT = 2.0
EQUIVALENT = 1.5
EQUIVALENT_PX = 0.01
IMPROVEMENT = 1.5
TIE_PX = 0.001

CLAIMS = (
    "In the noise-free case, the asymmetry of the PSF significantly affects the stability of the corner "
    "refinement algorithms.",
    "Under symmetric PSFs, the rotating-star pattern performs almost equivalently to the averaged checkerboard "
    "images. In contrast, under asymmetric PSFs, it brings significant improvements for all algorithms.",
    "With a symmetric PSF, the saddle surface fitting method is more robust to noise than the gradient-based "
    "method. Otherwise, saddle surface fitting is worse. The proposed refinement algorithm achieves the best "
    "results under both types of PSFs.",
)


@dataclasses.dataclass
class Check:
    text: str
    passed: bool


@dataclasses.dataclass
class Verdict:
    finding: int
    claim: str
    status: str
    checks: list[Check]

    @property
    def score(self) -> str:
        return f"{sum(c.passed for c in self.checks)}/{len(self.checks)} checks"


def _status(checks: list[Check]) -> str:
    if not checks:
        return "not testable"
    n = sum(c.passed for c in checks)
    return "reproduced" if n == len(checks) else "partly reproduced" if n else "not reproduced"


class _Ranges:
    """Mean range of a PSF group (True: symmetric) for a noise level, pattern and refiner"""

    def __init__(self, rows):
        self.by = {}
        for r in rows:
            g = SYMMETRIC.get(r["aberration"], True)
            self.by.setdefault((g, r["noise"], r["pattern"], r["refiner"]), []).append(r["range"])
        self.noises = sorted({r["noise"] for r in rows})
        self.groups = {SYMMETRIC.get(r["aberration"], True) for r in rows}
        self.refiners = list(dict.fromkeys(r["refiner"] for r in rows))
        self.patterns = list(dict.fromkeys(r["pattern"] for r in rows))

    def __call__(self, sym, noise, pattern, refiner) -> float:
        v = [x for x in self.by.get((sym, noise, pattern, refiner), []) if x is not None and math.isfinite(x)]
        return float(np.mean(v)) if v else float("nan")


def _name(sym):
    return "symmetric PSF" if sym else "asymmetric PSF"


def finding1(R: _Ranges) -> list[Check]:
    if {True, False} - R.groups or 0.0 not in R.noises or "checkerboard" not in R.patterns:
        return []
    out = []
    for ref in R.refiners:
        s, a = R(True, 0.0, "checkerboard", ref), R(False, 0.0, "checkerboard", ref)
        if math.isfinite(s) and math.isfinite(a):
            out.append(Check(f"checkerboard, {ref}, sigma_n = 0: range {a:.4f} px (asymmetric) vs {s:.4f} px "
                             f"(symmetric), x{a / s:.1f} (>= {SIGNIFICANT:g} needed)", a >= SIGNIFICANT * s))
    return out


def finding2(R: _Ranges) -> list[Check]:
    if {True, False} - R.groups or {"checkerboard", "rotstar"} - set(R.patterns):
        return []
    out = []
    for sym in sorted(R.groups, reverse=True):
        for ref in R.refiners:
            for n in R.noises:
                c, r = R(sym, n, "checkerboard", ref), R(sym, n, "rotstar", ref)
                if not (math.isfinite(c) and math.isfinite(r)):
                    continue
                head = f"{_name(sym)}, {ref}, sigma_n = {n:g}: checkerboard {c:.4f} px, rotstar {r:.4f} px"
                if sym:
                    ok = abs(c - r) <= EQUIVALENT_PX or max(c, r) <= EQUIVALENT * min(c, r)
                    out.append(Check(f"{head}: equivalent (within x{EQUIVALENT:g} or {EQUIVALENT_PX:g} px)", ok))
                else:
                    out.append(Check(f"{head}: improvement x{c / r:.1f} (>= {IMPROVEMENT:g} needed)",
                                     c >= IMPROVEMENT * r))
    return out


def finding3(R: _Ranges) -> list[Check]:
    if {True, False} - R.groups:
        return []
    out = []
    pats = [p for p in ("checkerboard", "rotstar") if p in R.patterns]
    refs = set(R.refiners)
    for sym in sorted(R.groups, reverse=True):
        for pat in pats:
            for n in R.noises:
                o, s, m = (R(sym, n, pat, x) for x in ("opencv", "saddle", "symmetric"))
                head = f"{_name(sym)}, {pat}, sigma_n = {n:g}"
                if n > 0 and {"opencv", "saddle"} <= refs and math.isfinite(o) and math.isfinite(s):
                    if sym:
                        out.append(Check(f"{head}: saddle {s:.4f} < opencv {o:.4f}", s < o))
                    else:
                        out.append(Check(f"{head}: saddle {s:.4f} > opencv {o:.4f}", s > o))
                others = [x for x in (o, s) if math.isfinite(x)]
                if "symmetric" in refs and math.isfinite(m) and others:
                    out.append(Check(f"{head}: symmetric {m:.4f} best (others {', '.join(f'{x:.4f}' for x in others)})",
                                     m <= min(others) + TIE_PX))
    return out


OBSERVATION = ("Our observation, not a claim of the paper (its synthetic section makes none about phase "
               "shifting): the 4-step phase-shift corner against the rotating star with the symmetric refinement, "
               "by the same metric.")


@dataclasses.dataclass
class Observation:
    title: str
    lines: list[str]  # the numbers, one comparison each
    conclusion: str  # computed from them


def phase_observation(rows: list[dict]) -> Observation | None:
    """phase / phase against rotstar / symmetric, per PSF group and noise level; None if the run lacks either"""
    R = _Ranges(rows)
    lines, ratios = [], {}
    for sym in sorted(R.groups, reverse=True):
        for n in R.noises:
            ph, rs = R(sym, n, "phase", "phase"), R(sym, n, "rotstar", "symmetric")
            if not (math.isfinite(ph) and math.isfinite(rs)) or rs <= 0:
                continue
            lines.append(f"{_name(sym)}, sigma_n = {n:g}: phase {ph:.4f} px, rotstar (symmetric) {rs:.4f} px: "
                         f"phase x{ph / rs:.2f}")
            ratios.setdefault((sym, n > 0), []).append(ph / rs)
    if not lines:
        return None
    out = []
    for (sym, noisy), rs in ratios.items():
        lo, hi = min(rs), max(rs)
        span = f"x{lo:.2f}" if np.isclose(lo, hi, rtol=0.005) else f"x{lo:.2f}-{hi:.2f}"
        verb = "more stable" if hi < 1 else "less stable" if lo > 1 else "sometimes more, sometimes less stable"
        subject, than = ("it", "") if out else ("the phase-shift corner", " than the rotating star")
        when = "with noise" if noisy else "noise-free"
        out.append(f"Under the {_name(sym)}, {when}, {subject} is {verb}{than} ({span} its range).")
    return Observation(OBSERVATION, lines, " ".join(out))


def verdicts(rows: list[dict]) -> list[Verdict]:
    """The three findings' verdicts from rows of table.over_tilts"""
    R = _Ranges(rows)
    out = []
    for i, f in enumerate((finding1, finding2, finding3)):
        checks = f(R)
        out.append(Verdict(i + 1, CLAIMS[i], _status(checks), checks))
    return out


def markdown(vs: list[Verdict]) -> str:
    """The verdicts with their evidence, as Markdown"""
    lines = []
    for v in vs:
        lines += [f"### Finding {v.finding}: {v.status} ({v.score})", "", f"> {v.claim}", ""]
        lines += [f"- {'yes' if c.passed else 'NO '}: {c.text}" for c in v.checks] or ["- (nothing to check)"]
        lines.append("")
    return "\n".join(lines)


def observation_markdown(o: Observation | None) -> str:
    """The phase observation as Markdown ('' if the run has no phase pattern)"""
    if o is None:
        return ""
    return "\n".join(["## Phase shifting: our observation", "", o.title, "", o.conclusion, ""]
                     + [f"- {x}" for x in o.lines] + [""])

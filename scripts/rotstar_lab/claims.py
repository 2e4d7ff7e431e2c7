"""Does a run reproduce the paper's real-world findings (4.2)? Decided from the numbers, not by hand

SYNOPSIS

    >>> from rotstar_lab.claims import claims, short_lines
    >>> def m(name, ab, ba, tilt_err=None, truth=None, cv="consistent"):
    ...     t = tilt_err or (ab, ab, ab)
    ...     pose = {"A->B": {"mean_px": ab, "per_pose": dict(zip("pqr", t)), "tilt_deg": dict(zip("pqr", (0, 30, 60)))},
    ...             "B->A": {"mean_px": ba, "per_pose": dict(zip("pqr", t)), "tilt_deg": dict(zip("pqr", (0, 30, 60)))}}
    ...     return {"method": name, "heldout": pose, "crossval": {"verdict": cv},
    ...             "truth": {"A": {"median_px": truth or ab}, "B": {"median_px": truth or ab}}}
    >>> cond = lambda k: {"label": f"e{k}", "methods": [
    ...     m("rotstar", 0.02, 0.02), m("star", 0.03, 0.025, (0.025, 0.03, 0.06)),
    ...     m("phase-keep", 0.05 * k, 0.05 * k), m("saddle", 0.05, 0.05 * k),
    ...     m("cornersubpix", 0.04, 0.04)]}
    >>> v = claims([cond(1), cond(2), cond(3)])
    >>> [x.status for x in v]
    ['reproduced', 'reproduced', 'reproduced', 'not reproduced', 'partly reproduced', 'reproduced', 'reproduced', 'reproduced']
    >>> print(short_lines(v)[3])
    4. not reproduced (0/3 checks): phase shifting not hurt by overexposure, helped by more light (less noise)
    >>> v[3].checks[0].text
    'phase-keep: highest exposure (e3) 0.15 px vs lowest (e1) 0.05 px: x3.00 (<= 1 needed)'

(In that made-up run phase shifting gets worse with every exposure, and the
star is no more sensitive to exposure than rotstar.)

The input is the rotstar-crossval results of one run, one per exposure in
rising order: the first is the lowest exposure, the last the saturating one.
A method's held-out error in a condition is the mean of its two directions
(calibrated on A, tested on B and the reverse); by tilt, the per-pose
errors of the test poses pooled by tilt (tilts.by_tilt). The methods in the
paper's roles: OURS (rotstar), STAR (Schops et al.'s star, the symmetric
refinement), PHASE (4-step phase shifting fitting clipped values as they are,
the paper's pipeline; PHASE_REJECTING drops them), CHECKERBOARD (the
checkerboard refinements; SADDLE stands for MATLAB's, a saddle fit).

Each finding is a set of checks; the verdict is "reproduced" if every check
passes, "partly reproduced" if some do, "not reproduced" if none do, "not
testable" if the run lacks what it needs. Findings 1-6 are the paper's
sentences (CLAIMS); 7 and 8 say what the truth (simulated data) and mrcal's
cross-validation make of them. Thresholds (module constants): ALMOST (share
of (exposure, tilt) cells for "almost all"), CLOSE (factor for "close
to"), SIGNIFICANT (factor for "degraded significantly").
"""

from __future__ import annotations

import html as _html
import math

import numpy as np

from rotstar_mrcal.synth.verdicts import Check, Verdict
from rotstar_mrcal.evaluate.tilts import by_tilt
from rotstar_mrcal.report.page import Section, methods_of

OURS = "rotstar"
STAR = "star"
PHASE = "phase-keep"
PHASE_REJECTING = "phase"
CHECKERBOARD = ("cornersubpix", "saddle", "opencv-sb")
SADDLE = "saddle"
ALMOST = 0.8
CLOSE = 1.5
SIGNIFICANT = 1.5
LOW_TILT = 50  # "below 50 degrees"

CLAIMS = (
    "Our method achieved the best results at almost all tested positions, especially when the second group is "
    "used for test.",
    "The star-shaped pattern yielded results close to ours when the tilt angle in the first calibration group "
    "was below 50 degrees, and it clearly outperformed the checkerboard method.",
    "However, its performance degraded significantly at larger angles and on the second calibration group, "
    "which involves larger rotational angles along the z-axis.",
    "All patterns from 0 to 30 degrees exhibit a certain amount of overexposure. However, this does not "
    "significantly affect the calibration results of the phase-shifting method. In fact, the results are better "
    "than those under the lowest exposure. This can be understood as a result of the higher contrast and lower "
    "noise brought by high exposure, which is essential for phase-shifting.",
    "The most exposure-sensitive methods are the method of Schops et al. for star pattern and MATLAB for "
    "checkerboard.",
    "Proposed method shows the accuracy advantages over the single star-shaped pattern and the phase-shifted "
    "method, especially under varying exposure settings and large calibration board tilt angles (conclusion).",
    "(not the paper's) The true camera agrees with findings 1 and 2: rotstar's calibrations are the closest to "
    "it, and the star's closer than the checkerboard's.",
    "(not the paper's) mrcal's cross-validation finds rotstar's calibrations on A and on B consistent with their "
    "uncertainty.",
)
SHORT = (
    "rotstar lowest held-out error at almost all positions, especially tested on group B",
    "star close to rotstar below 50 degrees (group A) and better than the checkerboard",
    "star degrades at large tilt and on group B (strong roll)",
    "phase shifting not hurt by overexposure, helped by more light (less noise)",
    "star and the saddle fit (MATLAB) the most exposure-sensitive",
    "rotstar beats star and phase shifting at every exposure and at the largest tilt",
    "against the truth: rotstar closest, star closer than the checkerboard",
    "cross-validation: rotstar's A and B calibrations consistent",
)


def _status(checks: list[Check]) -> str:
    if not checks:
        return "not testable"
    n = sum(c.passed for c in checks)
    return "reproduced" if n == len(checks) else "partly reproduced" if n else "not reproduced"


def _px(v: float) -> str:
    return "not calibrated" if not math.isfinite(v) else f"{v:.3g} px"


def _lt(a: float, b: float) -> bool:
    return math.isfinite(a) and (a < b or not math.isfinite(b))


class _Run:
    """The numbers of one run: held-out error per (condition, method[, direction]), by tilt, truth, verdict"""

    def __init__(self, results):
        self.labels = [r["label"] for r in results]
        self.by = [{m["method"]: m for m in r["methods"]} for r in results]
        self.methods = list(dict.fromkeys(m for b in self.by for m in b))

    def has(self, *names) -> bool:
        return all(any(n in b for b in self.by) for n in names)

    def heldout(self, k: int, name: str, direction: str | None = None) -> float:
        h = (self.by[k].get(name) or {}).get("heldout") or {}
        v = [(h.get(d) or {}).get("mean_px") for d in ((direction,) if direction else ("A->B", "B->A"))]
        v = [x for x in v if x is not None and math.isfinite(x)]
        return float(np.mean(v)) if v and len(v) == (1 if direction else 2) else math.inf

    def tilt(self, k: int, name: str, directions=None) -> dict[int, float]:
        h = (self.by[k].get(name) or {}).get("heldout") or {}
        return by_tilt({d: v for d, v in h.items() if directions is None or d in directions})

    def truth(self, k: int, name: str) -> float:
        t = (self.by[k].get(name) or {}).get("truth") or {}
        v = [(t.get(s) or {}).get("median_px") for s in "AB"]
        return float(np.mean(v)) if all(x is not None and math.isfinite(x) for x in v) else math.inf

    def verdict(self, k: int, name: str) -> str:
        return ((self.by[k].get(name) or {}).get("crossval") or {}).get("verdict") or "not cross-validated"

    def rivals(self, k: int) -> list[str]:
        return [n for n in self.by[k] if not n.startswith(OURS)]


def finding1(R: _Run) -> list[Check]:
    if not R.has(OURS):
        return []
    out, cells, won = [], 0, 0
    for k, lab in enumerate(R.labels):
        ours = R.heldout(k, OURS)
        best = min(R.rivals(k), key=lambda n: R.heldout(k, n), default=None)
        if best is None:
            continue
        b = R.heldout(k, best)
        out.append(Check(f"{lab}: rotstar {_px(ours)}, best other {best} {_px(b)}", _lt(ours, b)))
        t_ours = R.tilt(k, OURS)
        for t, v in t_ours.items():
            cells += 1
            won += all(_lt(v, R.tilt(k, n).get(t, math.inf)) or v == R.tilt(k, n).get(t) for n in R.rivals(k))
    if cells:
        out.append(Check(f"lowest in {won} of {cells} (exposure, tilt) cells ({ALMOST:.0%} needed)",
                         won >= ALMOST * cells))
    margin = {}
    for d in ("A->B", "B->A"):
        r = [min((R.heldout(k, n, d) for n in R.rivals(k)), default=math.inf) / R.heldout(k, OURS, d)
             for k in range(len(R.labels))]
        r = [x for x in r if math.isfinite(x)]
        margin[d] = float(np.mean(r)) if r else math.nan
    if all(math.isfinite(v) for v in margin.values()):
        out.append(Check(f"best other / rotstar, tested on B: x{margin['A->B']:.2f}, tested on A: "
                         f"x{margin['B->A']:.2f} (mean over exposures; larger on B needed)",
                         margin["A->B"] > margin["B->A"]))
    return out


def finding2(R: _Run) -> list[Check]:
    cbs = [n for n in CHECKERBOARD if R.has(n)]
    if not (R.has(OURS, STAR) and cbs):
        return []
    out = []
    for k, lab in enumerate(R.labels):
        s, o = R.tilt(k, STAR, ("B->A",)), R.tilt(k, OURS, ("B->A",))
        low = [t for t in s if t < LOW_TILT and t in o]
        if low:
            ratio = max(s[t] / o[t] for t in low)
            out.append(Check(f"{lab}, tested on A below {LOW_TILT} deg: star / rotstar at most x{ratio:.2f} "
                             f"(<= {CLOSE} needed)", ratio <= CLOSE))
        st = R.heldout(k, STAR)
        cb = {n: R.heldout(k, n) for n in cbs}
        out.append(Check(f"{lab}: star {_px(st)} vs " + ", ".join(f"{n} {_px(v)}" for n, v in cb.items()),
                         all(_lt(st, v) for v in cb.values())))
    return out


def finding3(R: _Run) -> list[Check]:
    if not R.has(OURS, STAR):
        return []
    out = []
    for k, lab in enumerate(R.labels):
        s, o = R.tilt(k, STAR), R.tilt(k, OURS)
        if len(s) > 1 and min(s) in o and max(s) in o:
            lo, hi = min(s), max(s)
            gs, go = s[hi] / s[lo], o[hi] / o[lo]
            out.append(Check(f"{lab}: star at {hi} deg / at {lo} deg x{gs:.2f} (>= {SIGNIFICANT} needed), "
                             f"rotstar's x{go:.2f} (less needed)", gs >= SIGNIFICANT and gs > go))
        rb = R.heldout(k, STAR, "A->B") / R.heldout(k, OURS, "A->B")
        ra = R.heldout(k, STAR, "B->A") / R.heldout(k, OURS, "B->A")
        if math.isfinite(rb) and math.isfinite(ra):
            out.append(Check(f"{lab}: star / rotstar tested on B x{rb:.2f}, on A x{ra:.2f} (larger on B needed)",
                             rb > ra))
    return out


def finding4(R: _Run) -> list[Check]:
    if not R.has(PHASE) or len(R.labels) < 2:
        return []
    lo, sat = R.heldout(0, PHASE), R.heldout(len(R.labels) - 1, PHASE)
    mid = R.heldout(len(R.labels) - 2, PHASE)
    r, rm = sat / lo, sat / mid
    out = [Check(f"{PHASE}: highest exposure ({R.labels[-1]}) {_px(sat)} vs lowest ({R.labels[0]}) {_px(lo)}: "
                 f"x{r:.2f} (<= 1 needed)", math.isfinite(r) and r <= 1.0),
           Check(f"{PHASE}: highest vs middle exposure ({R.labels[-2]}) {_px(mid)}: x{rm:.2f} "
                 f"(<= {SIGNIFICANT} needed)", math.isfinite(rm) and rm <= SIGNIFICANT),
           Check(f"{PHASE}: more light, less noise: middle exposure {_px(mid)} vs lowest {_px(lo)} (lower needed)",
                 _lt(mid, lo))]
    return out


def _sensitivity(R: _Run, name: str) -> float:
    v = [R.heldout(k, name) for k in range(len(R.labels))]
    return max(v) / min(v) if all(math.isfinite(x) for x in v) and min(v) > 0 else math.inf


def finding5(R: _Run) -> list[Check]:
    if not R.has(STAR, SADDLE) or len(R.labels) < 2:
        return []
    names = [n for n in R.methods if n != PHASE_REJECTING and not (n.startswith(OURS) and n != OURS)]
    sens = {n: _sensitivity(R, n) for n in names}
    ranked = sorted(sens, key=lambda n: -sens[n] if math.isfinite(sens[n]) else math.inf)
    ranked = [n for n in ranked if math.isfinite(sens[n])]
    top = ranked[:2]
    txt = ", ".join(f"{n} x{sens[n]:.2f}" for n in ranked)
    return [Check(f"{n}: worst / best exposure x{sens[n]:.2f}; most sensitive first: {txt}", n in top)
            for n in (STAR, SADDLE)]


def finding6(R: _Run) -> list[Check]:
    rivals = [n for n in (STAR, PHASE) if R.has(n)]
    if not (R.has(OURS) and rivals):
        return []
    out = []
    for k, lab in enumerate(R.labels):
        o = R.heldout(k, OURS)
        v = {n: R.heldout(k, n) for n in rivals}
        out.append(Check(f"{lab}: rotstar {_px(o)} vs " + ", ".join(f"{n} {_px(x)}" for n, x in v.items()),
                         all(_lt(o, x) for x in v.values())))
        t = R.tilt(k, OURS)
        if t:
            hi = max(t)
            v = {n: R.tilt(k, n).get(hi, math.inf) for n in rivals}
            out.append(Check(f"{lab} at {hi} deg: rotstar {_px(t[hi])} vs "
                             + ", ".join(f"{n} {_px(x)}" for n, x in v.items()),
                             all(_lt(t[hi], x) for x in v.values())))
    return out


def finding7(R: _Run) -> list[Check]:
    cbs = [n for n in CHECKERBOARD if R.has(n)]
    if not (R.has(OURS, STAR) and cbs):
        return []
    out = []
    for k, lab in enumerate(R.labels):
        o, s = R.truth(k, OURS), R.truth(k, STAR)
        if not math.isfinite(o) and not math.isfinite(s):
            continue
        best = min(R.rivals(k), key=lambda n: R.truth(k, n))
        out.append(Check(f"{lab}, vs the true model: rotstar {_px(o)}, best other {best} {_px(R.truth(k, best))}",
                         _lt(o, R.truth(k, best))))
        cb = {n: R.truth(k, n) for n in cbs}
        out.append(Check(f"{lab}, vs the true model: star {_px(s)} vs "
                         + ", ".join(f"{n} {_px(v)}" for n, v in cb.items()), all(_lt(s, v) for v in cb.values())))
    return out


def finding8(R: _Run) -> list[Check]:
    if not R.has(OURS):
        return []
    out = []
    for k, lab in enumerate(R.labels):
        others = ", ".join(f"{n} {R.verdict(k, n)}" for n in R.by[k] if n != OURS)
        out.append(Check(f"{lab}: rotstar {R.verdict(k, OURS)} (others: {others})",
                         R.verdict(k, OURS) == "consistent"))
    return out


def claims(results) -> list[Verdict]:
    """The paper's real-world findings (and what the truth and cross-validation say), each with its checks"""
    R = _Run(results)
    fns = (finding1, finding2, finding3, finding4, finding5, finding6, finding7, finding8)
    return [Verdict(i + 1, CLAIMS[i], _status(c), c) for i, c in enumerate(f(R) for f in fns)]


def short_lines(verdicts) -> list[str]:
    """One line per finding: number, status, score, the claim in a few words"""
    return [f"{v.finding}. {v.status} ({v.score}): {SHORT[v.finding - 1]}" for v in verdicts]


def markdown(verdicts) -> str:
    """Every finding: the paper's sentence, the verdict, each check with its numbers"""
    out = []
    for v in verdicts:
        out += [f"{v.finding}. **{v.status}** ({v.score}). *{v.claim}*"]
        out += [f"   - {'yes' if c.passed else 'no'}: {c.text}" for c in v.checks]
    return "\n".join(out) + "\n"


def applies(results) -> bool:
    """Whether the run compares the paper's patterns (rotstar and the star or phase shifting)"""
    names = methods_of(results)
    return OURS in names and (STAR in names or PHASE in names)


def section(results) -> Section | None:
    """The report's section of the claims (rotstar_mrcal.report.page.Section): every claim with its checks in
    the page and paper.md, one line each under headline.md's verdicts; None when the run does not compare
    the paper's patterns"""
    if not applies(results):
        return None
    v = claims(results)
    md = "\n".join(["## The paper's real-world claims (4.2)", "",
                    "Each claim in the paper's words, decided from the numbers above (rotstar_lab.claims); "
                    "the lowest exposure first, the saturating one last.", "", markdown(v)])
    e = _html.escape
    out = ["<h2>The paper's real-world claims (4.2)</h2>", "<ol>"]
    for x in v:
        out += [f"<li><b>{e(x.status)}</b> ({e(x.score)}). <i>{e(x.claim)}</i><ul>"]
        out += [f"<li>{'yes' if c.passed else 'no'}: {e(c.text)}</li>" for c in x.checks] + ["</ul></li>"]
    out += ["</ol>"]
    head = "The paper's claims (4.2):\n\n" + "\n".join(short_lines(v)) + "\n"
    return Section(md, "\n".join(out), head)

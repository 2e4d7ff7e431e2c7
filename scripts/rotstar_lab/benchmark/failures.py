"""Each method's failure modes, measured: saturation, display gamma mismatch, tilt and roll, noise

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_lab.benchmark.failures import corner_stats, cell
    >>> s = corner_stats(np.array([0.1, 0.2, np.nan, 4.0]), ["", "", "saturated", ""])
    >>> s["in_view"], s["found"], s["wrong"], round(s["rms_px"], 4), s["rejected"]
    (4, 2, 1, 0.1581, {'saturated': 1})
    >>> cell(s)
    '0.158 / 0.195 (50%, 1 wrong)'

    units = make_units(npose=2, seed=0)            # what to render, and the exposures of each
    records = run_units(units, jobs=2, log=print)  # render, expose, detect: per (table, row, method) errors
    summary = summarize(records)
    print(tables_text(summary)); print(findings(summary))

The scene: the `d435` preset (1280x800, OPENCV8) with make demo's lens (a
field-dependent Seidel PSF, optics.LensPSF: coma 1.5 and field-curvature
focus 0.3 waves at the image corners, diffraction at F/2, 3 um pixels), the
default screen with the paper's sequence but no identity frames
(make_layout(identity=False, phase_period=150, star_segments=16)): the 8
rotating-star frames, the 4-step phase shifts along x and along y (8 frames),
the checkerboard and the 16-segment star. The screen shows 8-bit values
encoded for a display gamma of 2.2 (simulate.shown_light), decoded with the
screen's own gamma. Exposure: read noise 1% and shot noise 1e-4 per unit
signal (a 10000 e- full well), 16 bits, white at GAIN of full scale unless a
table varies it. One capture per rotating-star and phase frame (8 each); the
checkerboard and the star frame are the mean of CAPTURES = 8 captures (the
paper's fairness rule: every method gets 8 captures' worth of light).

Every method sees the same rendered images of a pose and condition:

    rotstar        METHODS['rotstar'] on the 8 frames (finds and labels its own board): the paper's fit
    rotstar, psf-sim  METHODS['rotstar-psf-sim']: that fit less its offset under the coma this pose's
                   edges show (rotstar-detect's default pools the coma over a dataset's poses)
    phase          METHODS['phase'] (detect.phase, clipped windows rejected)
    phase, keep    detect.phase.phase_corners(saturation='keep'): clipped samples used as they are
    star           METHODS['star'] (symmetric refinement on the one star frame)
    saddle         METHODS['saddle'] (Lucchese-Mitra on the averaged checkerboard)

The refiners (phase, star, saddle) start from the *true* corners moved
START_PERTURB_PX in a random direction, each in the refinement window
rotstar's rule gives the true element (simulate.visibility.true_windows),
not from rotstar's detection: a row measures the refiner's own failure, and
rotstar's row shows where its detection fails. The corners counted are those
in view (the window inside the image). A corner is *found* when it is
reported within MATCH_PX of its true place, *wrong* when reported farther,
*rejected* when the method returns none (with its reason where the method
gives one). RMS and 95th percentile of the error are over the found corners.

The conditions (each over `npose` poses):

    saturation   gains GAINS of full scale for white (above 1 the white clips)
    gamma        screens of gamma SCREEN_GAMMAS showing the pattern encoded for 2.2
    tilt         the board at the image centre, tilted TILTS degrees about an
                 axis at 90 k / npose degrees from the board's x (pose k), after
                 a roll of ROLLS degrees about its normal (the star's edges and the
                 checkerboard's cross the pixel grid at another angle), at the
                 smallest distance where the whole board fits (margin 20 px)
    noise        read noise and shot noise NOISES
"""

from __future__ import annotations

import collections
import dataclasses
import math
import time

import mrcal
import numpy as np

from rotstar_mrcal import simulate
from rotstar_mrcal.optics.psf import LensPSF
from rotstar_mrcal.optics.wavefront import Seidel
from rotstar_mrcal.simulate.camera import remember_rays
from rotstar_mrcal.peers.registry import METHODS, PoseImages
from rotstar_mrcal.parallel import process_map
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.simulate.captures import averaged_captures, lit_box
from rotstar_mrcal.simulate.visibility import in_view, true_windows
from rotstar_lab.benchmark.scoring import MATCH_PX, perturbed_start
from rotstar_mrcal.peers.phase import phase_corners

COMA, FOCUS = 1.5, 0.3  # waves at the image corners: make demo's lens (demo.scene.COMA_WAVES, FOCUS_WAVES)
ENCODED_GAMMA = 2.2  # the display gamma the pattern's 8-bit values are encoded for
GAIN, READ, SHOT = 0.9, 0.01, 1e-4  # the base exposure
GAINS = (0.7, 1.0, 1.2, 1.4)
SCREEN_GAMMAS = (1.8, 2.2, 2.4, 2.6)
TILTS = (0, 30, 45, 60, 70)
ROLLS = (0, 22.5, 45)
NOISES = ((0.01, 1e-4), (0.03, 1e-4), (0.01, 1e-3))  # (read noise, shot noise)
CAPTURES = 8
MARGIN_PX = 20.0
TABLES = {  # table: (title of its rows, methods)
    "saturation": ("gain", ("rotstar", "rotstar-psf-sim", "phase", "phase-keep", "star", "saddle")),
    "gamma": ("screen gamma", ("rotstar", "rotstar-psf-sim", "phase", "star")),
    "tilt": ("tilt, roll", ("rotstar", "rotstar-psf-sim", "star", "saddle")),
    "noise": ("read, shot noise", ("rotstar", "rotstar-psf-sim", "phase", "star", "saddle")),
}
TITLES = {"rotstar": "rotstar", "rotstar-psf-sim": "rotstar, psf-sim", "phase": "phase",
          "phase-keep": "phase, keep clipped", "star": "star", "saddle": "saddle"}


@dataclasses.dataclass(frozen=True)
class Exposure:
    table: str
    row: str
    gain: float = GAIN
    read: float = READ
    shot: float = SHOT


@dataclasses.dataclass(frozen=True)
class Unit:
    """One rendered pose and the exposures (table rows) taken of it"""

    index: int  # the pose's number (its noise)
    rt: tuple  # rt_cam_board
    screen_gamma: float
    frames: tuple  # the kinds of frame rendered: ('rotstar', 'phase', 'checkerboard', 'star')
    exposures: tuple  # (Exposure, ...)


def paper_layout(screen=None):
    """The default screen with the phase shifts and the star, no identity frames; screen=(W, H): a small one

        >>> [f["kind"] for f in paper_layout((800, 600)).frames()][7:10]
        ['rotstar', 'phase', 'phase']
    """
    kw = dict(phase_period=150) if screen is None else dict(screen=screen, pitch=100, band=24, phase_period=100)
    return make_layout(identity=False, star_segments=16, **kw)


def fitted_pose(model, layout, tilt_deg: float, roll_deg: float, axis_deg: float) -> np.ndarray:
    """rt_cam_board: the board at the image centre, tilted and rolled, at the smallest distance where it fits"""
    W, H = model.imagersize()
    c = ((W - 1) / 2, (H - 1) / 2)
    d = 0.5 * simulate.default_distance_range(model, layout)[0]
    for _ in range(200):
        rt = simulate.look_at_pose(model, layout, c, d, math.radians(tilt_deg), math.radians(axis_deg),
                                   math.radians(roll_deg))
        if simulate.pose_ok(model, layout, rt, MARGIN_PX):
            return rt
        d *= 1.03
    raise RuntimeError(f"no distance fits the board at tilt {tilt_deg} and roll {roll_deg} degrees")


def make_units(npose: int, seed: int, model=None, layout=None) -> list[Unit]:
    """Every pose to render with its screen gamma and exposures (see the module doc)"""
    model = simulate.preset_model("d435") if model is None else model
    layout = paper_layout() if layout is None else layout
    rts = simulate.random_poses(model, layout, npose, np.random.default_rng([3, seed]))
    allf, binary = ("rotstar", "phase", "checkerboard", "star"), ("rotstar", "checkerboard", "star")
    base = (tuple(Exposure("saturation", f"{g:g}", gain=g) for g in GAINS)
            + tuple(Exposure("noise", f"{r:g}, {s:g}", read=r, shot=s) for r, s in NOISES))
    units = []
    for g in SCREEN_GAMMAS:
        ex = (Exposure("gamma", f"{g:g}"),) + (base if g == ENCODED_GAMMA else ())
        units += [Unit(i, tuple(rts[i]), g, allf, ex) for i in range(npose)]
    k = 0
    for t in TILTS:
        for r in ROLLS:
            for i in range(npose):
                rt = fitted_pose(model, layout, t, r, 90.0 * i / npose)
                units.append(Unit(1000 + k, tuple(rt), ENCODED_GAMMA, binary, (Exposure("tilt", f"{t:g}, {r:g}"),)))
                k += 1
    return units


# ---- one unit, in this process or a worker -------------------------------------------------------
_W: dict = {}


def _init(model_args, layout, rays, seed: int, psf=None) -> None:
    model = mrcal.cameramodel(intrinsics=model_args[0], imagersize=model_args[1])
    remember_rays(model, rays)
    _W.clear()
    _W.update(model=model, layout=layout, seed=seed,
              psf=LensPSF(Seidel(coma=COMA, focus=FOCUS), model.imagersize()) if psf is None else psf)


def _screen(gamma: float, kinds: tuple):
    """The screen of these frame kinds shown with this gamma (the last one kept: units come sorted)"""
    key = (gamma, kinds)
    if _W.get("screen_key") != key:
        _W.pop("screen", None)
        layout = _W["layout"]
        fr = [f for f in layout.frames() if f["kind"] in kinds]
        light = simulate.shown_light(simulate.exact_frames(layout, fr), ENCODED_GAMMA, gamma)
        _W.update(screen=simulate.make_screen(light, layout), screen_key=key, kinds=[f["kind"] for f in fr])
    return _W["screen"], _W["kinds"]


def _found(name: str, q: PoseImages):
    """(corners (ny, nx, 2) or None, per-corner reasons or None, why)"""
    if name == "phase-keep":
        r = phase_corners(q.phase, q.start, q.layout.corner_phase(), q.full_scale, saturation="keep")
        return r.corners, r.reason, ""
    f = METHODS[name](q)
    reasons = f.reasons
    if name == "rotstar" and q.detection is not None:
        reasons = q.detection.reasons
    return f.corners, reasons, f.why


def corner_errors(corners, reasons, why: str, truth: np.ndarray, view: np.ndarray):
    """(errors px of the in-view corners, NaN = none; their reasons, '' where reported)

    A missing corner's reason: the method's own for that corner, else `why` (no board), else
    'no fit or moved out of its window' (the refiners that say no more).

        >>> t = np.zeros((1, 3, 2)); view = np.array([[True, True, False]])
        >>> corner_errors(np.array([[[0.3, 0.4], [np.nan, np.nan], [0, 0]]]), None, "", t, view)
        (array([0.5, nan]), ['', 'no fit or moved out of its window'])
        >>> corner_errors(None, np.array([["dim", "", ""]], object), "no corner", t, view)[1]
        ['dim', 'no corner']
    """
    n = int(view.sum())
    e = np.full(n, np.nan) if corners is None else np.linalg.norm(np.asarray(corners, float)[view] - truth[view],
                                                                   axis=-1)
    r = np.asarray(reasons, dtype=object)[view] if reasons is not None else np.full(n, "", dtype=object)
    say = why if corners is None and why else "no fit or moved out of its window"
    return e, ["" if np.isfinite(v) else (str(x) if x else say) for v, x in zip(e, r)]


def run_unit(u: Unit) -> tuple[list[dict], float]:
    """Render unit u, take its exposures, run the methods of each exposure's table; (records, seconds)"""
    t0 = time.perf_counter()
    model, layout, seed = _W["model"], _W["layout"], _W["seed"]
    screen, kinds = _screen(u.screen_gamma, u.frames)
    rt = np.array(u.rt)
    E = simulate.render_irradiance(screen, model, rt, supersample=4, psf=_W["psf"])
    at = {k: np.flatnonzero(np.array(kinds) == k) for k in u.frames}
    truth = simulate.true_corners(model, layout, rt)
    view = in_view(model, layout, rt)
    start = perturbed_start(truth, seed, u.index)
    window = true_windows(model, layout, rt)
    fs = float(simulate.full_scale_code(16))
    roi = lit_box(E[at["checkerboard"][0]], screen.room)  # the averaged captures where the screen is
    out = []
    for j, x in enumerate(u.exposures):
        rng = np.random.default_rng([5, seed, u.index, j])

        def expose(img):
            return simulate.expose(img, gain=x.gain, noise=x.read, shot=x.shot, bits=16, rng=rng)

        names = TABLES[x.table][1]
        q = PoseImages(layout, fs, frames=expose(E[at["rotstar"]]), start=start, start_window=window)
        if "saddle" in names:
            q.checkerboard = averaged_captures(E[at["checkerboard"][0]], expose, CAPTURES, roi)
        if "star" in names:
            q.star = averaged_captures(E[at["star"][0]], expose, CAPTURES, roi)
        if "phase" in names:
            q.phase = expose(E[at["phase"]]).reshape((2, 4) + E.shape[1:])
        for name in names:
            e, why = corner_errors(*_found(name, q), truth, view)
            out.append({"table": x.table, "row": x.row, "method": name, "errors": e.tolist(), "why": why})
    return out, time.perf_counter() - t0


def run_units(units: list[Unit], jobs: int, seed: int = 0, model=None, layout=None, log=None,
              psf=None) -> list[dict]:
    """Every unit in `jobs` processes; the records of all (see run_unit)

    model and layout: those of make_units (default: the d435 and paper_layout());
    psf: anything render_irradiance takes (default: the LensPSF of the module doc).
    """
    model = simulate.preset_model("d435") if model is None else model
    layout = paper_layout() if layout is None else layout
    rays = simulate.camera_rays(model)
    order = sorted(range(len(units)), key=lambda i: (units[i].screen_gamma, units[i].frames, i))
    t0, out = time.perf_counter(), []
    try:
        for k, (recs, dt) in enumerate(process_map(run_unit, [(units[i],) for i in order], jobs, _init,
                                                   ((model.intrinsics(), model.imagersize()), layout, rays, seed, psf)), 1):
            out += recs
            if log:
                log(f"  failure modes: {k}/{len(units)} rendered and detected ({dt:.1f} s; "
                    f"{time.perf_counter() - t0:.0f} s)")
    finally:
        _W.clear()
    return out


# ---- numbers -------------------------------------------------------------------------------------
def corner_stats(errors, why) -> dict:
    """in view, found (within MATCH_PX), wrong (farther), RMS and 95th percentile px, rejections by reason"""
    e = np.asarray(errors, float)
    ok = np.isfinite(e) & (e <= MATCH_PX)
    good = e[ok]
    rej = collections.Counter(w for w, v in zip(why, e) if not np.isfinite(v))
    return {"in_view": int(e.size), "found": int(ok.sum()), "wrong": int((np.isfinite(e) & ~ok).sum()),
            "rms_px": float(np.sqrt(np.mean(good ** 2))) if good.size else math.nan,
            "p95_px": float(np.percentile(good, 95)) if good.size else math.nan,
            "rejected": dict(rej.most_common())}


def summarize(records: list[dict]) -> dict:
    """{table: {row: {method: corner_stats}}}, rows and methods in the order of TABLES

        >>> recs = [{"table": "gamma", "row": "2.6", "method": "phase", "errors": [0.1, 0.3], "why": ["", ""]},
        ...         {"table": "gamma", "row": "2.6", "method": "phase", "errors": [np.nan], "why": ["dim"]}]
        >>> s = summarize(recs)["gamma"]["2.6"]["phase"]
        >>> s["in_view"], s["found"], s["rejected"]
        (3, 2, {'dim': 1})
    """
    acc: dict = {}
    for r in records:
        m = acc.setdefault(r["table"], {}).setdefault(r["row"], {}).setdefault(r["method"], ([], []))
        m[0].extend(r["errors"])
        m[1].extend(r["why"])
    order = {"saturation": [f"{g:g}" for g in GAINS], "gamma": [f"{g:g}" for g in SCREEN_GAMMAS],
             "tilt": [f"{t:g}, {r:g}" for t in TILTS for r in ROLLS],
             "noise": [f"{r:g}, {s:g}" for r, s in NOISES]}
    return {t: {row: {m: corner_stats(*acc[t][row][m]) for m in TABLES[t][1] if m in acc[t][row]}
                for row in order[t] if row in acc[t]} for t in TABLES if t in acc}


def cell(s: dict) -> str:
    """'RMS / p95 (found %)' of one corner_stats, with the wrong ones when there are"""
    pct = f"{100 * s['found'] / s['in_view']:.0f}%" if s["in_view"] else "-"
    wrong = f", {s['wrong']} wrong" if s["wrong"] else ""
    if not s["found"]:
        return f"- ({pct}{wrong})"
    return f"{s['rms_px']:.3f} / {s['p95_px']:.3f} ({pct}{wrong})"


def table(summary: dict, name: str) -> str:
    """One Markdown table: a row per condition, a column per method

        >>> s = {"gamma": {"2.6": {"phase": corner_stats([0.1, 0.3], ["", ""])}}}
        >>> print(table(s, "gamma"))
        | screen gamma | rotstar | rotstar, psf-sim | phase | star |
        |---|---|---|---|---|
        | 2.6 |  |  | 0.224 / 0.290 (100%) |  |
    """
    rows = summary.get(name, {})
    methods = TABLES[name][1]
    head = [TABLES[name][0]] + [TITLES[m] for m in methods]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row, ms in rows.items():
        lines.append("| " + " | ".join([row] + [cell(ms[m]) if m in ms else "" for m in methods]) + " |")
    return "\n".join(lines)


def rejections(summary: dict, name: str) -> str:
    """The reasons of the rejected corners of one table, per row and method ('' when none)"""
    out = []
    for row, ms in summary.get(name, {}).items():
        for m, s in ms.items():
            if s["rejected"]:
                out.append(f"{TABLES[name][0]} {row}, {TITLES[m]}: "
                           + "; ".join(f"{n} {w}" for w, n in s["rejected"].items()))
    return ("Rejected corners, and why: " + ". ".join(out) + ".") if out else "No corner was rejected."


def _get(summary, t, row, m):
    return summary.get(t, {}).get(row, {}).get(m)


def _say(s) -> str:
    if s is None:
        return "not measured"
    if not s["found"]:
        return f"no corner ({s['in_view']} in view)"
    return f"RMS {s['rms_px']:.3f} px, {100 * s['found'] / s['in_view']:.0f}% found"


def _range(v: list[float]) -> str:
    lo, hi = f"{min(v):.3f}", f"{max(v):.3f}"
    return f"at {lo} px" if lo == hi else f"within {lo}-{hi} px"


def findings(summary: dict) -> str:
    """What the numbers say, one paragraph of a sentence or two per table, written from them"""
    out = []
    hi, lo = f"{max(GAINS):g}", f"{min(GAINS):g}"
    if "saturation" in summary:
        sat = summary["saturation"]
        first = next((row for row, ms in sat.items() if float(row) >= 1 and "phase" in ms
                      and ms["phase"]["found"] < 0.5 * ms["phase"]["in_view"]), None)
        out.append(f"Saturation: from gain {lo} to {hi} the phase method with its check goes from "
                   f"{_say(_get(summary, 'saturation', lo, 'phase'))} to "
                   f"{_say(_get(summary, 'saturation', hi, 'phase'))}"
                   + (f"; already at gain {first} it keeps {_pct(sat[first]['phase'])} (the crests of the four "
                      "steps cover every phase, so a window where the white clips is clipped in some step)"
                      if first else "")
                   + f"; keeping the clipped samples it goes to "
                   f"{_say(_get(summary, 'saturation', hi, 'phase-keep'))}; rotstar from "
                   f"{_say(_get(summary, 'saturation', lo, 'rotstar'))} to "
                   f"{_say(_get(summary, 'saturation', hi, 'rotstar'))}, the star from "
                   f"{_say(_get(summary, 'saturation', lo, 'star'))} to "
                   f"{_say(_get(summary, 'saturation', hi, 'star'))}.")
    if "gamma" in summary:
        g = summary["gamma"]
        ph = {row: ms["phase"]["rms_px"] for row, ms in g.items() if "phase" in ms}
        rs = [ms["rotstar"]["rms_px"] for ms in g.values() if "rotstar" in ms]
        worst = max(ph, key=lambda k: ph[k] if np.isfinite(ph[k]) else -1) if ph else None
        matched = ph.get(f"{ENCODED_GAMMA:g}", math.nan)
        ratio = ph[worst] / matched if worst and matched > 0 else math.nan
        out.append(f"Gamma mismatch (pattern encoded for {ENCODED_GAMMA:g}): the phase method's RMS is "
                   + ", ".join(f"{v:.3f} px at {k}" for k, v in ph.items())
                   + (f" (worst: screen gamma {worst}, {ratio:.2f} times the matched one)" if np.isfinite(ratio)
                      else "")
                   + (f"; rotstar's stays {_range(rs)}." if rs else ".")
                   + (" A mismatched gamma bends each fringe symmetrically about its crest and trough, so the "
                      "4-step phase errs by an odd function of the phase that vanishes at phase 0, where the "
                      "corners are (the fringes' period is the pitch): the phase planes' zero hardly moves."
                      if np.isfinite(ratio) and ratio < 1.25 else ""))
    if "tilt" in summary:
        parts = []
        for m in TABLES["tilt"][1]:
            v = {row: ms[m] for row, ms in summary["tilt"].items() if m in ms}
            if not v:
                continue
            worst = max(v, key=lambda k: _badness(v[k]))
            why = next(iter(v[worst]["rejected"]), "")
            parts.append(f"{TITLES[m]} {_say(v.get('0, 0'))} head-on, worst at tilt, roll {worst} degrees "
                         f"({_say(v[worst])}, {v[worst]['wrong']} wrong" + (f"; rejected: {why}" if why else "")
                         + ")")
        out.append("Tilt and roll: " + "; ".join(parts) + ".")
    if "noise" in summary:
        n = summary["noise"]
        out.append("Noise: " + "; ".join(
            f"read {row.split(', ')[0]}, shot {row.split(', ')[1]}: "
            + ", ".join(f"{TITLES[m]} {ms[m]['rms_px']:.3f}" for m in TABLES['noise'][1] if m in ms) + " px RMS"
            for row, ms in n.items()) + ".")
    return "\n\n".join(out)


def setup_line(npose: int, seed: int) -> str:
    return (f"Simulated D435 (1280x800, OPENCV8) with make demo's lens (coma {COMA:g} and focus {FOCUS:g} waves at the "
            f"image corners, F/2), the paper's sequence on the default screen (pattern encoded for gamma "
            f"{ENCODED_GAMMA:g}); read noise {READ:g} and shot noise {SHOT:g} of full scale, white at {GAIN:g} "
            f"unless varied, 16-bit; {npose} pose(s) per condition (seed {seed}). Cells: RMS / 95th percentile "
            f"of the error in px over the corners found within {MATCH_PX:g} px of the truth (found: of the corners "
            "in view). The refiners start 0.5 px from the true corners in rotstar's window of the true element.")


def text(summary: dict, npose: int, seed: int) -> str:
    """The whole section: set-up, the four tables with their rejections, what the numbers say"""
    parts = [setup_line(npose, seed)]
    heads = {"saturation": "Phase under saturation (white clips above gain 1):",
             "gamma": f"Phase under display gamma mismatch (the pattern encoded for {ENCODED_GAMMA:g}):",
             "tilt": "Star under large tilt and strong roll (degrees; the board at the image centre, as close "
                     "as it fits):",
             "noise": "Read and shot noise (fraction of full scale; variance per unit signal):"}
    for t in TABLES:
        if t in summary:
            parts += [heads[t], table(summary, t), rejections(summary, t)]
    parts.append(findings(summary))
    return "\n\n".join(parts)


def readme_line(summary: dict) -> str:
    """One sentence for README.md"""
    hi = f"{max(GAINS):g}"
    worst = max((f"{g:g}" for g in SCREEN_GAMMAS),
                key=lambda k: (_get(summary, "gamma", k, "phase") or {"rms_px": -1})["rms_px"])
    tilt = summary.get("tilt", {})
    top = [row for row in tilt if float(row.split(",")[0]) == max(TILTS)]

    def at_top(m):
        ss = [tilt[row][m] for row in top if m in tilt[row]]
        return (f"{100 * sum(x['found'] for x in ss) / max(sum(x['in_view'] for x in ss), 1):.0f}%",
                max((x["rms_px"] for x in ss if x["found"]), default=math.nan))

    parts = [f"With the white clipped (gain {hi}) the phase-shift method finds "
             f"{_pct(_get(summary, 'saturation', hi, 'phase'))} of the corners "
             f"({_rms(_get(summary, 'saturation', hi, 'phase-keep'))} px RMS if it keeps the clipped samples), "
             f"rotstar {_pct(_get(summary, 'saturation', hi, 'rotstar'))} "
             f"({_rms(_get(summary, 'saturation', hi, 'rotstar'))} px)",
             f"a screen of gamma {worst} showing a pattern encoded for {ENCODED_GAMMA:g} leaves phase at "
             f"{_rms(_get(summary, 'gamma', worst, 'phase'))} px RMS "
             f"({_rms(_get(summary, 'gamma', f'{ENCODED_GAMMA:g}', 'phase'))} matched)"]
    if top:
        (sf, sr), (rf, rr) = at_top("star"), at_top("rotstar")
        parts.append(f"at {max(TILTS)} degrees of tilt (any roll) the star finds {sf} (at most {sr:.3f} px RMS), "
                     f"rotstar {rf} (at most {rr:.3f} px)")
    return "; ".join(parts) + " (doc/benchmark.md, *Failure modes*)."


def _badness(s: dict) -> tuple:
    """Sort key of the worst row: fewest found, then largest RMS"""
    return (-s["found"] / max(s["in_view"], 1), s["rms_px"] if np.isfinite(s["rms_px"]) else math.inf)


def _pct(s) -> str:
    return "-" if s is None or not s["in_view"] else f"{100 * s['found'] / s['in_view']:.0f}%"


def _rms(s) -> str:
    return "-" if s is None or not s["found"] else f"{s['rms_px']:.3f}"

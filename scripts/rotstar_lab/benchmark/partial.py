"""Partial views (issue 13): boards hanging over the imager's edges, rotstar against OpenCV's ChArUco detector

SYNOPSIS

    >>> from rotstar_lab.benchmark.partial import CONDITIONS, make_views
    >>> list(CONDITIONS)
    ['clean', 'read noise 6 DN', 'saturated']
    >>> views = make_views(nhang=1, nwhole=1, seed=0)     # per lens and condition; whole: per condition
    >>> [(v.lens, v.kind, v.condition) for v in views][2:4]
    [('d435', 'hanging', 'saturated'), ('wide', 'hanging', 'clean')]
    >>> len(views)                                          # 2 lenses x 3 conditions + 3 whole boards
    9

    results = run_views(views, seed=0, jobs=2, log=print)   # [ViewResult], rendered and detected in 2 processes
    s = summarize(results)                # per (lens, kind, condition, method): counts, RMS
    print(hanging_table(s)); print(whole_table(s)); print(goal_lines(s))

A view is one pose seen in one of CONDITIONS; every view has a pose of its
own. Per lens (simulate.camera presets: `d435`, 1280x800 with mild
distortion, and `wide`, 1280x800, ~112 degrees with strong barrel
distortion) and condition:

- `hanging`: simulate.poses.hanging_poses: the board close to the camera,
  its centre near an image corner or edge, tilted up to 60 degrees, any
  roll, 30-75 % of its corners in view (default_rng([3, seed, lens, condition]));
- `whole` (wide lens only): random_poses with the whole band lattice in the
  image, tilts uniform in WHOLE_TILT_DEG (default_rng([4, seed, condition])).

Each view is rendered (the 8 rotating-star frames, the identity frames and
the ChArUco board of pattern.charuco on the same screen: SUPERSAMPLE x
SUPERSAMPLE area sampling, Gaussian PSF of PSF_SIGMA px) and exposed in its
condition, 8-bit (1 DN = 1/255 of full scale; the noise from
default_rng([5, seed, lens, kind, condition, index])): the rotating-star
and identity frames one capture each; the ChArUco frame CAPTURES captures
averaged (the paper's fairness rule, as the benchmark's checkerboard
baselines), rounded to the 8 bits its detector reads.

Methods: rotstar through the registry (methods.METHODS["rotstar"] with
PoseImages(frames, identity)); OpenCV's cv2.aruco.CharucoDetector with its
defaults (pattern.charuco.detect_charuco), its corner ids mapped to our
(i, j) labels.

Scoring, the same for both (score_view), against the true corners
(simulate.visibility.seen: NaN where the camera cannot see the corner):

- in view: simulate.visibility.in_view, the corner's refinement window
  inside the image;
- reported: the in-view corners the method reports; corners reported
  outside the in-view set are counted apart (`outside`), in neither the
  in-view count nor the percentage;
- wrong label: a reported corner (in view or not) farther than half a
  spacing (visibility.half_spacing) from the true corner of its label, or
  labelled with a corner the camera cannot see;
- RMS and max error: the correctly labelled in-view corners;
- complete (whole boards): every corner reported, no wrong label.
"""

from __future__ import annotations

import collections
import dataclasses
import time

import mrcal
import numpy as np
import cv2

from rotstar_mrcal import simulate
from rotstar_mrcal.parallel import process_map
from rotstar_mrcal.pattern.layout import Layout, make_layout
from rotstar_mrcal.simulate.poses import hanging_poses
from rotstar_mrcal.simulate.captures import averaged_captures, lit_box
from rotstar_mrcal.peers.charuco import charuco_board, detect_charuco, render_charuco
from rotstar_mrcal.peers.registry import METHODS as REGISTRY, PoseImages
from rotstar_mrcal.simulate.visibility import half_spacing, in_view, seen

LENSES = ("d435", "wide")
CONDITIONS = {  # name: (gain: full-scale fraction for a white screen seen head-on, read noise in DN of 8 bits)
    "clean": (0.9, 1.0),
    "read noise 6 DN": (0.9, 6.0),
    "saturated": (1.4, 1.0),
}
BITS = 8
SUPERSAMPLE = 2
PSF_SIGMA = 1.0  # px
CAPTURES = 8  # ChArUco frame captures averaged
IN_VIEW = (0.3, 0.75)  # fraction of the corners in view of a hanging board
MAX_TILT_DEG = 60.0  # hanging boards
WHOLE_LENS = "wide"
WHOLE_TILT_DEG = (30.0, 65.0)  # whole boards
METHODS = ("rotstar", "charuco")
TITLES = {"rotstar": "rotstar", "charuco": "ChArUco (OpenCV)"}
GOAL_REPORTED = 0.95  # of the in-view corners of hanging boards
GOAL_VIEWS = 200  # hanging views, at least


@dataclasses.dataclass
class View:
    lens: str  # a simulate.camera preset
    kind: str  # 'hanging' | 'whole'
    condition: str  # a key of CONDITIONS
    index: int
    rt: np.ndarray  # (6,) rt_cam_board

    @property
    def key(self) -> tuple:
        return self.lens, self.kind, self.condition, self.index


@dataclasses.dataclass
class ViewResult:
    view: View
    scores: dict  # method -> score_view's dict (+ 'why', 'cpu_s')
    seconds: float  # wall time of the rendering, exposure and detections


def make_views(nhang: int, nwhole: int, seed: int, layout: Layout | None = None) -> list[View]:
    """nhang hanging views per lens and condition, then nwhole whole boards per condition on the wide lens"""
    layout = make_layout() if layout is None else layout
    out = []
    for k, lens in enumerate(LENSES):
        model = simulate.preset_model(lens)
        for c, cond in enumerate(CONDITIONS):
            rts = hanging_poses(model, layout, nhang, np.random.default_rng([3, seed, k, c]), in_view=IN_VIEW,
                                max_tilt_deg=MAX_TILT_DEG) if nhang else []
            out += [View(lens, "hanging", cond, i, rt) for i, rt in enumerate(rts)]
    model = simulate.preset_model(WHOLE_LENS)
    for c, cond in enumerate(CONDITIONS):
        rts = simulate.random_poses(model, layout, nwhole, np.random.default_rng([4, seed, c]),
                                    min_tilt_deg=WHOLE_TILT_DEG[0], max_tilt_deg=WHOLE_TILT_DEG[1]) if nwhole else []
        out += [View(WHOLE_LENS, "whole", cond, i, rt) for i, rt in enumerate(rts)]
    return out


def score_view(corners: np.ndarray | None, truth: np.ndarray, view: np.ndarray, half: np.ndarray) -> dict:
    """One method on one view: in-view corners, reported, outside, wrong labels, errors (see the module doc)

    corners, truth: (ny, nx, 2), NaN = not reported / not seen; view: (ny, nx)
    in view; half: (ny, nx) half spacings.

    >>> t = np.stack(np.meshgrid(np.arange(3.0) * 20, np.arange(2.0) * 20), axis=-1)   # (2, 3, 2)
    >>> view = np.array([[True, True, False], [True, True, False]])
    >>> c = t + 0.1; c[0, 0] = np.nan; c[1, 1] = t[1, 0]                        # one missed, one mislabelled
    >>> s = score_view(c, t, view, np.full((2, 3), 10.0))
    >>> s["in_view"], s["reported"], s["outside"], s["wrong"], s["complete"]
    (4, 3, 2, 1, False)
    >>> np.round(s["errors_px"], 4).tolist()
    [0.1414, 0.1414]
    """
    shape = truth.shape[:2]
    c = np.full(shape + (2,), np.nan) if corners is None else np.asarray(corners, float)
    rep = np.isfinite(c).all(axis=-1)
    err = np.linalg.norm(c - truth, axis=-1)
    with np.errstate(invalid="ignore"):
        right = rep & (err <= half)  # NaN truth or half: not right
    wrong = rep & ~right
    e = err[right & view]
    return {"in_view": int(view.sum()), "reported": int((rep & view).sum()), "outside": int((rep & ~view).sum()),
            "wrong": int(wrong.sum()), "complete": bool(rep.all() and not wrong.any()),
            "errors_px": [round(float(v), 6) for v in e]}


# ---------------------------------------------------------------------------
# rendering and detection, one view per call, in worker processes
# ---------------------------------------------------------------------------
_W: dict = {}  # the worker's layout, cameras, rays, screen and ChArUco detector (init_worker)


def screen_frames(layout: Layout) -> np.ndarray:
    """The frames the views show: the rotating-star and identity frames of layout.frames(), then the ChArUco board"""
    seq = [f for f in layout.frames() if f["kind"] in ("rotstar", "identity")]
    return np.concatenate((simulate.exact_frames(layout, seq), render_charuco(layout)[None].astype(np.float32)))


def init_worker(layout: Layout, cameras: dict, rays: dict) -> None:
    """cameras: lens -> (intrinsics, imagersize); rays: lens -> its RayGrid (computed once in the parent)"""
    cv2.setNumThreads(1)
    models = {k: mrcal.cameramodel(intrinsics=v[0], imagersize=v[1]) for k, v in cameras.items()}
    for k, m in models.items():
        simulate.camera.remember_rays(m, rays[k])
    _W.update(layout=layout, models=models, rays=rays, screen=simulate.make_screen(screen_frames(layout), layout),
              charuco=cv2.aruco.CharucoDetector(charuco_board(layout)))


def view_truth(model, layout: Layout, rt) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(true corners (ny, nx, 2) NaN where not seen, in view (ny, nx), half spacings (ny, nx))"""
    truth, _ = seen(model, mrcal.transform_point_rt(np.asarray(rt, float), layout.board_points()))
    return truth, in_view(model, layout, rt), half_spacing(truth)


def view_job(view: View, seed: int) -> ViewResult:
    """Render one view, expose it in its condition, detect with both methods, score (after init_worker)"""
    t0 = time.perf_counter()
    layout, model = _W["layout"], _W["models"][view.lens]
    E = simulate.render_irradiance(_W["screen"], model, view.rt, supersample=SUPERSAMPLE, psf=PSF_SIGMA,
                                   rays=_W["rays"][view.lens])
    truth, inview, half = view_truth(model, layout, view.rt)
    n = layout.nframes
    top = float(simulate.full_scale_code(BITS))
    gain, dn = CONDITIONS[view.condition]
    rng = np.random.default_rng([5, seed, LENSES.index(view.lens), view.kind == "whole",
                                 list(CONDITIONS).index(view.condition), view.index])

    def expose(e):
        return simulate.expose(e, gain=gain, noise=dn / 255.0, bits=BITS, rng=rng)

    frames = expose(E[:-1])
    board = averaged_captures(E[-1], expose, CAPTURES, roi=lit_box(E[-1]))
    c0 = time.process_time()
    identity = frames[n:] if len(frames) > n else None
    f = REGISTRY["rotstar"](PoseImages(layout, top, frames=frames[:n], identity=identity))
    c1 = time.process_time()
    ch = detect_charuco(board, layout, top, _W["charuco"])
    c2 = time.process_time()
    scores = {"rotstar": score_view(f.corners, truth, inview, half) | {"why": f.why, "cpu_s": c1 - c0},
              "charuco": score_view(ch, truth, inview, half) | {"why": "", "cpu_s": c2 - c1}}
    return ViewResult(view, scores, time.perf_counter() - t0)


def run_views(views: list[View], seed: int, jobs: int, layout: Layout | None = None, log=None) -> list[ViewResult]:
    """Every view rendered, exposed, detected and scored in `jobs` processes; in the order of views"""
    layout = make_layout() if layout is None else layout
    lenses = sorted({v.lens for v in views})
    models = {k: simulate.preset_model(k) for k in lenses}
    init = (layout, {k: (m.intrinsics(), m.imagersize()) for k, m in models.items()},
            {k: simulate.camera_rays(m) for k, m in models.items()})
    out: list[ViewResult | None] = [None] * len(views)
    where = {v.key: i for i, v in enumerate(views)}
    t0 = time.perf_counter()
    try:
        for done, r in enumerate(process_map(view_job, [(v, seed) for v in views], jobs, init_worker, init), 1):
            out[where[r.view.key]] = r
            if log and (done % 10 == 0 or done == len(views)):
                log(f"  partial views: {done}/{len(views)} ({time.perf_counter() - t0:.0f} s)")
    finally:
        _W.clear()  # with jobs <= 1 the worker state was set up in this process
    return out


# ---------------------------------------------------------------------------
# summaries, tables, goals
# ---------------------------------------------------------------------------
def _pool(scores: list[dict]) -> dict:
    e = np.concatenate([s["errors_px"] for s in scores]) if scores else np.empty(0)
    in_view = sum(s["in_view"] for s in scores)
    reported = sum(s["reported"] for s in scores)
    whys = collections.Counter(s["why"].split(" (")[0] for s in scores if s["why"])  # without the numbers
    return {"views": len(scores), "in_view": in_view, "reported": reported,
            "reported_fraction": reported / in_view if in_view else None,
            "outside": sum(s["outside"] for s in scores), "wrong": sum(s["wrong"] for s in scores),
            "wrong_views": sum(s["wrong"] > 0 for s in scores), "complete": sum(s["complete"] for s in scores),
            "rms_px": float(np.sqrt(np.mean(e**2))) if e.size else None,
            "max_px": float(e.max()) if e.size else None,
            "cpu_s_median": float(np.median([s["cpu_s"] for s in scores])) if scores else None,
            "reasons": dict(whys.most_common(3))}


def summarize(results: list[ViewResult]) -> dict:
    """{(lens, kind, condition, method): pooled counts}, plus (lens or 'all', kind, 'all', method) totals"""
    groups = collections.defaultdict(list)
    for r in results:
        for m, s in r.scores.items():
            groups[(r.view.lens, r.view.kind, r.view.condition, m)].append(s)
            groups[("all", r.view.kind, "all", m)].append(s)
    return {k: _pool(v) for k, v in groups.items()}


def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:.1f} %"


def _px(x) -> str:
    return "-" if x is None else f"{x:.3f}"


def hanging_table(summary: dict) -> str:
    """Markdown: per lens and condition, the hanging views, rotstar and ChArUco side by side"""
    head = ["lens", "condition", "views", "in-view corners"]
    for m in METHODS:
        head += [f"{TITLES[m]}: reported", "wrong labels", "RMS px"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    keys = [k for k in summary if k[1] == "hanging" and k[0] != "all" and k[3] == METHODS[0]]
    for lens in LENSES:
        for cond in CONDITIONS:
            if (lens, "hanging", cond, METHODS[0]) not in keys:
                continue
            lines.append(_row(summary, (lens, "hanging", cond), lens, cond))
    if keys:
        lines.append(_row(summary, ("all", "hanging", "all"), "**all**", "all", bold=True))
    return "\n".join(lines)


def _row(summary, key, lens, cond, bold=False) -> str:
    first = summary[key + (METHODS[0],)]
    cells = [lens, cond, str(first["views"]), str(first["in_view"])]
    for m in METHODS:
        s = summary[key + (m,)]
        cells += [_pct(s["reported_fraction"]), str(s["wrong"]), _px(s["rms_px"])]
    if bold:
        cells = cells[:2] + [f"**{c}**" for c in cells[2:]]
    return "| " + " | ".join(cells) + " |"


def whole_table(summary: dict) -> str:
    """Markdown: the whole boards on the wide lens, per condition: complete, reported, wrong labels, RMS"""
    head = ["lens", "condition", "poses"]
    for m in METHODS:
        head += [f"{TITLES[m]}: complete", "reported", "wrong labels", "RMS px"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for cond in CONDITIONS:
        key = (WHOLE_LENS, "whole", cond)
        if key + (METHODS[0],) not in summary:
            continue
        cells = [WHOLE_LENS, cond, str(summary[key + (METHODS[0],)]["views"])]
        for m in METHODS:
            s = summary[key + (m,)]
            cells += [f"{s['complete']}/{s['views']}", _pct(s["reported_fraction"]), str(s["wrong"]), _px(s["rms_px"])]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def goals(summary: dict) -> dict:
    """Issue 13's goals for rotstar on these views: reported share, no wrong label, enough views, whole boards"""
    out = {}
    h = summary.get(("all", "hanging", "all", "rotstar"))
    if h:
        out["reported"] = {"goal": f"hanging boards: >= {GOAL_REPORTED:.0%} of the in-view corners reported",
                           "value": h["reported_fraction"],
                           "pass": bool(h["reported_fraction"] is not None and h["reported_fraction"] >= GOAL_REPORTED)}
        out["wrong"] = {"goal": f"hanging boards: 0 wrong labels over >= {GOAL_VIEWS} views",
                        "value": h["wrong"], "views": h["views"],
                        "pass": bool(h["wrong"] == 0 and h["views"] >= GOAL_VIEWS)}
    w = summary.get(("all", "whole", "all", "rotstar"))
    if w:
        out["whole"] = {"goal": f"whole boards on the {WHOLE_LENS} lens, tilts up to {WHOLE_TILT_DEG[1]:g} degrees: "
                                "every pose complete", "value": w["complete"], "views": w["views"],
                        "pass": bool(w["complete"] == w["views"])}
    return out


def goal_lines(summary: dict) -> str:
    """Markdown bullets: each goal with rotstar's value, PASS or FAIL, and ChArUco's figure beside it"""
    ch_h = summary.get(("all", "hanging", "all", "charuco"))
    ch_w = summary.get(("all", "whole", "all", "charuco"))
    lines = []
    for k, g in goals(summary).items():
        verdict = f"**{'PASS' if g['pass'] else 'FAIL'}**"
        if k == "reported":
            lines.append(f"- {g['goal']}: rotstar {_pct(g['value'])} -> {verdict} (ChArUco "
                         f"{_pct(ch_h['reported_fraction'])})")
        elif k == "wrong":
            lines.append(f"- {g['goal']}: rotstar {g['value']} wrong labels in {g['views']} views -> {verdict} "
                         f"(ChArUco {ch_h['wrong']}, in {ch_h['wrong_views']} of the views)")
        else:
            lines.append(f"- {g['goal']}: rotstar {g['value']}/{g['views']} -> {verdict} (ChArUco "
                         f"{ch_w['complete']}/{ch_w['views']})")
    return "\n".join(lines)


def notes(summary: dict) -> str:
    """Markdown bullets: corners reported outside the in-view set, rotstar's commonest reasons for no board"""
    lines = []
    for m in METHODS:
        for kind in ("hanging", "whole"):
            s = summary.get(("all", kind, "all", m))
            if s:
                lines.append(f"- {TITLES[m]}, {kind} views: {s['outside']} corners reported outside the in-view set; "
                             f"{s['wrong_views']} views with a wrong label; median {s['cpu_s_median']:.3f} CPU s "
                             "per view")
    for kind in ("hanging", "whole"):
        s = summary.get(("all", kind, "all", "rotstar"))
        if s and s["reasons"]:
            why = "; ".join(f"{n} x '{w}'" for w, n in s["reasons"].items())
            lines.append(f"- rotstar's commonest reasons for no board ({kind}): {why}")
    return "\n".join(lines)


def summary_sentence(summary: dict) -> str:
    """README's line: the hanging views' reported share and wrong labels, both methods, and the whole boards"""
    h = {m: summary.get(("all", "hanging", "all", m)) for m in METHODS}
    w = {m: summary.get(("all", "whole", "all", m)) for m in METHODS}
    if not h["rotstar"]:
        return ""
    text = (f"On {h['rotstar']['views']} simulated views of boards hanging over the imager's edges (D435-like and "
            f"wide-angle lenses, clean, noisy, saturated), rotstar reports {_pct(h['rotstar']['reported_fraction'])} "
            f"of the in-view corners with {h['rotstar']['wrong']} wrong labels; OpenCV's ChArUco detector on a ChArUco "
            f"board at the same poses {_pct(h['charuco']['reported_fraction'])} with {h['charuco']['wrong']}.")
    if w["rotstar"]:
        text += (f" Whole boards on the wide-angle lens at {WHOLE_TILT_DEG[0]:g}-{WHOLE_TILT_DEG[1]:g} degrees of "
                 f"tilt: {w['rotstar']['complete']}/{w['rotstar']['views']} complete (ChArUco "
                 f"{w['charuco']['complete']}/{w['charuco']['views']}).")
    return text


def setup_line(nhang: int, nwhole: int, seed: int) -> str:
    """What was simulated, one paragraph"""
    conds = ", ".join(f"{k} (gain {g:g}, read noise {dn:g} DN)" for k, (g, dn) in CONDITIONS.items())
    return (f"{nhang} hanging poses per lens and condition ({', '.join(LENSES)}; {IN_VIEW[0]:.0%}-{IN_VIEW[1]:.0%} of "
            f"the corners in view, tilts up to {MAX_TILT_DEG:g} degrees, any roll) and {nwhole} whole boards per "
            f"condition on the {WHOLE_LENS} lens (tilts {WHOLE_TILT_DEG[0]:g}-{WHOLE_TILT_DEG[1]:g} degrees), seed "
            f"{seed}, every view a pose of its own; conditions: {conds}; {BITS}-bit, {SUPERSAMPLE}x{SUPERSAMPLE} area "
            f"supersampling, Gaussian PSF sigma {PSF_SIGMA:g} px; ChArUco frame: mean of {CAPTURES} captures.")


def to_dict(results: list[ViewResult], summary: dict) -> dict:
    """For bench.json: per view its pose and scores, the pooled summaries and the goals"""
    return {"views": [{"lens": r.view.lens, "kind": r.view.kind, "condition": r.view.condition, "index": r.view.index,
                       "rt_cam_board": [float(x) for x in r.view.rt], "scores": r.scores, "seconds": r.seconds}
                      for r in results],
            "summary": {" / ".join(k): v for k, v in summary.items()},
            "goals": goals(summary)}

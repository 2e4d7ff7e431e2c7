"""The validation report: headline table, verdict, detail tables, as Markdown and HTML

SYNOPSIS

    >>> from rotstar_mrcal.report.page import headline, verdicts, fmt
    >>> def m(name, ab, ba, ratio, ta=None):
    ...     return {"method": name, "heldout": {"A->B": {"mean_px": ab, "boards": 7},
    ...                                         "B->A": {"mean_px": ba, "boards": 7}},
    ...             "crossval": {"ratio_median": ratio, "verdict": "consistent" if ratio <= 1 else "model errors"},
    ...             "truth": None if ta is None else {"A": {"median_px": ta}, "B": {"median_px": ta}}}
    >>> results = [{"label": "4000 us", "methods": [m("rotstar", 0.012, 0.015, 0.6, 0.01),
    ...                                             m("opencv-sb", 0.05, 0.08, 3.1, 0.04)]}]
    >>> print(headline(results).markdown())
    | method | 4000 us: held-out MRE, px | 4000 us: vs true model, px |
    |---|---|---|
    | rotstar | **0.012 / 0.015** | **0.01 / 0.01** |
    | opencv-sb | 0.05 / 0.08 | 0.04 / 0.04 |
    >>> verdicts(results)[0]
    'Lowest held-out error: rotstar in 1 of 1 condition.'
    >>> fmt(0.01234), fmt(1.5), fmt(None)
    ('0.0123', '1.5', '-')

Input: the results.json of rotstar-crossval runs (one per condition, e.g.
exposure), each {"label", "methods": [per-method summary as
compare.evaluate makes it, plus "figures"], ...}. Cells "a / b" are the two
directions (calibrated on A and tested on B / the reverse) or the two
calibrations (A / B); bold marks the best mean of the two in its column.
"""

from __future__ import annotations

import dataclasses
import html as _html
import re

import numpy as np

from rotstar_mrcal.report.stereo import section as stereo_section, section_html as stereo_section_html
from rotstar_mrcal.report.table import Table, fmt, get
from rotstar_mrcal.evaluate.tilts import by_tilt


def _pair(m, kind):
    """(a, b) numbers of one method: held-out MRE both ways, or truth error of A and B"""
    if kind == "heldout":
        return get(m, "heldout", "A->B", "mean_px"), get(m, "heldout", "B->A", "mean_px")
    return get(m, "truth", "A", "median_px"), get(m, "truth", "B", "median_px")


def _pair_mean(p):
    v = [x for x in p if x is not None and np.isfinite(x)]
    return float(np.mean(v)) if len(v) == len(p) else np.inf


def methods_of(results) -> list[str]:
    out = []
    for r in results:
        for m in r["methods"]:
            if m["method"] not in out:
                out.append(m["method"])
    return out


def _by_method(result) -> dict:
    return {m["method"]: m for m in result["methods"]}


def headline(results) -> Table:
    """Methods x conditions: held-out MRE both ways, and the error against the truth when known"""
    methods = methods_of(results)
    kinds = ["heldout"] + (["truth"] if any(m.get("truth") for r in results for m in r["methods"]) else [])
    header, cols = ["method"], []
    for r in results:
        for k in kinds:
            header.append(f"{r['label']}: " + ("held-out MRE, px" if k == "heldout" else "vs true model, px"))
            cols.append((_by_method(r), k))
    rows, bold = [], set()
    for i, name in enumerate(methods):
        row = [name]
        for bym, k in cols:
            m = bym.get(name)
            row.append("-" if m is None else " / ".join(fmt(v) for v in _pair(m, k)))
        rows.append(row)
    for j, (bym, k) in enumerate(cols, start=1):
        scores = [_pair_mean(_pair(bym[n], k)) if n in bym else np.inf for n in methods]
        if scores and np.isfinite(min(scores)):
            bold.add((int(np.argmin(scores)), j))
    cap = ("held-out MRE: calibrated on group A, tested on group B / the reverse (the paper's metric); "
           "vs true model: median projection error over the imager of the model calibrated on A / on B. "
           "Lower is better; bold: best in its column.")
    return Table(header, rows, cap, bold)


def tilt_table(results) -> Table | None:
    """Methods x (condition, tilt of the test poses): held-out MRE, both directions' test poses pooled (tilts.by_tilt);
    None when no condition knows its poses' tilts (real data)

    >>> ho = {"A->B": {"per_pose": {"p": 0.1, "q": 0.3}, "tilt_deg": {"p": 0.2, "q": 59.6}}}
    >>> print(tilt_table([{"label": "e1", "methods": [{"method": "rotstar", "heldout": ho}]}]).markdown())
    | method | e1: 0 deg | e1: 60 deg |
    |---|---|---|
    | rotstar | **0.1** | **0.3** |
    """
    per = [{m["method"]: by_tilt(m.get("heldout")) for m in r["methods"]} for r in results]
    cols = [(k, t) for k, p in enumerate(per) for t in sorted({t for v in p.values() for t in v})]
    if not cols:
        return None
    methods = methods_of(results)
    header = ["method"] + [f"{results[k]['label']}: {t} deg" for k, t in cols]
    vals = [[per[k].get(n, {}).get(t) for k, t in cols] for n in methods]
    rows = [[n] + [fmt(v) for v in row] for n, row in zip(methods, vals)]
    bold = set()
    for j in range(len(cols)):
        col = [np.inf if row[j] is None else row[j] for row in vals]
        if np.isfinite(min(col)):
            bold.add((int(np.argmin(col)), j + 1))
    cap = ("held-out MRE by the tilt of the test poses (the angle between the board's normal and the line of "
           "sight, from the truth): the mean over the poses of that tilt of both test groups (B with the model "
           "calibrated on A, A with B's), px. Bold: best in its column.")
    return Table(header, rows, cap, bold)


def verdicts(results) -> list[str]:
    """A few sentences a person can read in ten seconds"""
    out = []
    methods = methods_of(results)
    wins = {n: 0 for n in methods}
    for r in results:
        bym = _by_method(r)
        scores = {n: _pair_mean(_pair(m, "heldout")) for n, m in bym.items()}
        if scores and np.isfinite(min(scores.values())):
            wins[min(scores, key=scores.get)] += 1
    n = len(results)
    best = [k for k, v in sorted(wins.items(), key=lambda kv: -kv[1]) if v > 0]
    if best:
        out.append("Lowest held-out error: " + ", ".join(
            f"{k} in {wins[k]} of {n} condition{'s' if n > 1 else ''}" for k in best) + ".")
    parts = []
    for name in methods:
        vs = [get(_by_method(r).get(name), "crossval", "verdict") for r in results]
        vs = [v for v in vs if v]
        if vs:
            c = {v: vs.count(v) for v in dict.fromkeys(vs)}
            parts.append(f"{name}: " + ", ".join(f"{v} {k}/{len(vs)}" for v, k in c.items()))
    if parts:
        out.append("mrcal cross-validation (diff of the A and B calibrations vs their uncertainty): "
                   + "; ".join(parts) + ".")
    boards = {}
    for r in results:
        for m in r["methods"]:
            for side in "AB":
                boards.setdefault(m["method"], []).append(get(m, "calibration", side, "boards") or 0)
    most = max((max(v) for v in boards.values()), default=0)
    short = [f"{n} {min(v)}-{max(v)}" for n, v in boards.items() if min(v) < most]
    if short:
        out.append(f"Fewer boards than the others (of up to {most} per group, so less reliable calibrations): "
                   + ", ".join(short) + ".")
    tr = []
    for name in methods:
        v = [_pair_mean(_pair(_by_method(r)[name], "truth")) for r in results
             if name in _by_method(r) and _by_method(r)[name].get("truth")]
        v = [x for x in v if np.isfinite(x)]
        if v:
            tr.append((float(np.max(v)), name))
    if tr:
        tr.sort()
        out.append("Against the true model (worst condition, mean of A and B): "
                   + ", ".join(f"{n} {fmt(v, 2)} px" for v, n in tr) + ".")
    return out


def detail(result) -> Table:
    """One condition: every number of every method"""
    header = ["method", "boards A / B", "fit RMS A / B, px", "MRE A→B", "MRE B→A",
              "diff A-B, px", "uA+uB, px", "diff/(uA+uB)", "cross-validation", "vs truth A / B, px"]
    rows, bold = [], set()
    for m in result["methods"]:
        cal, ho, cv = m.get("calibration", {}), m.get("heldout", {}), m.get("crossval") or {}
        rows.append([
            m["method"],
            " / ".join(str(get(cal, s, "boards") or "-") for s in "AB"),
            " / ".join(fmt(get(cal, s, "rms_px")) for s in "AB"),
            fmt(get(ho, "A->B", "mean_px")),
            fmt(get(ho, "B->A", "mean_px")),
            fmt(cv.get("diff_median_px")),
            fmt(cv.get("unc_median_px")),
            fmt(cv.get("ratio_median"), 2),
            "not calibrated" if m.get("error") else (cv.get("verdict") or cv.get("error", "-")),
            " / ".join(fmt(v) for v in _pair(m, "truth")) if m.get("truth") else "-",
        ])
    for j in (3, 4, 5):
        v = [float(r[j]) if r[j] != "-" else np.inf for r in rows]
        if v and np.isfinite(min(v)):
            bold.add((int(np.argmin(v)), j))
    cap = (f"{result['label']}: boards used by each calibration; RMS of its own fit; held-out MRE both ways; "
           "projection diff of the two calibrations, their summed 1-sigma uncertainty and the ratio "
           "(medians over the imager)")
    return Table(header, rows, cap, bold)


@dataclasses.dataclass
class Section:
    """An extra section of the report, after the headline (and the table by tilt): in the page (markdown,
    html), in paper.md (markdown) and in short under headline.md's verdicts (headline; '' for none).
    make demo's paper claims are one (scripts/demo.py); folder.add_sections puts them in a report
    folder already written."""
    markdown: str
    html: str
    headline: str = ""


def paper_section(results, sections=()) -> str:
    """Markdown: the error by tilt of the test poses and the extra sections ('' if there is neither)"""
    out = []
    t = tilt_table(results)
    if t is not None:
        out += ["## By tilt of the test poses", "", t.markdown(), "", f"*{t.caption}*", ""]
    out += [s.markdown for s in sections]
    return "\n".join(out)


def headline_markdown(results) -> str:
    """headline.md's part about the conditions: the headline table and the verdicts"""
    return headline(results).markdown() + "\n\n" + "\n".join(f"- {v}" for v in verdicts(results)) + "\n"


def _top_markdown(results) -> list[str]:
    h = headline(results)
    return (["## Headline", "", h.markdown(), "", f"*{h.caption}*", ""]
            + [f"- {v}" for v in verdicts(results)] + [""])


def _top_html(results) -> list[str]:
    out = ["<h2>Headline</h2>", headline(results).html(), "<ul>"]
    out += [f"<li>{inline(v)}</li>" for v in verdicts(results)] + ["</ul>"]
    t = tilt_table(results)
    if t is not None:
        out += ["<h2>By tilt of the test poses</h2>", t.html()]
    return out


def with_sections(page: dict, results, sections) -> dict:
    """The pages {'index.md', 'index.html', 'headline.md'} (their text, as written without sections)
    with the sections after the headline (and the table by tilt), and paper.md ('' when empty)"""
    if not (results and sections):
        return dict(page, **{"paper.md": paper_section(results)})
    md_top = "\n".join(_top_markdown(results))
    old = paper_section(results)
    md = page["index.md"].replace(md_top + ("\n" + old if old else ""),
                                  md_top + "\n" + paper_section(results, sections), 1)
    html_top = "\n".join(_top_html(results))
    page_html = page["index.html"].replace(html_top, "\n".join([html_top] + [s.html for s in sections]), 1)
    head = headline_markdown(results)
    short = "".join(f"\n{s.headline}" for s in sections if s.headline)
    head_md = page["headline.md"].replace(head, head + short, 1)
    return {"index.md": md, "index.html": page_html, "headline.md": head_md,
            "paper.md": paper_section(results, sections)}


def _alt(caption: str) -> str:
    """A caption as an image's alt text (no brackets, no command)"""
    return caption.split(". Redraw:")[0].replace("[", "(").replace("]", ")")


def markdown(results, title: str, figures=(), per_condition_figures=None, notes: str = "", stereo=(),
             sections=()) -> str:
    """The report page. figures: [(caption, path)] after the headline; per_condition_figures:
    {label: [(caption, path)]} after each condition's table; stereo: make stereo's results
    (stereoreport), a section each after the conditions; sections: Section's after the headline."""
    out = [f"# {title}", ""]
    if notes:
        out += [notes.strip(), ""]
    if results:
        out += _top_markdown(results)
        paper = paper_section(results, sections)
        out += [paper] if paper else []
    for cap, path in figures:
        out += [f"![{cap}]({path})", "", f"*{cap}*", ""]
    for r in results:
        d = detail(r)
        out += [f"## {r['label']}", "", d.markdown(), "", f"*{d.caption}*", ""]
        out += [f"- {m['method']} not calibrated: {m['error']}" for m in r["methods"] if m.get("error")]
        out += [""] if any(m.get("error") for m in r["methods"]) else []
        if r.get("lensmodel"):
            out += [f"Lens model: `{r['lensmodel']}`; groups: A = `{r.get('groups', {}).get('A', 'A')}`, "
                    f"B = `{r.get('groups', {}).get('B', 'B')}`.", ""]
        for cap, path in (per_condition_figures or {}).get(r["label"], []):
            out += [f"![{_alt(cap)}]({path})", "", f"*{cap}*", ""]
        if r.get("commands"):
            out += ["<details><summary>commands run</summary>", "", "```"] + r["commands"] + ["```", "",
                                                                                              "</details>", ""]
    out += [stereo_section(s) for s in stereo]
    out += ["See doc/validation.md for what the numbers mean and what to do when they are not good.", ""]
    return "\n".join(out)


def inline(text: str) -> str:
    """Markdown's inline marks of one paragraph as HTML (escaped): `code` and **bold**

    SYNOPSIS

        >>> inline("run `rotstar-report a/ --out r/` (**slow** < 1 min)")
        'run <code>rotstar-report a/ --out r/</code> (<b>slow</b> &lt; 1 min)'
    """
    parts = re.split(r"(`[^`]*`)", text)
    out = []
    for p in parts:
        if len(p) >= 2 and p.startswith("`") and p.endswith("`"):
            out.append(f"<code>{_html.escape(p[1:-1])}</code>")
        else:
            out.append(re.sub(r"\*\*(.+?)\*\*", r"<b>\1</b>", _html.escape(p)))
    return "".join(out)


def html(results, title: str, figures=(), per_condition_figures=None, notes: str = "", stereo=(),
         sections=()) -> str:
    """The same page as markdown(), as standalone HTML"""
    e = _html.escape
    out = ["<!DOCTYPE html>", "<html><head><meta charset='utf-8'>", f"<title>{e(title)}</title>",
           "<style>body{font-family:sans-serif;max-width:1100px;margin:2em auto;padding:0 1em}"
           "table{border-collapse:collapse;margin:1em 0;font-size:90%}td,th{border:1px solid #ccc;"
           "padding:3px 8px;text-align:right}td:first-child,th:first-child{text-align:left}"
           "caption{caption-side:bottom;font-size:85%;color:#555;text-align:left;padding-top:4px}"
           "img{max-width:100%}pre{background:#f4f4f4;padding:8px;overflow-x:auto;font-size:80%}</style>",
           "</head><body>", f"<h1>{e(title)}</h1>"]
    if notes:
        out += [f"<p>{inline(p)}</p>" for p in notes.strip().split("\n\n")]
    if results:
        out += _top_html(results) + [x.html for x in sections]
    for cap, path in figures:
        out.append(f"<figure><img src='{e(path)}' alt='{e(cap)}'><figcaption>{inline(cap)}</figcaption></figure>")
    for r in results:
        out += [f"<h2>{e(r['label'])}</h2>", detail(r).html()]
        out += [f"<p>{e(m['method'])} not calibrated: {e(m['error'])}</p>" for m in r["methods"] if m.get("error")]
        if r.get("lensmodel"):
            out.append(f"<p>Lens model: <code>{e(r['lensmodel'])}</code></p>")
        for cap, path in (per_condition_figures or {}).get(r["label"], []):
            out.append(f"<figure><img src='{e(path)}' alt='{e(cap)}'><figcaption>{inline(cap)}</figcaption></figure>")
        if r.get("commands"):
            out.append("<details><summary>commands run</summary><pre>" + e("\n".join(r["commands"]))
                       + "</pre></details>")
    out += [stereo_section_html(s) for s in stereo]
    out += ["<p>See doc/validation.md for what the numbers mean.</p>", "</body></html>"]
    return "\n".join(out)

"""The paper's real-world claims as verdicts (validate.claims), the tilt of a pose (validate.tilts) and the
report's table by tilt: pure functions on made-up numbers, fast"""

from __future__ import annotations

import math

import numpy as np
import pytest

from rotstar_mrcal import simulate
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.simulate.poses import board_centre_m
from rotstar_lab import claims
from rotstar_mrcal.report import page as report
from rotstar_mrcal.evaluate.tilts import by_tilt, tilt_deg, tilts_of

TILTS = (0, 30, 60)


@pytest.mark.parametrize("axis, roll", [(0.0, 0.0), (90.0, 0.0), (0.0, 30.0), (37.0, -20.0)])
def test_tilt_is_look_at_poses_tilt(axis, roll):
    model, layout = simulate.preset_model("d435"), make_layout()
    rt = np.array([simulate.look_at_pose(model, layout, xy, 0.3, math.radians(t), math.radians(axis),
                                         math.radians(roll))
                   for xy in ((640, 400), (250, 200), (1030, 600)) for t in TILTS])
    got = tilt_deg(rt, board_centre_m(layout)).reshape(3, 3)
    assert np.allclose(got, TILTS, atol=1e-6)
    # the corner grid's centre (what rotstar-crossval knows) is the board's centre
    spacing = layout.pitch * layout.pixel_pitch_m
    centre = ((layout.nx - 1) * spacing / 2, (layout.ny - 1) * spacing / 2, 0.0)
    assert np.allclose(tilt_deg(rt, centre).reshape(3, 3), TILTS, atol=0.5)
    names = [f"pose{i:03d}" for i in range(len(rt))]
    t = tilts_of(dict(zip(names[1:], rt[1:])), names, board_centre_m(layout))  # pose000's truth unknown
    assert list(t) == names[1:] and abs(t["pose002"] - 60) < 1e-6


def test_by_tilt_pools_both_directions_in_bins():
    ho = {"A->B": {"per_pose": {"a": 0.1, "b": 0.2, "c": None}, "tilt_deg": {"a": 1.0, "b": 31.0, "c": 59.0}},
          "B->A": {"per_pose": {"a": 0.3, "b": float("nan")}, "tilt_deg": {"a": 4.9, "b": 61.0}}}
    assert by_tilt(ho) == pytest.approx({0: 0.2, 30: 0.2})
    assert by_tilt(ho, step=30) == pytest.approx({0: 0.2, 30: 0.2})
    assert by_tilt({"A->B": {"per_pose": {"a": 0.1}}}) == {} and by_tilt(None) == {}


def method(name, ab, ba, by_tilt_err=None, truth=None, verdict="consistent"):
    """One method's rotstar-crossval summary: held-out MRE both ways, per test pose at 0/30/60 degrees"""
    t = by_tilt_err or (ab, ab, ab)
    return {"method": name, "crossval": {"verdict": verdict},
            "heldout": {d: {"mean_px": v, "per_pose": dict(zip("pqr", t)), "tilt_deg": dict(zip("pqr", TILTS))}
                        for d, v in (("A->B", ab), ("B->A", ba))},
            "truth": {s: {"median_px": truth or ab} for s in "AB"}}


def paper_like(k):
    """Exposure k of a run that behaves as the paper says"""
    return {"label": f"{2000 * 2 ** k} us", "methods": [
        method("rotstar", 0.010, 0.012, (0.010, 0.011, 0.012)),
        method("star", 0.03 * (1 + k), 0.014, (0.012, 0.014, 0.04 * (1 + k)), truth=0.02),
        method("phase-keep", 0.04 - 0.005 * k, 0.04 - 0.005 * k),
        method("saddle", 0.05 * (1 + k), 0.05 * (1 + k)),
        method("cornersubpix", 0.1, 0.1), method("opencv-sb", 0.1, 0.1)]}


def test_a_run_that_behaves_as_the_paper_says_reproduces_every_claim():
    v = claims.claims([paper_like(k) for k in range(3)])
    assert [x.finding for x in v] == list(range(1, 9))
    assert all(x.status == "reproduced" for x in v), claims.markdown(v)
    lines = claims.short_lines(v)
    assert lines[0].startswith("1. reproduced (") and "rotstar lowest held-out error" in lines[0]
    md = claims.markdown(v)
    assert "*Our method achieved the best results at almost all tested positions" in md and "   - yes: " in md


def test_each_claim_fails_on_the_numbers_that_contradict_it():
    runs = [paper_like(k) for k in range(3)]
    by = [{m["method"]: m for m in r["methods"]} for r in runs]
    by[1]["saddle"].update(method("saddle", 0.005, 0.005))  # a checkerboard method beats rotstar and the star
    by[2]["phase-keep"].update(method("phase-keep", 0.2, 0.2))  # saturation ruins phase shifting
    by[0]["rotstar"]["crossval"]["verdict"] = "model errors"
    v = {x.finding: x for x in claims.claims(runs)}
    assert v[1].status == "partly reproduced" and not v[1].checks[1].passed and "saddle" in v[1].checks[1].text
    assert v[2].status == "partly reproduced" and "saddle 0.005 px" in v[2].checks[3].text
    assert v[4].status == "partly reproduced" and "x5.71" in v[4].checks[1].text and v[4].checks[2].passed
    assert v[8].status == "partly reproduced" and "model errors" in v[8].checks[0].text


def test_a_method_that_failed_to_calibrate_fails_its_checks_and_missing_methods_are_not_testable():
    runs = [paper_like(k) for k in range(3)]
    for m in runs[2]["methods"]:
        if m["method"] == "phase-keep":
            m["heldout"] = None  # not calibrated at the saturating exposure
    v = {x.finding: x for x in claims.claims(runs)}
    assert not v[4].checks[0].passed and "not calibrated" in v[4].checks[0].text
    only = [{"label": r["label"], "methods": [m for m in r["methods"] if m["method"] in ("rotstar", "saddle")]}
            for r in runs]
    v = {x.finding: x for x in claims.claims(only)}
    assert [v[i].status for i in (2, 3, 4, 5, 6, 7)] == ["not testable"] * 6
    assert v[1].status != "not testable"


def test_the_report_tabulates_by_tilt_and_states_the_claims():
    runs = [paper_like(k) for k in range(3)]
    t = report.tilt_table(runs)
    assert t.header[:4] == ["method", "2000 us: 0 deg", "2000 us: 30 deg", "2000 us: 60 deg"]
    rows = {r[0]: r for r in t.rows}
    assert rows["star"][3] == "0.04" and (0, 3) in t.bold  # rotstar best at 60 degrees
    sec = report.paper_section(runs, [claims.section(runs)])
    assert "## By tilt of the test poses" in sec and "## The paper's real-world claims (4.2)" in sec
    page = report.html(runs, "t", sections=[claims.section(runs)])
    assert "By tilt of the test poses" in page and "real-world claims" in page
    # real data (no tilts) and a run without the paper's patterns: neither section
    plain = [{"label": "x", "methods": [{"method": "rotstar", "heldout": {"A->B": {"mean_px": 0.1}}}]}]
    assert report.tilt_table(plain) is None and claims.section(plain) is None and report.paper_section(plain) == ""


def test_the_claims_added_to_a_written_report_are_the_report_written_with_them(tmp_path):
    """make demo: rotstar-report writes the report, scripts/demo.py adds the claims (report.folder.add_sections);
    the same pages as the report written with the claims' section"""
    from rotstar_mrcal.report.folder import add_sections, build_report

    runs = [paper_like(k) for k in range(3)]
    sec = claims.section(runs)
    direct = build_report(runs, [str(tmp_path)] * 3, str(tmp_path / "direct"), "t", mrcal_figures=False,
                          sections=[sec])
    build_report(runs, [str(tmp_path)] * 3, str(tmp_path / "added"), "t", mrcal_figures=False)
    added = add_sections(str(tmp_path / "added"), [sec])
    assert sorted(added) == ["headline.md", "index.html", "index.md", "paper.md"]
    for name, path in added.items():
        assert open(path).read() == open(direct[name]).read(), name
    assert "The paper's claims (4.2):" in open(added["headline.md"]).read()

"""The failure-mode benchmark (benchmark/failures.py): its numbers, its tables, and a tiny run of it"""

import math

import mrcal
import numpy as np
import pytest

from rotstar_mrcal import simulate
from rotstar_lab.benchmark import failures as F
from rotstar_mrcal.simulate.poses import board_centre_m

from conftest import lab_script


def stats(rms, found=10, in_view=10, wrong=0, rejected=None):
    return {"in_view": in_view, "found": found, "wrong": wrong, "rms_px": rms, "p95_px": 2 * rms,
            "rejected": rejected or {}}


def test_corner_stats():
    s = F.corner_stats([0.3, 0.4, np.nan, np.nan, 5.0], ["", "", "saturated", "saturated", ""])
    assert (s["in_view"], s["found"], s["wrong"]) == (5, 2, 1)
    assert math.isclose(s["rms_px"], math.sqrt((0.09 + 0.16) / 2)) and s["rejected"] == {"saturated": 2}
    none = F.corner_stats([np.nan], ["no board"])
    assert none["found"] == 0 and math.isnan(none["rms_px"]) and F.cell(none) == "- (0%)"


def test_tables_and_findings():
    summary = {
        "saturation": {"0.7": {"rotstar": stats(0.05), "phase": stats(0.02), "phase-keep": stats(0.02),
                               "star": stats(0.08)},
                       "1.4": {"rotstar": stats(0.06), "phase": stats(math.nan, 0, rejected={"saturated": 10}),
                               "phase-keep": stats(0.3), "star": stats(0.09)}},
        "gamma": {"2.2": {"rotstar": stats(0.05), "phase": stats(0.02)},
                  "2.6": {"rotstar": stats(0.05), "phase": stats(0.06)}},
        "tilt": {"0, 0": {"star": stats(0.05)}, "70, 45": {"star": stats(0.5, found=4, wrong=2)}},
    }
    t = F.table(summary, "saturation")
    assert t.splitlines()[0] == "| gain | rotstar | rotstar, psf-sim | phase | phase, keep clipped | star | saddle |"
    assert "| 1.4 | 0.060 / 0.120 (100%) |  | - (0%) | 0.300 / 0.600 (100%) | 0.090 / 0.180 (100%) |  |" in t
    assert "gain 1.4, phase: 10 saturated" in F.rejections(summary, "saturation")
    assert F.rejections(summary, "gamma") == "No corner was rejected."
    f = F.findings(summary)
    assert "to no corner (10 in view)" in f and "worst: screen gamma 2.6, 3.00 times the matched one" in f
    assert "worst at tilt, roll 70, 45 degrees (RMS 0.500 px, 40% found, 2 wrong)" in f
    assert "the phase planes' zero hardly moves" not in f  # the mismatch did move it here
    line = F.readme_line(summary)
    assert "finds 0% of the corners (0.300 px RMS if it keeps" in line and "at 70 degrees of tilt (any roll) the star finds 40% (at most 0.500 px" in line


def test_fitted_pose():
    model = simulate.preset_model("pinhole-small")
    layout = F.paper_layout(screen=(800, 600))
    rt = F.fitted_pose(model, layout, 70, 22.5, 0)
    assert simulate.pose_ok(model, layout, rt, F.MARGIN_PX)
    assert abs(math.degrees(float(simulate.tilt_angle(rt[None], layout)[0])) - 70) < 1
    d = np.linalg.norm(mrcal.transform_point_rt(rt, board_centre_m(layout)))
    closer = simulate.look_at_pose(model, layout, (319.5, 199.5), d / 1.03, math.radians(70), 0, math.radians(22.5))
    assert not simulate.pose_ok(model, layout, closer, F.MARGIN_PX)  # as close as it fits


@pytest.mark.slow  # make test-slow: an end-to-end run, left out of make test
def test_tiny_run():
    """A few renders of a small board, Gaussian blur: every table has its rows and methods, saturation
    rejects the phase corners with the reason and the clipped-keeping phase still reports them"""
    model = simulate.preset_model("pinhole-small")
    layout = F.paper_layout(screen=(800, 600))
    units = F.make_units(1, 0, model, layout)
    assert len(units) == len(F.SCREEN_GAMMAS) + len(F.TILTS) * len(F.ROLLS)
    base = [u for u in units if u.screen_gamma == F.ENCODED_GAMMA and "phase" in u.frames]
    pick = [units[0], base[0], units[-1]]  # gamma 1.8, the matched screen with all exposures, tilt 70 roll 45
    s = F.summarize(F.run_units(pick, jobs=1, seed=0, model=model, layout=layout, psf=1.0))
    assert list(s) == ["saturation", "gamma", "tilt", "noise"]
    assert list(s["saturation"]) == ["0.7", "1", "1.2", "1.4"] and list(s["gamma"]) == ["1.8", "2.2"]
    assert list(s["tilt"]) == ["70, 45"] and list(s["tilt"]["70, 45"]) == ["rotstar", "rotstar-psf-sim", "star",
                                                                          "saddle"]
    n = layout.nx * layout.ny
    for t in s.values():
        for row in t.values():
            for m in row.values():
                assert 0 < m["in_view"] <= n and m["found"] + m["wrong"] + sum(m["rejected"].values()) == m["in_view"]
    low, high = s["saturation"]["0.7"], s["saturation"]["1.4"]
    assert low["phase"]["found"] == low["phase"]["in_view"] and low["phase"]["rms_px"] < 0.2
    assert high["phase"]["found"] == 0 and any("saturated" in w for w in high["phase"]["rejected"])
    assert high["phase-keep"]["found"] > 0.9 * high["phase-keep"]["in_view"]
    text = F.text(s, 1, 0)
    assert text.count("\n| ") > 10 and "Saturation: from gain 0.7 to 1.4" in text


def test_bench_switch():
    bench = lab_script("bench")
    a = bench.parse_args(["--poses", "0", "--partial", "0", "--whole", "0", "--failures", "1"])
    assert (a.poses, a.failures) == (0, 1)
    assert bench.parse_args(["--quick"]).failures == 1
    for bad in (["--poses", "0"], ["--poses", "0", "--partial", "0", "--whole", "0", "--failures", "0"],
                ["--failures", "-1"]):
        with pytest.raises(SystemExit):
            bench.parse_args(bad)

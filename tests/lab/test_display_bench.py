"""The display-map benchmark's table (scripts/display_bench.py --doc) and its make target; the run is
`make display-bench`"""

from __future__ import annotations

import math
import os
import subprocess

import numpy as np
import pytest

from rotstar_lab.docblock import rewrite_block
from rotstar_mrcal.detect.display_offsets import DisplayCheck
from rotstar_mrcal.simulate.display import identity_maps, parse_display_maps

from conftest import lab_script

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


@pytest.fixture(scope="module")
def bench():
    return lab_script("display_bench")


def fake(median: float, skipped: dict, kept: int = 3) -> dict:
    """A result as run() gives it, for 3 still poses and pose003 moved"""
    return {"kept": [f"pose{i:03d}" for i in range(kept)], "skipped": skipped, "reported": True,
            "map_error": (0.012, 9.0), "motion": {"pose000": 0.021, "pose001": 0.04, "pose002": 0.03,
                                                   "pose003": 0.31},
            "corner_rms": 0.0048, "cal": {"median_px": median, "max_px": 2 * median, "fit_rms_px": 0.0051,
                                          "boards": kept}}


def test_the_table_round_trips_through_the_doc_block(bench, tmp_path):
    moved = {"pose003": "camera moved during the sequence (0.31 px > 0.15)"}
    res = {"clean": fake(0.0044, moved), "real-monitor": fake(0.0050, moved)}
    text = bench.doc_table(res, 3, 7, 12.0)
    rows = [line for line in text.splitlines() if line.startswith("| ")]
    assert len(rows) == 3 and rows[1].startswith("| clean | 3 of 3 | pose003: camera moved")
    assert "0.021-0.040 / 0.310" in rows[2] and "0.0050 / 0.0100 | 0.0051 |" in rows[2]
    assert "median x1.14, max x1.14" in text and "1.2x): met" in text and "motion: yes" in text
    assert "scripts/display_bench.py --poses 3, seed 7, 12 s" in text
    fn = tmp_path / "detector.md"
    fn.write_text("before\n<!-- display-bench:begin -->\nold\n<!-- display-bench:end -->\nafter\n")
    assert rewrite_block(str(fn), "display-bench", text)
    body = fn.read_text().split("<!-- display-bench:begin -->\n")[1].split("<!-- display-bench:end -->")[0]
    assert body == text + "\n" and not rewrite_block(str(fn), "display-bench", text)
    worse = dict(res, **{"real-monitor": fake(0.0060, {}, kept=4)})  # over 1.2x, the moved pose kept
    text = bench.doc_table(worse, 3, 7, 12.0)
    assert "1.2x): NOT met" in text and "motion: NO" in text and not bench.verdict(worse, 3)


def test_the_doc_has_one_display_bench_block(bench):
    with open(bench.DOC) as f:
        doc = f.read()
    assert doc.count("<!-- display-bench:begin -->") == 1 and doc.count("<!-- display-bench:end -->") == 1


def test_map_error_against_the_true_maps(bench):
    maps = parse_display_maps(bench.REAL_MONITOR, 8, (1600, 1000))
    lin = maps[:, :, :2] - np.eye(2)
    uv, origin, centre = np.array([[0.0, 0], [800, 500]]), np.array([100.0, 50]), np.array([400.0, 250])
    screen = np.einsum("kab,nb->kna", maps[:, :, :2], uv + origin) + maps[:, None, :, 2] - (uv + origin)
    at_centre = np.einsum("kab,b->ka", maps[:, :, :2], centre + origin) + maps[:, :, 2] - (centre + origin)
    exact = DisplayCheck(at_centre - at_centre.mean(axis=0), {}, 8, linear=lin - lin.mean(axis=0),
                         centre=centre, uv=uv)
    assert np.abs(exact.displacement() - (screen - screen.mean(axis=0))).max() < 1e-9
    assert bench.map_error(exact, maps, origin) == pytest.approx((0.0, 0.0), abs=1e-6)
    assert bench.map_error(exact, identity_maps(8), origin)[0] > 1.5  # the shifts of up to 2 display px
    assert all(math.isnan(e) for e in bench.map_error(DisplayCheck(None, {}, 2), maps, origin))


def test_make_display_bench_runs_the_script_with_doc():
    out = subprocess.run(["make", "-n", "-C", ROOT, "display-bench"], capture_output=True, text=True, check=True)
    assert "scripts/display_bench.py" in out.stdout and "--doc" in out.stdout
    with open(os.path.join(ROOT, "Makefile")) as f:
        make = f.read()
    bench_recipe = make.split("\nbench:")[1].split("\n\n")[0]
    assert bench_recipe.index("calib-bench") < bench_recipe.index("display-bench")
    assert "display-bench-out" in make.split("\nclean:")[1].split("\n\n")[0]
    assert "make display-bench" in make.split("\nhelp:")[1].split("\n\n")[0]

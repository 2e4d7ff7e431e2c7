"""The benchmark's library (rotstar_lab.benchmark) on a tiny scene, and the doc blocks it rewrites"""

from __future__ import annotations

import os

import numpy as np
import pytest

from rotstar_lab.benchmark import calibration, detection, scoring, tables
from rotstar_lab.benchmark import scene as scenes
from rotstar_lab.docblock import BlockError, rewrite_block
from rotstar_mrcal.peers.registry import METHODS
from rotstar_mrcal.pattern.layout import make_layout


def grid(ny=3, nx=4, step=20.0):
    return np.stack(np.meshgrid(np.arange(nx) * step, np.arange(ny) * step), axis=-1)


# ---- scoring ----------------------------------------------------------------
def test_score_board_statuses():
    t = grid()
    assert scoring.score_board(None, t, True) == ("not found", None)
    assert scoring.score_board(t + 0.2, t, False)[0] == "ok"
    assert scoring.score_board(t[::-1] + 0.2, t, True)[0] == "ok"  # a flip, relabelled
    assert scoring.score_board(t[::-1], t, False)[0] == "mislabelled"  # the method's own labels: wrong
    q = t.copy()
    q[1, 1] += (4.0, 0.0)  # labelled right, one corner 4 px off
    assert scoring.score_board(q, t, False)[0] == "outlier"
    q = t + (20.0, 0.0)  # shifted by a column
    assert scoring.score_board(q, t, False)[0] == "mislabelled"
    assert scoring.score_board(np.full_like(t, np.nan), t, False)[0] == "not found"


def test_score_board_square_transpose():
    t = grid(4, 4)
    status, q = scoring.score_board(np.swapaxes(t, 0, 1), t, True)
    assert status == "ok" and np.allclose(q, t)


def test_pose_rows_and_summary():
    t = grid()
    q = t + 0.1
    q[0, 0] = np.nan
    rows = [scoring.pose_row(0, "ok", q, t, "", 0.2, 0.3),
            scoring.pose_row(1, "not found", None, t, "no board", 0.4, 0.5),
            scoring.pose_row(2, "mislabelled", t[::-1], t, "", 0.6, 0.7)]
    assert rows[0]["n_corners"] == 11 and not rows[0]["complete"]
    assert rows[1]["reason"] == "no board" and rows[2]["reason"] == ""
    s = scoring.summarize(rows, 12)
    assert (s["poses"], s["complete"], s["not_found"], s["mislabelled"], s["outlier"]) == (3, 0, 1, 1, 0)
    assert (s["corners"], s["corners_possible"]) == (11, 36)
    assert s["rms_px"] == pytest.approx(0.1 * np.sqrt(2), abs=1e-6)
    assert s["cpu_seconds_median"] == 0.4 and s["wall_seconds_max"] == 0.7


def test_perturbed_start_is_seeded():
    a = scoring.perturbed_start(grid(), 3, 1)
    assert np.array_equal(a, scoring.perturbed_start(grid(), 3, 1))
    assert not np.array_equal(a, scoring.perturbed_start(grid(), 3, 2))
    assert scoring.perturbed_start(None, 0, 0) is None


def test_goals_paired_and_standalone():
    def rows(errs):
        return [{"status": "ok" if e else "not found", "errors_px": e or [], "n_corners": len(e or [])}
                for e in errs]

    res = {"rotstar": rows([[0.01], [0.01]]), "saddle": rows([[0.02], None]), "opencv-sb": rows([[0.1], [0.1]])}
    summ = {"rotstar": {"rms_px": 0.01, "cpu_seconds_median": 0.6, "cpu_seconds_max": 0.7, "wall_seconds_median": 1},
            "saddle": {"rms_px": 0.02}, "opencv-sb": {"rms_px": 0.1}}
    g = scoring.goals(summ, res, {k: k.upper() for k in res}, {"opencv-sb"})
    assert g["accuracy"]["best_baseline"] == "SADDLE" and g["accuracy"]["ratio"] == 0.5 and g["accuracy"]["pass"]
    assert g["accuracy"]["paired_poses"] == 1
    assert g["accuracy_standalone"]["best_baseline"] == "OPENCV-SB"
    assert not g["speed"]["pass"]
    text = tables.goal_lines(g)
    assert "**PASS**" in text and "**FAIL**" in text and "would pass" in text


# ---- tables -----------------------------------------------------------------
def test_input_text_of_every_method():
    for name in METHODS:
        assert tables.input_text(name)
    assert tables.input_text("rotstar") == "8 rotating-star frames"
    assert tables.input_text("opencv-classic") == "averaged checkerboard: own search, win 5"


def test_accuracy_and_calibration_tables():
    s = scoring.summarize([scoring.pose_row(0, "ok", grid() + 0.1, grid(), "", 0.1, 0.1)], 12)
    tab = tables.accuracy_table({"rotstar": s, "mrgingham": s}, {"mrgingham": {"mb": 60.0}})
    lines = tab.splitlines()
    assert len(lines) == 4 and lines[0].count("|") == lines[1].count("|") == lines[2].count("|")
    assert "60.0 (process)" in lines[3] and "| 1/1 |" in lines[2]
    cal = tables.calibration_table({"rotstar": {"boards": 2, "error": "2 boards: too few to calibrate"},
                                    "saddle": {"boards": 9, "fit_rms_px": 0.01, "median_px": 0.02,
                                               "p95_px": 0.03, "max_px": 0.04}})
    assert "| rotstar (symmetric) | 2 | 2 boards: too few to calibrate |" in cal and "| 0.0200 |" in cal


def test_failures_lists_what_went_wrong():
    t = grid()
    rows = {"saddle": [scoring.pose_row(0, "not found", None, t, "no start", 0, 0),
                       scoring.pose_row(1, "ok", t, t, "", 0, 0)]}
    assert tables.failures(rows) == "- saddle fit (Lucchese-Mitra), pose 0: not found (no start)"
    assert tables.failures({"saddle": rows["saddle"][1:]}) == "- none"


# ---- a tiny scene, end to end -------------------------------------------------
@pytest.fixture(scope="module")
def tiny():
    """Two poses of a 6 x 4 board with identity frames (and the 6 x 6 square board)"""
    layout = make_layout(screen=(800, 600), pitch=100, band=24)
    square = make_layout(screen=(1000, 1000), pitch=100, band=24, nx=6, ny=6)
    return scenes.make_scene(2, 0, 16, camera="pinhole-small", layout=layout, square=square)


@pytest.fixture
def restore_affinity():
    """detect_all pins this process to one CPU and one OpenCV thread: undo it after the test"""
    import cv2

    cpus, threads = os.sched_getaffinity(0), cv2.getNumThreads()
    yield
    os.sched_setaffinity(0, cpus)
    cv2.setNumThreads(threads)


@pytest.mark.slow  # make test-slow: an end-to-end run, left out of make test
def test_render_is_seeded_and_independent_of_processes(tiny):
    one = scenes.render_all(tiny, 1)
    two = scenes.render_all(tiny, 2)
    assert [p.index for p in two] == [0, 1]
    for a, b in zip(one, two):
        assert np.array_equal(a.rotstar, b.rotstar) and np.array_equal(a.checker, b.checker)
        assert np.array_equal(a.checker_square, b.checker_square)
    p = one[0]
    assert p.rotstar.shape == (8, 400, 640) and p.rotstar.dtype == np.uint16
    assert p.identity.shape == (tiny.layout.identity_code.nframes, 400, 640) and p.identity.dtype == np.uint16
    assert np.array_equal(one[1].identity, two[1].identity)
    assert p.checker.dtype == np.float32 and p.checker.shape == (400, 640)
    assert not np.array_equal(one[0].checker, one[1].checker)


@pytest.mark.slow  # make test-slow: the benchmark's detect-and-calibrate driver, which make bench runs
def test_detect_all_on_a_tiny_scene(tiny, tmp_path, restore_affinity):
    poses = scenes.render_all(tiny, 1)
    run = detection.detect_all(tiny, poses, str(tmp_path), measure_memory=False)
    assert list(run.results) == detection.benchmarked_methods(have_programs="mrgingham" in run.results)
    for name, rows in run.results.items():
        assert [r["status"] for r in rows] == ["ok", "ok"], name
        assert all(r["rms_px"] < 0.5 for r in rows), name
    assert run.results["rotstar"][0]["n_corners"] == tiny.layout.nx * tiny.layout.ny
    w = run.weights["rotstar-weighted"][0]
    assert w.shape == (tiny.layout.ny, tiny.layout.nx) and np.isclose(np.median(w), 1)
    cal = calibration.calibrate_all(tiny, run.labelled, run.weights, str(tmp_path))
    assert list(cal)[:2] == ["rotstar", "rotstar-weighted"]
    assert all("too few" in c["error"] for c in cal.values())  # 2 boards


@pytest.mark.slow  # make test-slow: a benchmark render check, which make bench runs
def test_identity_frames_leave_the_other_images_alone(tiny):
    """A layout without identity frames: the same 8 frames and checkerboards, no identity frames"""
    import dataclasses

    plain = dataclasses.replace(tiny, layout=dataclasses.replace(tiny.layout, identity=False))
    a, b = scenes.render_all(tiny, 1)[0], scenes.render_all(plain, 1)[0]
    assert b.identity is None and a.identity is not None
    assert np.array_equal(a.rotstar, b.rotstar) and np.array_equal(a.checker, b.checker)
    q = detection.pose_inputs("rotstar", tiny, a, 65535.0, None)
    assert q.identity is a.identity and q.frames is a.rotstar


def test_memory_probe_of_a_refiner(tiny, tmp_path, restore_affinity):
    from rotstar_lab.benchmark import memory

    p = scenes.render_all(tiny, 1)[0]
    q = detection.pose_inputs("saddle", tiny, p, 65535.0, None, tiny.truth("checkerboard")[0],
                              np.full((tiny.layout.ny, tiny.layout.nx), 4.0))
    mem = memory.measure_memory({"saddle": q}, str(tmp_path))
    assert mem["saddle"]["mb"] >= 0 and mem["saddle"]["peak_kb"] > 0


# ---- doc blocks -----------------------------------------------------------------
def test_rewrite_block(tmp_path):
    fn = tmp_path / "doc.md"
    fn.write_text("a\n<!-- x:begin -->\nold\nlines\n<!-- x:end -->\nb\n<!-- y:begin -->\n<!-- y:end -->\n")
    assert rewrite_block(str(fn), "x", "new\n")
    assert rewrite_block(str(fn), "y", "| t |")
    assert fn.read_text() == "a\n<!-- x:begin -->\nnew\n<!-- x:end -->\nb\n<!-- y:begin -->\n| t |\n<!-- y:end -->\n"
    assert not rewrite_block(str(fn), "x", "new")
    with pytest.raises(BlockError):
        rewrite_block(str(fn), "z", "text")
    fn.write_text("<!-- x:end -->\n<!-- x:begin -->\n")
    with pytest.raises(BlockError):
        rewrite_block(str(fn), "x", "text")


def test_docs_have_the_blocks_the_commands_write():
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    for path, name in (("README.md", "bench:summary"), ("doc/benchmark.md", "bench:result"),
                       ("README.md", "bench:partial"), ("doc/benchmark.md", "bench:partial"),
                       ("doc/benchmark.md", "bench:calibration"), ("README.md", "demo:headline"),
                       ("doc/validation.md", "demo:headline"), ("doc/capture.md", "capture-calib-bench")):
        with open(os.path.join(root, path)) as f:
            text = f.read()
        assert text.count(f"<!-- {name}:begin -->") == 1 and text.count(f"<!-- {name}:end -->") == 1, (path, name)


# ---- the averaged checkerboard -------------------------------------------------
def test_averaged_captures_divide_the_noise():
    from rotstar_mrcal import simulate
    from rotstar_mrcal.simulate.captures import averaged_captures, lit_box

    E = np.full((60, 80), 0.02)
    E[10:50, 20:60] = 0.5
    rng = np.random.default_rng(0)

    def expose(img):
        return simulate.expose(img, gain=1.0, noise=0.01, bits=16, rng=rng)

    one = expose(E).astype(float)
    avg = averaged_captures(E, expose, 8)
    assert avg.dtype == np.float32
    ratio = np.std(one[10:50, 20:60]) / np.std(avg[10:50, 20:60])
    assert 2.4 < ratio < 3.3  # sqrt(8) = 2.83
    box = lit_box(E, margin=2)
    assert box == ((8, 52), (18, 62))
    roi = averaged_captures(E, expose, 8, roi=box)
    assert 2.4 < np.std(one[10:50, 20:60]) / np.std(roi[10:50, 20:60]) < 3.3
    assert 0.7 < np.std(one[:5]) / np.std(roi[:5]) < 1.4  # one capture outside the box


def test_bench_driver_help():
    import subprocess
    import sys

    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    for script, option in (("bench.py", "--doc"), ("demo.py", "--no-docs")):
        r = subprocess.run([sys.executable, os.path.join(root, "scripts", script), "--help"], capture_output=True,
                           text=True)
        assert r.returncode == 0 and option in r.stdout, script

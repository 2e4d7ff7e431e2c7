"""rotstar-crossval on a rendered simulated D435 dataset (tests/conftest.py: d435_seq)

The held-out metric with the true camera must sit at the detector's noise
floor, and a slightly wrong camera must be clearly worse; the comparison
mode (two pose groups) must write its models, figures and results.
"""

from __future__ import annotations

import json
import os
import shutil

import mrcal
import pytest

from rotstar_mrcal.calibrate.cornerset import load_corner_set, read_vnl_names


@pytest.fixture(scope="module")
def heldout_run(d435_seq, run_cli, tmp_path_factory):
    out = tmp_path_factory.mktemp("heldout")
    r = run_cli("rotstar-crossval", os.path.join(d435_seq.path, "truth.cameramodel"), d435_seq.path,
                "--outdir", out, "--json", "--jobs", "2")
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout), out


def test_true_model_gives_the_noise_floor(heldout_run, d435_seq):
    res, out = heldout_run
    # every pose but possibly the steepest (conftest's steep60) gives a board
    assert res["boards"] >= len(d435_seq.poses) - 1 and res["points"] > 0.98 * res["boards"] * 126
    assert res["mean_px"] < 0.02  # rotstar's corners are ~0.005 px from the truth
    assert set(res["per_pose"]) <= set(d435_seq.poses) and len(res["per_pose"]) == res["boards"]
    assert os.path.exists(os.path.join(out, "rotstar", "test.vnl"))  # the detected corners are kept


def test_perturbed_model_is_clearly_worse(heldout_run, d435_seq, run_cli, tmp_path):
    res, out = heldout_run
    model = d435_seq.model
    lens, intr = model.intrinsics()
    intr = intr.copy()
    intr[4] += 0.01  # k1: 0.3 px at the image corners
    wrong = tmp_path / "wrong.cameramodel"
    mrcal.cameramodel(intrinsics=(lens, intr), imagersize=model.imagersize()).write(str(wrong))
    r = run_cli("rotstar-crossval", wrong, os.path.join(out, "rotstar", "test.vnl"), "--json")
    assert r.returncode == 0, r.stderr
    bad = json.loads(r.stdout)
    assert bad["mean_px"] > 5 * res["mean_px"] and bad["mean_px"] > 0.05
    # and as a table for people
    r = run_cli("rotstar-crossval", wrong, os.path.join(out, "rotstar", "test.vnl"))
    assert r.returncode == 0 and "| pose | corners | MRE, px |" in r.stdout and "held-out MRE" in r.stdout


def split_vnl(vnl, even, odd):
    """Write the boards of a corners.vnl alternately into two files"""
    names = read_vnl_names(vnl)
    rank = {n: i % 2 for i, n in enumerate(names)}
    with open(vnl) as f, open(even, "w") as fe, open(odd, "w") as fo:
        for line in f:
            if line.startswith("#"):
                fe.write(line)
                fo.write(line)
            elif line.strip():
                (fe if rank[line.split()[0]] == 0 else fo).write(line)


def test_two_groups_compared(heldout_run, d435_seq, run_cli, tmp_path):
    _, out = heldout_run
    even, odd = tmp_path / "even.vnl", tmp_path / "odd.vnl"
    split_vnl(os.path.join(out, "rotstar", "test.vnl"), even, odd)
    xdir = tmp_path / "xval"
    r = run_cli("rotstar-crossval", "--set", "rotstar", even, odd, "--lensmodel", "opencv5", "--label", "even vs odd",
                "--outdir", xdir, "--jobs", "2", "--gridn", "30")
    assert r.returncode == 0, r.stderr
    assert "mrcal-calibrate-cameras --corners-cache" in r.stderr  # the commands are printed
    n_even, n_odd = (len(load_corner_set(str(v)).files) for v in (even, odd))
    assert r.stdout.startswith("| method |") and f"| rotstar | {n_even} / {n_odd} |" in r.stdout
    res = json.load(open(xdir / "results.json"))
    m = res["methods"][0]
    assert res["label"] == "even vs odd" and res["lensmodel"] == "LENSMODEL_OPENCV5"
    assert m["heldout"]["A->B"]["mean_px"] < 0.03 and m["heldout"]["B->A"]["mean_px"] < 0.03
    assert m["truth"]["A"]["median_px"] < 0.1 and m["truth"]["A"]["method"] == "procrustes"
    assert m["crossval"]["verdict"] in ("consistent", "borderline", "model errors")
    for d in ("A->B", "B->A"):  # the true tilt of every test pose (rotstar-report's table by tilt)
        t = m["heldout"][d]["tilt_deg"]
        assert set(m["heldout"][d]["per_pose"]) <= set(t) and all(0 <= v < 90 for v in t.values())
    for f in (m["figures"]["maps"], res["figures"]["per_pose"], m["models"]["A"]):
        assert os.path.exists(xdir / f)
    assert n_even >= 5 and n_odd >= 5


def test_bad_arguments(run_cli, tmp_path):
    r = run_cli("rotstar-crossval", tmp_path / "nothing.vnl", tmp_path / "nothing2.vnl")
    assert r.returncode == 2 and "no such file" in r.stderr
    r = run_cli("rotstar-crossval")
    assert r.returncode == 2 and "MODEL TEST" in r.stderr


def test_unreadable_models_are_named(run_cli, tmp_path, heldout_run):
    bad = tmp_path / "bad.cameramodel"
    bad.write_text("garbage\n")
    _, out = heldout_run
    r = run_cli("rotstar-crossval", bad, os.path.join(out, "rotstar", "test.vnl"))
    assert r.returncode == 2 and f"{bad}: not a camera model mrcal can parse" in r.stderr
    assert "Traceback" not in r.stderr
    plain = tmp_path / "plain.cameramodel"  # no optimization_inputs: no uncertainty to compare with
    mrcal.cameramodel(intrinsics=("LENSMODEL_PINHOLE", [600.0, 600, 640, 400]), imagersize=(1280, 800)).write(str(plain))
    r = run_cli("rotstar-crossval", plain, plain)
    assert r.returncode == 2 and "has no optimization_inputs" in r.stderr


@pytest.mark.slow  # make test-slow: a longer end-to-end run
def test_one_dataset_is_split_in_two(d435_seq, run_cli, tmp_path):
    """rotstar-crossval SEQ: interleaved halves of one recording, written for mrcal's own tools too"""
    xdir = tmp_path / "xval"
    r = run_cli("rotstar-crossval", d435_seq.path, "--outdir", xdir, "--jobs", "2", "--gridn", "20", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "interleaved" in r.stderr and r.stdout.startswith("| method |")
    a, b = (read_vnl_names(str(xdir / "rotstar" / f"{s}.vnl")) for s in "AB")
    assert a and b and not set(a) & set(b) and abs(len(a) - len(b)) <= 1
    res = json.load(open(xdir / "results.json"))
    assert res["lensmodel"] == "LENSMODEL_OPENCV8"  # rotstar-calibrate's lean model
    assert res["methods"][0]["heldout"]["A->B"]["mean_px"] < 0.03
    assert res["label"] == "seq"  # the recording's name, not "seq vs seq"


def test_heldout_without_outdir_writes_nothing_here(d435_seq, run_cli, tmp_path, tmp_path_factory):
    seq = tmp_path_factory.mktemp("two") / "seq"  # two poses of it: the same run, a sixth of the detection
    os.makedirs(seq)
    shutil.copy(os.path.join(d435_seq.path, "pattern.json"), seq)
    for pose in d435_seq.poses[1:3]:
        shutil.copytree(os.path.join(d435_seq.path, pose), seq / pose)
    r = run_cli("rotstar-crossval", os.path.join(d435_seq.path, "truth.cameramodel"), seq, "--jobs", "2", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert os.listdir(tmp_path) == [] and "not kept" in r.stdout


def test_model_of_another_imager_is_refused(heldout_run, d435_seq, run_cli, tmp_path):
    _, out = heldout_run
    lens, intr = d435_seq.model.intrinsics()
    other = tmp_path / "portrait.cameramodel"
    mrcal.cameramodel(intrinsics=(lens, intr), imagersize=(800, 1280)).write(str(other))
    r = run_cli("rotstar-crossval", other, os.path.join(out, "rotstar", "test.vnl"))
    assert r.returncode == 2 and "800x1280" in r.stderr and r.stdout == ""
    r = run_cli("rotstar-crossval", tmp_path / "missing.cameramodel", os.path.join(out, "rotstar", "test.vnl"))
    assert r.returncode == 2 and "no such file" in r.stderr

"""rotstar-report from a small simulated run of rotstar-crossval (corner-level datasets, real mrcal)"""

from __future__ import annotations

import pytest
import json
import os
import re
import shutil

from evaluate.test_validate import corner_dataset

from rotstar_mrcal.report import page as report


@pytest.mark.slow  # make test-slow: an end-to-end run, left out of make test
def test_report_builds_from_a_small_simulated_run(run_cli, tmp_path):
    sets = []
    for name, sigma in (("sharp", 0.03), ("noisy", 0.3)):
        a = corner_dataset(str(tmp_path / "A"), 10, 1, sigma, noise_seed=11 + len(sets), vnl=f"{name}.vnl")
        b = corner_dataset(str(tmp_path / "B"), 10, 2, sigma, noise_seed=21 + len(sets), vnl=f"{name}.vnl")
        sets += ["--set", name, a, b]
    # a detector that found nothing in group A: reported, not fatal
    (tmp_path / "A" / "empty.vnl").write_text("# filename x y level\npose000/rotstar_00.png - - -\n")
    sets += ["--set", "empty", tmp_path / "A" / "empty.vnl", tmp_path / "B" / "noisy.vnl"]
    x1 = tmp_path / "x1"
    r = run_cli("rotstar-crossval", *sets, "--lensmodel", "opencv5", "--label", "exposure 1", "--outdir", x1,
                "--gridn", "24", "--jobs", "2")
    assert r.returncode == 0, r.stderr
    assert "empty: " in r.stderr and "| empty | - / - |" in r.stdout and "not calibrated" in r.stdout
    # a second condition: the same results under another label
    x2 = tmp_path / "x2"
    shutil.copytree(x1, x2)
    res = json.load(open(x2 / "results.json"))
    res["label"] = "exposure 2"
    json.dump(res, open(x2 / "results.json", "w"))

    out = tmp_path / "report"
    (tmp_path / "setup.md").write_text("Corners from `corner_dataset`, **simulated**.\n")
    r = run_cli("rotstar-report", x1, x2, "--out", out, "--title", "small run", "--notes", tmp_path / "setup.md")
    assert r.returncode == 0, r.stderr
    for f in ("index.md", "index.html", "headline.md", "results.json", "summary-heldout.png", "summary-truth.png"):
        assert os.path.exists(out / f), f
    md = (out / "index.md").read_text()
    assert md.startswith("# small run") and "## exposure 1" in md and "## exposure 2" in md
    page = (out / "index.html").read_text()
    assert "<p>Corners from <code>corner_dataset</code>, <b>simulated</b>.</p>" in page  # Markdown marks rendered
    assert "Redraw: <code>mrcal-show-" in page
    # simulated: the error by tilt of the test poses (also paper.md); not the paper's patterns: no claims
    assert "## By tilt of the test poses" in md and "claims" not in md + (out / "headline.md").read_text()
    assert (out / "paper.md").read_text().startswith("## By tilt of the test poses")
    for img in re.findall(r"!\[[^]]*\]\(([^)]+)\)", md) + re.findall(r"src='([^']+)'", (out / "index.html").read_text()):
        assert os.path.exists(out / img), img  # every figure the pages show is in the folder
    # mrcal's own views of the first method's calibration, each with the command that redraws it
    for tool in ("projection-uncertainty --observations", "residuals-board-observation", "residuals --histogram",
                 "projection-diff", "valid-intrinsics-region", "distortion-off-pinhole"):
        assert f"Redraw: `mrcal-show-{tool}" in md and f"redraw with: mrcal-show-{tool}" in r.stderr, tool
    assert "--cbmax 3 " not in md and "outliers" in md
    # the corners' images are not on disk: the worst board is drawn without one, and the caption says so
    assert "residuals over its image" not in md
    assert re.search(r"without its image: \S*/pose000/rotstar_00.png is not on disk", md)
    assert os.path.getsize(out / "exposure-1" / "mrcal-sharp-uncertainty.png") > 1000
    # the headline on stdout: both methods, the sharp corners win everywhere and say so
    assert r.stdout == (out / "headline.md").read_text()
    rows = {line.split("|")[1].strip(): line for line in r.stdout.splitlines() if line.startswith("| ")}
    assert "**" in rows["sharp"] and "**" not in rows["noisy"] and rows["empty"].count(" - |") == 4
    assert "Lowest held-out error: sharp in 2 of 2 conditions." in r.stdout
    # the noisier corners give a larger held-out error, about in proportion
    m = {e["method"]: e for e in res["methods"]}
    ratio = m["noisy"]["heldout"]["A->B"]["mean_px"] / m["sharp"]["heldout"]["A->B"]["mean_px"]
    assert 5 < ratio < 15


def test_report_rejects_duplicate_labels(tmp_path):
    res = {"format": "rotstar-crossval/1", "label": "same", "methods": []}
    for d in ("a", "b"):
        os.makedirs(tmp_path / d)
        json.dump(res, open(tmp_path / d / "results.json", "w"))
    from rotstar_mrcal.cli.report import main

    assert main([str(tmp_path / "a"), str(tmp_path / "b"), "--out", str(tmp_path / "r")]) == 2
    assert report.headline([res]).rows == []


def test_report_out_under_a_file(tmp_path):
    from rotstar_mrcal.cli.report import main

    res = {"format": "rotstar-crossval/1", "label": "x", "methods": []}
    os.makedirs(tmp_path / "a")
    json.dump(res, open(tmp_path / "a" / "results.json", "w"))
    (tmp_path / "file").write_text("")
    assert main([str(tmp_path / "a"), "--out", str(tmp_path / "file" / "report")]) == 2

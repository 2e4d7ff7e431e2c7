"""The package's layering, read from its source (scripts/rotstar_lab/imports.py): what issue 21 set up stays"""

from __future__ import annotations

import os

import pytest

from rotstar_lab.imports import circles, graph, imports, reach

PKG = os.path.join(os.path.dirname(__file__), "..", "..", "rotstar_mrcal")


@pytest.fixture(scope="module")
def package():
    return graph(PKG)


def test_no_import_circles(package):
    _, g = package
    assert circles(g) == []


def test_circles_are_found():
    """The check can fail: a two-module circle and a three-module one"""
    g = {"a": {"b"}, "b": {"a"}, "c": {"d"}, "d": {"e"}, "e": {"c"}, "f": {"a"}}
    assert circles(g) == [["a", "b"], ["c", "d", "e"]]


def test_detection_reaches_no_evaluation_report_or_simulator(package):
    _, g = package
    folders = {m.split(".")[1] for m in reach(g, "rotstar_mrcal.cli.detect") if m.count(".") >= 2}
    assert folders <= {"cli", "detect", "peers", "pattern", "calibrate", "optics"}, folders  # (optics: psf-sim's PSFs)
    assert not folders & {"evaluate", "report", "simulate", "synth"}, folders


def test_the_package_never_imports_the_lab_and_synth_only_from_its_command(package):
    mods, _ = package
    for m, p in mods.items():
        with open(p) as fh:
            assert "rotstar_lab" not in fh.read(), m
        synth = {t for t, _ in imports(m, p, mods) if t.startswith("rotstar_mrcal.synth")}
        assert not synth or m.startswith("rotstar_mrcal.synth") or m == "rotstar_mrcal.cli.synth", (m, synth)

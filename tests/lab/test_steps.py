"""rotstar_lab.steps: make demo's and make stereo's steps, with the time left from the last run"""

from __future__ import annotations

import os
import re
import sys

import pytest

from rotstar_lab import steps


@pytest.fixture
def clean_clock():
    yield
    steps._clock = None


def run_steps(path, sleeps, capsys) -> list[str]:
    """One run of the drivers' steps (python sleeping s seconds each); the lines after each step"""
    clock = steps.start_clock(path)
    for s in sleeps:
        steps.run_step([sys.executable, "-c", f"import time; time.sleep({s})"], "demo")
    clock.finish()
    return [line for line in capsys.readouterr().err.splitlines() if line.startswith("  (")]


def test_time_left_from_the_last_run(tmp_path, capsys, clean_clock):
    path = str(tmp_path / ".steps.json")
    first = run_steps(path, [0.1, 0.1, 1.2], capsys)
    assert len(first) == 3 and not any("left" in line for line in first)  # no earlier run: no estimate
    second = run_steps(path, [0.1, 0.1, 1.2], capsys)
    left = [float(re.search(r"about (\d+) s left", line).group(1)) for line in second]
    assert 1 <= left[0] <= 3 and 1 <= left[1] <= 3 and left[2] == 0  # the long last step is still to come
    assert os.listdir(tmp_path) == [".steps.json"]


def test_other_steps_than_last_time_give_no_estimate(tmp_path, capsys, clean_clock):
    path = str(tmp_path / ".steps.json")
    run_steps(path, [0.0], capsys)
    clock = steps.start_clock(path)
    steps.run_step([sys.executable, "-c", "pass"], "demo")  # (the same program: the same step)
    steps.run_step(["true"], "demo")  # not in the last run
    lines = [line for line in capsys.readouterr().err.splitlines() if line.startswith("  (")]
    assert "left" in lines[0] and "left" not in lines[1] and clock.times and len(clock.names) == 2


def test_a_corrupt_record_is_no_estimate(tmp_path, capsys, clean_clock):
    (tmp_path / ".steps.json").write_text("{not json")
    assert "left" not in run_steps(str(tmp_path / ".steps.json"), [0.0], capsys)[0]

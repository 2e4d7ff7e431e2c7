"""Every command's --help (its real exit codes, no meaningless defaults) and writes that fail
(standard output on a full disk, an output folder that cannot be made, a file limit reached):
one line naming the file (or standard output) and the reason, exit status 1 or 2, no traceback"""

from __future__ import annotations

import importlib
import inspect
import json
import os
import re
import resource
import signal
import subprocess

import numpy as np
import pytest

from conftest import VENV_BIN, cli_env
from rotstar_mrcal.cli import common
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.simulate import Settings, preset_model, random_poses, write_dataset

TOOLS = ["pattern", "detect", "synth", "capture", "segment", "calibrate", "crossval", "report"]


def codes_in(src: str) -> set[int]:
    """The exit codes a piece of source gives: literals in return/sys.exit lines, the EXIT_ names,
    fail() (Failure's default 2)"""
    names = {k: v for k, v in vars(common).items() if k.startswith("EXIT_") and isinstance(v, int)}
    codes = set()
    for line in re.findall(r"^\s*(?:return|sys\.exit\()(.*)$", src, re.M):
        codes |= {int(c) for c in re.findall(r"\b(\d+)\b", line) if int(c) in (0, 1, 2, 130)}
    codes |= {names[n] for n in re.findall(r"\b(EXIT_[A-Z_]+)\b", src) if n in names}
    if re.search(r"\bfail\(", src):
        codes.add(common.EXIT_BAD_INPUT)
    return codes


def help_codes(text: str) -> set[int]:
    """The codes the 'exit status:' paragraph of a --help names"""
    m = re.search(r"exit status: (.*)", " ".join(text.split()))
    assert m, "no 'exit status:' paragraph"
    return {int(c) for c in re.findall(r"(?:^|; )(\d+) ", m.group(1))}


@pytest.mark.parametrize("tool", TOOLS)
def test_help_names_the_exit_codes_the_code_uses(tool, capsys):
    mod = importlib.import_module(f"rotstar_mrcal.cli.{tool}")
    with pytest.raises(SystemExit) as e:
        mod.main(["--help"])
    text = capsys.readouterr().out
    src = inspect.getsource(mod).replace(inspect.getsource(mod).split("\ndef ")[0], "")  # (code, not the text)
    used = codes_in(src) | {2}  # argparse's own
    if re.search(r"\brun\(", src):
        used |= codes_in(inspect.getsource(common.run))
    assert e.value.code == 0 and help_codes(text) == used, text
    assert not re.search(r"\(default: (None|False|True|\[\])\)", text)


def test_synth_subcommands_show_only_meaningful_defaults(capsys):
    from rotstar_mrcal.cli import synth

    for sub in ("experiment", "psf", "bound"):
        with pytest.raises(SystemExit):
            synth.main([sub, "--help"])
        text = capsys.readouterr().out
        assert "(default: None)" not in text and "(default: False)" not in text
        assert sub != "experiment" or "(default: synth-out)" in text


# ---- writes that fail -----------------------------------------------------------------------
def cli(tool: str, *args, cwd=None, stdout=subprocess.PIPE, limit=None) -> subprocess.CompletedProcess:
    """A command as the user runs it; limit: the largest file it may write, in bytes (a full disk)"""

    def full_disk():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return subprocess.run([os.path.join(VENV_BIN, tool), *map(str, args)], stdout=stdout, stderr=subprocess.PIPE,
                          text=True, cwd=cwd, env=cli_env(), timeout=120, preexec_fn=full_disk if limit else None)


def error_line(r: subprocess.CompletedProcess) -> str:
    lines = [x for x in r.stderr.splitlines() if "Warning" not in x and not x.startswith("  ")]
    assert "Traceback" not in r.stderr and "Exception ignored" not in r.stderr, r.stderr
    return lines[-1]


@pytest.fixture(scope="module")
def seq(tmp_path_factory) -> str:
    """One small pose (a 6x4 grid seen by the 640x400 pinhole camera)"""
    path = str(tmp_path_factory.mktemp("io") / "seq")
    model, layout = preset_model("pinhole-small"), make_layout(screen=(800, 600), pitch=100, band=24)
    write_dataset(path, layout, model, random_poses(model, layout, 1, np.random.default_rng(1), max_tilt_deg=30),
                  Settings(bits=16, seed=0, supersample=1))  # (read for labels and reasons only)
    return path


def test_detect_to_a_full_standard_output(seq):
    with open("/dev/full", "w") as full:
        r = cli("rotstar-detect", seq, stdout=full)
    assert r.returncode == 1 and error_line(r) == "rotstar-detect: standard output: No space left on device"


def test_detect_output_file_on_a_full_disk_leaves_no_file(seq, tmp_path):
    r = cli("rotstar-detect", seq, "-o", tmp_path / "corners.vnl", limit=1000)
    assert r.returncode == 1 and error_line(r) == f"rotstar-detect: {tmp_path / 'corners.vnl'}: File too large"
    assert os.listdir(tmp_path) == []


@pytest.fixture
def results(tmp_path) -> str:
    os.makedirs(tmp_path / "a")
    json.dump({"format": "rotstar-crossval/1", "label": "x", "methods": []}, open(tmp_path / "a" / "results.json", "w"))
    return str(tmp_path / "a")


def test_report_into_a_folder_that_cannot_be_made(results):
    r = cli("rotstar-report", results, "--out", "/sys/rotstar-report")
    assert r.returncode == 2 and error_line(r) == "rotstar-report: --out /sys/rotstar-report: Operation not permitted"
    assert not os.path.exists("/sys/rotstar-report")


def test_report_on_a_full_disk(results, tmp_path):
    r = cli("rotstar-report", results, "--out", tmp_path / "rep", limit=1000)
    named = re.fullmatch(r"rotstar-report: (.*): File too large", error_line(r))
    assert r.returncode == 1 and named and os.path.dirname(named.group(1)) == str(tmp_path / "rep"), r.stderr
    assert r.stdout == "" and not [f for f in os.listdir(tmp_path / "rep") if f.startswith(".")]  # no temporary file


# ---- every command run is printed ----------------------------------------------------------
def test_crossval_prints_the_detection_it_runs(seq, tmp_path, capsys):
    """rotstar-crossval's in-process detection is printed as the rotstar-detect command that gives the same corners"""
    from rotstar_mrcal.cli import crossval

    vnl = crossval.detect_dataset(seq, ["rotstar"], str(tmp_path / "x"), "A")["rotstar"]
    cmd = [line for line in capsys.readouterr().err.splitlines() if line.startswith("$ ")]
    assert cmd == [f"$ rotstar-detect {seq} --refine symmetric -o {vnl}    # (run here, in this process)"]
    again = str(tmp_path / "again.vnl")
    r = cli("rotstar-detect", *cmd[0].split("#")[0].split()[2:-1], again)
    assert r.returncode == 0 and open(again).read() == open(vnl).read()
    # the default corner set: rotstar-detect's default, psf-sim, under the name rotstar
    vnl = crossval.detect_default(seq, str(tmp_path / "y"), "B")
    cmd = [line for line in capsys.readouterr().err.splitlines() if line.startswith("$ ")]
    assert vnl == str(tmp_path / "y" / "rotstar" / "B.vnl")
    assert cmd == [f"$ rotstar-detect {seq} --refine psf-sim -o {vnl}    # (run here, in this process)"]
    r = cli("rotstar-detect", *cmd[0].split("#")[0].split()[2:-1], again)
    assert r.returncode == 0 and open(again).read() == open(vnl).read()


def test_pattern_into_a_folder_that_cannot_be_made():
    r = cli("rotstar-pattern", "--out", "/sys/rotstar-pattern")
    assert r.returncode == 2 and error_line(r) == "rotstar-pattern: --out /sys/rotstar-pattern: Operation not permitted"

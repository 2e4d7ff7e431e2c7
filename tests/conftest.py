"""Shared fixtures of the detector tests: one simulated D435 dataset per session

The dataset (rendered once, ~12 s on 2 cores) is what a user would record with
an Intel RealSense D435 (1280x800, 16-bit, mild OPENCV8 distortion, Gaussian
blur of 1 px, 1% noise) looking at the default screen layout (14 x 9 corners,
pitch 150, band 40): eight random poses spread over the imager (tilts up to
50 degrees) and four chosen ones, named in ROLES:

    closeup   0.2 m away, 20 degrees: elements of ~30 px, where the pipeline
              starts the refinement from the rough corners (not the centroids)
    steep55a  55 degrees of tilt about the board's x axis
    steep55b  55 degrees about the board's diagonal
    steep60   60 degrees (the upper end of random_poses' default range)

The tests compare everything with the simulator's truth (seq/truth.json,
seq/truth.cameramodel). The command-line tools are run from the venv that
runs the tests (its bin/ first on PATH, as `make test` does).
"""

from __future__ import annotations

import contextlib
import dataclasses
import fcntl
import functools
import importlib.metadata
import importlib.util
import math
import multiprocessing.forkserver
import multiprocessing.resource_tracker
import os
import select
import signal
import subprocess
import sys
import threading
import traceback
import zlib

import numpy as np
import pytest

from rotstar_mrcal.pattern.layout import Layout, make_layout
from rotstar_mrcal.simulate import (Settings, Truth, load_truth, look_at_pose, preset_model, random_poses,
                                   write_dataset)

VENV_BIN = os.path.dirname(sys.executable)
TEST_SUPERSAMPLE = 2
"""Sub-pixels per camera pixel side in the tests' D435 renders (the simulator's default is 4): a quarter of
the rendering, and the same corners to the detector. Measured on 5 poses of d435_poses (0, 3, 8, 9, 11),
rendered at 4 and at 2 with the same noise: detected corners 0.0002-0.0019 px RMS apart, and as far from
the truth either way (0.003-0.007 px RMS)."""
D435_SETTINGS = Settings(bits=16, seed=0, supersample=TEST_SUPERSAMPLE)  # blur 1 px, noise 1%, gain 0.9, area sampling
N_RANDOM = 8
ROLES = {"closeup": "pose008", "steep55a": "pose009", "steep55b": "pose010", "steep60": "pose011"}


@dataclasses.dataclass
class SimSeq:
    """A simulated dataset on disk and its truth"""

    path: str
    truth: Truth
    layout: Layout

    @property
    def model(self):
        return self.truth.model

    @property
    def poses(self) -> list[str]:
        return self.truth.poses

    def corners(self, pose: str) -> np.ndarray:
        return self.truth.corners[pose]

    def rt(self, pose: str) -> np.ndarray:
        return self.truth.rt_cam_board[pose]


def d435_poses(model, layout) -> np.ndarray:
    rts = list(random_poses(model, layout, N_RANDOM, np.random.default_rng(0), max_tilt_deg=50.0))
    deg = math.radians
    rts.append(look_at_pose(model, layout, (640.0, 400.0), 0.2, tilt=deg(20), tilt_axis=deg(30), roll=0.15))
    rts.append(look_at_pose(model, layout, (520.0, 360.0), 0.45, tilt=deg(55), tilt_axis=0.0, roll=0.3))
    rts.append(look_at_pose(model, layout, (760.0, 440.0), 0.45, tilt=deg(55), tilt_axis=deg(45), roll=-0.4))
    rts.append(look_at_pose(model, layout, (640.0, 400.0), 0.45, tilt=deg(60), tilt_axis=0.0, roll=0.3))
    return np.array(rts)


SMALL_LAYOUT = make_layout(screen=(800, 600), pitch=100, band=24)
"""The capture tests' screen: 6 x 4 corners on 800 x 600, the default sequence (20 loop entries)"""


@pytest.fixture
def pattern_dir(tmp_path):
    """A pattern folder of SMALL_LAYOUT (pattern.json alone), as rotstar-capture --pattern reads it"""
    d = tmp_path / "pattern"
    d.mkdir()
    (d / "pattern.json").write_text(SMALL_LAYOUT.to_json())
    return d


@pytest.fixture(scope="session")
def d435_seq(tmp_path_factory) -> SimSeq:
    """Rendered once per run: under pytest-xdist (make test's -n 2) the first worker renders it into the
    run's shared temporary folder while the other waits on a lock, then reads it back"""
    model, layout = preset_model("d435"), make_layout()
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent  # shared by the workers of this run
    seq, done = str(root / "d435-shared" / "seq"), root / "d435-shared.done"
    with open(root / "d435-shared.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if done.exists():
            return SimSeq(seq, load_truth(seq), layout)
        truth = write_dataset(seq, layout, model, d435_poses(model, layout), D435_SETTINGS, jobs=2,
                              extra={"camera": "d435"})
        done.touch()
    return SimSeq(seq, truth, layout)


def lab_script(name: str):
    """scripts/NAME.py (a lab driver, not a package module) loaded as a module, for its functions"""
    fn = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scripts", f"{name}.py")
    spec = importlib.util.spec_from_file_location(name, fn)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def cli_env() -> dict:
    env = dict(os.environ)
    env["PATH"] = VENV_BIN + os.pathsep + env.get("PATH", "")
    return env


def ctrl_c_reaches_it() -> None:
    """In the child, before exec: Ctrl-C's default action, as a terminal's foreground job has it

    A test run started in the background of a non-interactive shell (`make test &`, a CI step) inherits
    SIGINT ignored, and so would the command under test: it would run to the end, unmoved by Ctrl-C.
    """
    signal.signal(signal.SIGINT, signal.SIG_DFL)


IN_PROCESS = os.environ.get("ROTSTAR_TEST_SUBPROCESS", "0") in ("", "0")
"""Commands run in the test's own process (run_command): the console script's function with its argv, working
folder, a closed stdin and its own stdout and stderr (file descriptors included, for the tools it starts), as
the installed script runs it, without the 0.3-1 s of a new interpreter and its imports per run (measured: 250
command runs in make test). ROTSTAR_TEST_SUBPROCESS=1 runs every one of them as a real process instead."""


@functools.cache
def _entry_point(tool: str):
    """The function behind one of our console scripts (pyproject.toml's [project.scripts]); None for another tool"""
    eps = importlib.metadata.entry_points(group="console_scripts", name=tool)
    return next(iter(eps)).load() if tool.startswith("rotstar-") and eps else None


class _Drain(threading.Thread):
    """Reads a pipe (as subprocess.run's capture_output does, so that no writer blocks on a full pipe); text()
    gives what was written until then, not waiting for an end of file that a process the command started (the
    forkserver of its workers, which outlives the command here) would hold back"""

    def __init__(self, fd: int):
        super().__init__(daemon=True)
        self.fd, self.data, self.stopped = fd, bytearray(), False
        self.start()

    def run(self):
        while True:
            stopped = self.stopped  # read before the select: what was written before text() is read after it
            ready, _, _ = select.select([self.fd], [], [], 0 if stopped else 0.05)
            chunk = os.read(self.fd, 1 << 16) if ready else b""
            self.data += chunk
            if not chunk and (stopped or ready):
                break
        os.close(self.fd)

    def text(self) -> str:
        self.stopped = True
        self.join()
        return self.data.decode(errors="replace")


def _dup_or_none(fd: int) -> int | None:
    try:
        return os.dup(fd)
    except OSError:
        return None


def _run_here(fn, argv: list[str], cwd) -> subprocess.CompletedProcess:
    """What `sys.exit(tool())` does in a new process with captured pipes, done in this one"""
    saved = (sys.argv, sys.stdin, sys.stdout, sys.stderr, os.getcwd(), os.environ.get("PATH"))
    multiprocessing.resource_tracker.ensure_running()  # started here, not inside with the command's pipes
    multiprocessing.forkserver.ensure_running()  # (as parallel does); they outlive the command in this process
    for f in (sys.stdout, sys.stderr):
        f.flush()
    fds = [_dup_or_none(k) for k in (0, 1, 2)]  # (a test run may start with one of them closed)
    (out_r, out_w), (err_r, err_w) = os.pipe(), os.pipe()
    out, err = _Drain(out_r), _Drain(err_r)
    null = os.open(os.devnull, os.O_RDONLY)
    for fd, k in ((null, 0), (out_w, 1), (err_w, 2)):
        os.dup2(fd, k)
        os.close(fd)
    sys.stdin = open(0, closefd=False)
    sys.stdout = open(1, "w", closefd=False)
    sys.stderr = open(2, "w", closefd=False, buffering=1)
    sys.argv = list(argv)
    os.environ["PATH"] = cli_env()["PATH"]
    code = 1
    try:
        if cwd is not None:
            os.chdir(cwd)
        code = fn()
    except SystemExit as e:
        code = e.code
    except Exception:  # the interpreter prints it and exits 1 (the test run's own Ctrl-C goes on up)
        traceback.print_exc()
        code = 1
    finally:
        with contextlib.suppress(OSError, ValueError):
            sys.stdout.flush()
        if code is not None and not isinstance(code, int):  # sys.exit("message")
            print(code, file=sys.stderr)
            code = 1
        sys.stderr.flush()
        sys.argv, sys.stdin, sys.stdout, sys.stderr = saved[:4]
        os.chdir(saved[4])
        if saved[5] is None:
            os.environ.pop("PATH", None)
        else:
            os.environ["PATH"] = saved[5]
        for k, fd in enumerate(fds):
            if fd is None:
                os.close(k)
            else:
                os.dup2(fd, k)
                os.close(fd)
    return subprocess.CompletedProcess(argv, code or 0, out.text(), err.text())


def run_command(tool: str, *args, cwd=None, timeout=300, process: bool = False) -> subprocess.CompletedProcess:
    """`tool args...` as the user runs it -> CompletedProcess (text, captured); see IN_PROCESS

    process=True: always a real process (what needs one: signals, a time limit against a hang, the environment)
    """
    argv = [tool, *map(str, args)]
    fn = _entry_point(tool)
    if IN_PROCESS and not process and fn is not None:
        return _run_here(fn, argv, cwd)
    return subprocess.run([os.path.join(VENV_BIN, tool), *argv[1:]], capture_output=True, text=True,
                          cwd=cwd, env=cli_env(), timeout=timeout)


@pytest.fixture(scope="session")
def run_cli():
    """run_cli('rotstar-detect', arg, ...) -> CompletedProcess (text, captured): run_command"""
    return run_command


def huge_png(path, width=60000, height=60000):
    """A valid PNG signature and IHDR claiming width x height at 16 bits, with a tiny IDAT (a corrupt header)"""
    def chunk(kind, data):
        return len(data).to_bytes(4, "big") + kind + data + zlib.crc32(kind + data).to_bytes(4, "big")

    ihdr = width.to_bytes(4, "big") + height.to_bytes(4, "big") + bytes([16, 0, 0, 0, 0])
    with open(path, "wb") as fh:
        fh.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\0" * 64))
                 + chunk(b"IEND", b""))

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

import dataclasses
import fcntl
import importlib.util
import math
import os
import signal
import subprocess
import sys
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


@pytest.fixture(scope="session")
def run_cli():
    """run_cli('rotstar-detect', arg, ...) -> CompletedProcess (text, captured)"""

    def run(tool: str, *args, cwd=None, timeout=300) -> subprocess.CompletedProcess:
        return subprocess.run([os.path.join(VENV_BIN, tool), *map(str, args)], capture_output=True, text=True,
                              cwd=cwd, env=cli_env(), timeout=timeout)

    return run


def huge_png(path, width=60000, height=60000):
    """A valid PNG signature and IHDR claiming width x height at 16 bits, with a tiny IDAT (a corrupt header)"""
    def chunk(kind, data):
        return len(data).to_bytes(4, "big") + kind + data + zlib.crc32(kind + data).to_bytes(4, "big")

    ihdr = width.to_bytes(4, "big") + height.to_bytes(4, "big") + bytes([16, 0, 0, 0, 0])
    with open(path, "wb") as fh:
        fh.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\0" * 64))
                 + chunk(b"IEND", b""))

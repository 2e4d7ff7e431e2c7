"""The plain-pip install (scripts/pip_install.sh, README.md) on a fresh virtualenv: slow, run by `make pip-check`"""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


@pytest.mark.slow
def test_pip_install_without_uv(tmp_path):
    venv = tmp_path / "v"
    env = dict(os.environ, PYTHON=getattr(sys, "_base_executable", sys.executable))
    t0 = time.monotonic()
    r = subprocess.run(["sh", os.path.join(ROOT, "scripts", "pip_install.sh"), str(venv)], env=env,
                       capture_output=True, text=True, timeout=1800)
    took = time.monotonic() - t0
    assert r.returncode == 0, r.stdout + r.stderr
    assert "rotstar-mrcal 0.1.0" in r.stdout
    print(f"\npip install into a fresh venv: {took:.0f} s")
    for tool in ("rotstar-calibrate", "rotstar-detect", "mrcal-calibrate-cameras", "mrcal-show-projection-uncertainty"):
        h = subprocess.run([str(venv / "bin" / tool), "--help"], capture_output=True, text=True, timeout=120)
        assert h.returncode == 0 and "usage" in h.stdout.lower(), tool + h.stderr

"""Started from an interactive shell (standard input a terminal), no tool waits on it: the demo's report step
(rotstar-crossval, then rotstar-report with mrcal's figures) and mrcal's scripts run in-process finish"""

from __future__ import annotations

import os
import pty
import signal
import subprocess
import sys
import textwrap

from conftest import VENV_BIN, cli_env
from evaluate.test_validate import corner_dataset

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def on_a_terminal(argv, timeout: float, cwd=None) -> tuple[int | None, str]:
    """Run argv with its standard input a pseudo-terminal nobody types on; (exit status or None if it
    had not finished after timeout seconds (then killed), its stderr)"""
    master, slave = pty.openpty()
    try:
        p = subprocess.Popen(argv, stdin=slave, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             cwd=cwd, env=cli_env(), start_new_session=True)
        try:
            _, err = p.communicate(timeout=timeout)
            return p.returncode, err
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            _, err = p.communicate()
            return None, err
    finally:
        os.close(slave)
        os.close(master)


def test_demo_report_step_finishes_on_a_terminal(tmp_path):
    """scripts/demo.py's crossval_and_report (one exposure, one corner set of 8 + 8 poses) from a terminal"""
    found = {"rotstar": {g: corner_dataset(str(tmp_path / g), 8, seed, 0.03) for g, seed in (("A", 1), ("B", 2))}}
    (tmp_path / "setup.md").write_text("Set-up: `corners.vnl` of simulated corners.\n")
    script = textwrap.dedent(f"""
        import sys, types
        sys.path.insert(0, {os.path.join(ROOT, "scripts")!r})
        import demo
        from rotstar_lab.demo import scene
        scene.EXPOSURES = scene.EXPOSURES[:1]
        label = scene.EXPOSURES[0][0]
        rep, headline = demo.crossval_and_report(types.SimpleNamespace(jobs=1), {str(tmp_path)!r},
                                                 {{label: {found!r}}}, {{}})
        print(rep)
    """)
    code, err = on_a_terminal([os.path.join(VENV_BIN, "python"), "-c", script], timeout=150, cwd=tmp_path)
    assert code == 0, f"did not finish (exit {code}): {err[-1500:]}"
    rep = tmp_path / "report"
    assert (rep / "index.html").stat().st_size > 0 and (rep / "index.md").stat().st_size > 0
    assert "rotstar-report: wrote" in err


def test_mrcal_script_run_in_process_reads_no_terminal(tmp_path):
    """validate.calibrate._run_script (mrcal-calibrate-cameras in a worker) gives the script no terminal to read"""
    script = tmp_path / "reads.py"
    script.write_text("import os, sys\nprint(repr(sys.stdin.read()), os.read(0, 10))\n")
    code, err = on_a_terminal([sys.executable, "-c", textwrap.dedent(f"""
        from rotstar_mrcal.calibrate.solve import _run_script
        code, text = _run_script({str(script)!r}, [])
        assert code == 0 and text == "'' b''\\n", (code, text)
        """)], timeout=20)
    assert code == 0, f"did not finish (exit {code}): {err[-800:]}"

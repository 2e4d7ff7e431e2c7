"""rotstar-detect on a pose folder that lacks one identity frame: read, said once, the same board as the whole pose"""

from __future__ import annotations

import os
import re
import shutil

import numpy as np
import pytest

from rotstar_mrcal import dataset
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.simulate import Settings, look_at_pose, preset_model, write_dataset
from rotstar_mrcal.vnl import read_corners

LAYOUT = make_layout(screen=(800, 600), pitch=100, band=24)
CORNER_AGREE_PX = 1e-3  # see tests/detect/test_identity_missing.py


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """Two poses of a small camera (pose000, pose001)"""
    model = preset_model("pinhole-small")
    rts = [look_at_pose(model, LAYOUT, (320, 200), 0.3, tilt=0.4, roll=0.3),
           look_at_pose(model, LAYOUT, (300, 180), 0.25, tilt=0.5, tilt_axis=1.2, roll=-0.4)]
    seq = str(tmp_path_factory.mktemp("rendered") / "seq")
    write_dataset(seq, LAYOUT, model, rts, Settings(bits=16, seed=0, supersample=2))
    return seq


def with_copy(src: str, dst: str, remove: list[str]) -> str:
    """src's dataset and a copy of its pose000 as pose002 without the files `remove`"""
    shutil.copytree(src, dst)
    shutil.copytree(os.path.join(dst, "pose000"), os.path.join(dst, "pose002"))
    for fn in remove:
        os.remove(os.path.join(dst, "pose002", fn))
    return dst


def boards(vnl: str) -> dict:
    """{pose: (ny, nx, 2) corners} of the boards in a corners.vnl"""
    with open(vnl) as f:
        found = read_corners(f, LAYOUT.nx, LAYOUT.ny)
    return {os.path.basename(os.path.dirname(fn)): c for fn, c in found.items() if c is not None}


def test_one_identity_frame_missing_gives_the_whole_poses_board(rendered, run_cli, tmp_path):
    seq = with_copy(rendered, str(tmp_path / "seq"), ["identity_06.png"])
    r = run_cli("rotstar-detect", seq, "-o", tmp_path / "corners.vnl", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    notes = [line for line in r.stderr.splitlines() if "missing" in line]
    assert notes == ["rotstar-detect: pose002: identity_06.png missing: read from the other 9 identity frames"]
    b = boards(str(tmp_path / "corners.vnl"))
    assert sorted(b) == ["pose000", "pose001", "pose002"]
    seen = np.isfinite(b["pose000"][..., 0])
    assert seen.sum() == LAYOUT.nx * LAYOUT.ny
    assert np.array_equal(np.isfinite(b["pose002"][..., 0]), seen)
    assert np.abs(b["pose002"] - b["pose000"])[seen].max() < CORNER_AGREE_PX


def test_two_identity_frames_missing_skip_the_pose_as_before(rendered, run_cli, tmp_path):
    seq = with_copy(rendered, str(tmp_path / "seq"), ["identity_07.png", "identity_02.png"])
    r = run_cli("rotstar-detect", seq, "-o", tmp_path / "corners.vnl", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    lines = [line for line in r.stderr.splitlines() if "pose002" in line]
    assert len(lines) == 1
    assert re.fullmatch(rf"\[3/3\] pose002: skipped: {re.escape(seq)}/pose002/identity_02\.png: missing frame", lines[0])
    assert sorted(boards(str(tmp_path / "corners.vnl"))) == ["pose000", "pose001"]
    assert dataset.list_poses(seq) == ["pose000", "pose001", "pose002"]

"""dataset.load_pose and read_rig on a pose that lacks one identity frame (a short capture that missed it)"""

from __future__ import annotations

import os

import numpy as np
import pytest

from rotstar_mrcal import dataset
from rotstar_mrcal.pattern.layout import make_layout

LAYOUT = make_layout(screen=(800, 600), pitch=100, band=24)
IDENT = [f["file"] for f in LAYOUT.frames() if f["kind"] == "identity"]


def frames(rng, shape=(30, 40)) -> dict:
    return {f["file"]: rng.integers(0, 65535, shape).astype(np.uint16) for f in LAYOUT.frames()}


@pytest.fixture
def seq(tmp_path):
    """A dataset of one pose whose every frame differs (pose000), its frames"""
    seq = str(tmp_path / "seq")
    dataset.write_pattern(seq, LAYOUT)
    imgs = frames(np.random.default_rng(0))
    dataset.write_pose(seq, "pose000", imgs)
    return seq, imgs


def test_one_identity_frame_missing_is_read_as_nan(seq):
    seq, imgs = seq
    whole = dataset.load_pose(seq, "pose000", LAYOUT)
    assert whole.missing == () and np.isfinite(whole.identity).all()
    os.remove(os.path.join(seq, "pose000", IDENT[3]))
    p = dataset.load_pose(seq, "pose000", LAYOUT)
    assert p.missing == (IDENT[3],)
    assert p.identity.dtype == np.float32 and p.identity.shape == whole.identity.shape
    assert np.isnan(p.identity[3]).all()
    keep = [k for k in range(len(IDENT)) if k != 3]
    assert np.array_equal(p.identity[keep], whole.identity[keep])
    assert np.array_equal(p.rotstar, whole.rotstar) and np.array_equal(p.checkerboard, whole.checkerboard)


@pytest.mark.parametrize("remove, first", [((IDENT[5], IDENT[2]), IDENT[2]), (("rotstar_04.png",), "rotstar_04.png"),
                                           ((IDENT[1], "rotstar_06.png"), "rotstar_06.png")])
def test_more_missing_is_todays_one_line_error(seq, remove, first):
    """Two identity frames, or any rotating-star frame: '<the first missing file>: missing frame'"""
    seq, _ = seq
    for fn in remove:
        os.remove(os.path.join(seq, "pose000", fn))
    with pytest.raises(dataset.DatasetError) as e:
        dataset.load_pose(seq, "pose000", LAYOUT)
    assert str(e.value) == f"{os.path.join(seq, 'pose000', first)}: missing frame"


def test_a_frame_size_mismatch_is_still_named_with_a_frame_missing(seq):
    seq, imgs = seq
    os.remove(os.path.join(seq, "pose000", IDENT[0]))
    dataset.write_pose(seq, "pose000", {IDENT[4]: imgs[IDENT[4]][:, 1:]})
    with pytest.raises(dataset.DatasetError, match=rf"{IDENT[4]}: frame size 39x30 differs from the others \(40x30\)"):
        dataset.load_pose(seq, "pose000", LAYOUT)


def test_a_rig_camera_lacking_one_identity_frame_is_read(tmp_path):
    seq = str(tmp_path / "rig")
    dataset.write_pattern(seq, LAYOUT)
    rng = np.random.default_rng(1)
    for k in (0, 1):
        dataset.write_pose(seq, f"pose000/camera-{k}", frames(rng))
    os.remove(os.path.join(seq, "pose000", "camera-1", IDENT[7]))
    os.remove(os.path.join(seq, "pose000", "camera-1", "checkerboard.png"))  # load_pose does without it too
    ds = dataset.open_dataset(seq)
    assert ds.poses == {0: ["pose000/camera-0"], 1: ["pose000/camera-1"]}
    assert ds.load("pose000/camera-1").missing == (IDENT[7],)
    os.remove(os.path.join(seq, "pose000", "camera-1", IDENT[8]))
    with pytest.raises(dataset.DatasetError, match=rf"camera-1/{IDENT[7]}: missing, though .*camera-0 has it"):
        dataset.open_dataset(seq)

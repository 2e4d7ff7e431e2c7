"""The speed measurement of make bench (rotstar_lab.benchmark.speed)"""

import json
import os
import shutil

import numpy as np
import pytest

from rotstar_mrcal import dataset
from rotstar_lab.benchmark import speed
from rotstar_mrcal.pattern.layout import make_layout


@pytest.mark.slow  # make test-slow: an end-to-end run, left out of make test
def test_measure_speed_on_two_poses(d435_seq, tmp_path):
    seq = tmp_path / "seq"
    seq.mkdir()
    shutil.copy(os.path.join(d435_seq.path, "pattern.json"), seq)
    for pose in ("pose000", "pose001"):
        os.symlink(os.path.join(d435_seq.path, pose), seq / pose)
    r = speed.measure_speed(str(seq), repeats=1)
    assert [p.pose for p in r.poses] == ["pose000", "pose001"] and all(p.found for p in r.poses)
    assert all(p.decode_s > 0 and p.detect_s > 0 for p in r.poses)
    assert r.n_images == 2 * len(d435_seq.layout.frames())  # 8 rotating-star, the identity frames, checkerboard
    assert all(p.detect_plain_s > 0 for p in r.poses) and r.identity_share is not None  # with and without them
    assert len(d435_seq.layout.frames()) == 22
    # the command did everything the in-process calls did, and started up
    assert r.command_s > 0 and r.startup_s >= 0
    assert r.ratio_with_startup >= r.ratio
    if shutil.which("mrgingham"):
        assert r.mrgingham_s > 0 and r.command_vs_mrgingham == r.command_s / r.mrgingham_s
        assert np.isclose(r.vs_mrgingham, r.detect_with_startup_s / (r.mrgingham_s / 2))
    t = r.table()
    assert "detect / decode" in t and ("PASS" in t or "FAIL" in t)
    json.dumps(r.to_dict())


def test_speed_result_arithmetic():
    poses = [speed.PoseSpeed("a", 0.1, 0.15, True, 0.12), speed.PoseSpeed("b", 0.1, 0.25, True, 0.25)]
    r = speed.SpeedResult(poses, command_s=1.0, mrgingham_s=4.0, n_images=18, repeats=1)
    assert np.isclose(r.identity_share, 0.125)  # median of +25% and +0%
    assert r.ratio == 2.0  # median of 1.5 and 2.5
    assert np.isclose(r.startup_s, 0.4)
    assert np.isclose(r.ratio_with_startup, 4.0)  # (0.15 + 0.2) / 0.1 and (0.25 + 0.2) / 0.1
    assert r.command_vs_mrgingham == 0.25
    assert np.isclose(r.vs_mrgingham, (0.2 + 0.2) / 2.0)  # median detect + start-up share, per mrgingham pose
    g = r.goals()
    assert not g["ratio"]["pass"] and g["mrgingham"]["pass"] and not g["identity"]["pass"]
    assert "+12.5% -> **FAIL**" in r.table()


def test_write_dataset_round_trip(tmp_path):
    layout = make_layout(screen=(800, 600), pitch=100, band=24)
    rng = np.random.default_rng(0)
    frames = rng.integers(0, 65536, (8, 30, 40)).astype(np.float32)
    checker = rng.uniform(0, 65535, (30, 40))
    identity = rng.integers(0, 65536, (layout.identity_code.nframes, 30, 40)).astype(np.float32)
    seq = speed.write_dataset(str(tmp_path / "seq"), layout, [(frames, checker, identity)], bits=16)
    p = dataset.load_pose(seq, "pose000", dataset.read_pattern(seq)[1])
    np.testing.assert_array_equal(p.rotstar, frames)
    np.testing.assert_array_equal(p.identity, identity)
    np.testing.assert_array_equal(p.checkerboard, np.round(checker))
    assert p.full_scale == 65535.0
    # captures without identity frames (the benchmark's): a dataset whose pattern.json lists none
    seq = speed.write_dataset(str(tmp_path / "lean"), layout, [(frames, checker)], bits=8)
    d, lean = dataset.read_pattern(seq)
    assert not lean.identity and "identity" not in d
    p = dataset.load_pose(seq, "pose000", lean)
    assert p.identity is None and p.full_scale == 255.0
    np.testing.assert_array_equal(p.rotstar, np.clip(frames, 0, 255))
    with pytest.raises(ValueError, match="3 identity frames, the layout has 10"):
        speed.write_dataset(str(tmp_path / "bad"), layout, [(frames, checker, identity[:3])], bits=16)

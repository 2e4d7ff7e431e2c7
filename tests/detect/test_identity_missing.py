"""A pose recorded without one identity frame (all NaN): the same elements named, the same corners found"""

from __future__ import annotations

import numpy as np
import pytest

from rotstar_mrcal import dataset
from rotstar_mrcal.detect.identity import read_identities
from rotstar_mrcal.detect.pipeline import detect_pose
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.simulate import Settings, look_at_pose, preset_model, true_corners, write_dataset

LAYOUT = make_layout(screen=(800, 600), pitch=100, band=24)
CORNER_AGREE_PX = 1e-3
"""How far a corner found without one identity frame may lie from the whole pose's: the identity map (and so
the element regions, their windows and rough corners) comes from the other frames, so the refinement starts
elsewhere and stops within its step tolerance (1e-3 px). Measured on the two poses here, every frame missing in
turn: at most 4e-7 px (elements of ~25 px) and 9e-5 px (a close-up)."""


@pytest.fixture(scope="module")
def poses(tmp_path_factory):
    """[(Pose, truth corners)] of a small camera: a board whole in view, and a close-up hanging over the edge"""
    model = preset_model("pinhole-small")
    rts = [look_at_pose(model, LAYOUT, (320, 200), 0.3, tilt=0.4, roll=0.3),
           look_at_pose(model, LAYOUT, (600, 100), 0.2, tilt=0.5, roll=-0.4)]
    seq = str(tmp_path_factory.mktemp("missing_identity") / "seq")
    write_dataset(seq, LAYOUT, model, rts, Settings(bits=16, seed=0, supersample=2))
    return [(dataset.load_pose(seq, f"pose{k:03d}", LAYOUT), true_corners(model, LAYOUT, rt))
            for k, rt in enumerate(rts)]


def without(identity: np.ndarray, *frames: int) -> np.ndarray:
    out = identity.copy()
    out[list(frames)] = np.nan
    return out


def test_every_element_read_with_any_one_frame_missing(poses):
    code = LAYOUT.identity_code
    for p, _ in poses:
        whole = read_identities(p.rotstar, p.identity, code)
        assert np.sum(whole.index >= 0) >= 12
        for k in range(code.nframes):
            ids = read_identities(p.rotstar, without(p.identity, k), code)
            assert sorted(ids.index.tolist()) == sorted(whole.index.tolist()), k
            assert ids.misordered == ()


SOME_FRAMES = (0, 4, 9)  # the first, a middle and the last of the 10 (every one in turn: the reading test above;
#                          the corners measured with every frame missing in turn: CORNER_AGREE_PX)


def test_same_labels_and_corners_with_one_frame_missing(poses):
    for p, truth in poses:
        whole = detect_pose(p.rotstar, LAYOUT, full_scale=p.full_scale, identity=p.identity)
        assert whole.found, whole.error
        seen = np.isfinite(whole.corners[..., 0])
        assert np.linalg.norm(whole.corners - truth, axis=-1)[seen].max() < 0.1
        for k in SOME_FRAMES:
            r = detect_pose(p.rotstar, LAYOUT, full_scale=p.full_scale, identity=without(p.identity, k))
            assert r.found, (k, r.error)
            assert np.array_equal(np.isfinite(r.corners[..., 0]), seen), k
            assert np.abs(r.corners - whole.corners)[seen].max() < CORNER_AGREE_PX, k


def test_two_frames_missing_name_no_element(poses):
    p, _ = poses[0]
    r = detect_pose(p.rotstar, LAYOUT, full_scale=p.full_scale, identity=without(p.identity, 2, 7))
    assert not r.found
    assert r.error.startswith("identities of 0 of ") and r.error.endswith("identity unreadable: 2 identity frames missing")


def test_an_inverted_frame_is_named_beside_a_missing_one(poses):
    """A frame written inverted as a whole image (its surround white) is still found, the missing frame not tried"""
    p, _ = poses[0]
    ident = without(p.identity, 6)
    ident[3] = p.full_scale - ident[3]
    ids = read_identities(p.rotstar, ident, LAYOUT.identity_code)
    assert ids.misordered[:2] == ("inverted", 3)
    r = detect_pose(p.rotstar, LAYOUT, full_scale=p.full_scale, identity=ident)
    assert not r.found and r.error.startswith("identity frame 3 (identity_03.png) inverted")

"""Per-frame display maps (an affine per frame in screen coordinates) told apart from camera motion

Synthetic per-frame corners: a board seen through a homography, each frame
shown through its own affine map on the screen (the same in every pose), as
on a real monitor (doc/detector.md); then cameras that moved (a shift, a turn
of the image) during the sequence.
"""

import dataclasses

import numpy as np
import pytest

from rotstar_mrcal.detect.display_offsets import (
    MAX_MOTION, dataset_offsets, frame_shifts, map_displacement,
)

NX, NY, PITCH = 14, 9, 160.0  # the default board's grid, display px per step
CENTRE = np.array([(NX - 1) / 2, (NY - 1) / 2]) * PITCH
J, I = np.mgrid[0:NY, 0:NX]
LABELS = np.column_stack((I.ravel(), J.ravel()))
UV = LABELS * PITCH
# the real monitor: shifts 0, 0, +2, +1, +1, -1, +1, +1 display px along v, frame 3 640 ppm taller (bottom kept)
SHIFT = np.array([[0, 0], [0, 0], [0, 2], [0, 1], [0, 1], [0, -1], [0, 1], [0, 1]], float)
LINEAR = np.zeros((8, 2, 2))
LINEAR[3, 1, 1] = 640e-6
SHIFT[3, 1] -= 640e-6 * (NY - 1) / 2 * PITCH  # about the centre: the bottom row stays
OFFSETS = SHIFT - SHIFT.mean(axis=0)
LIN0 = LINEAR - LINEAR.mean(axis=0)


def homography(rng) -> np.ndarray:
    """A tilted view: about 0.3-0.5 camera px per display px, some perspective"""
    H = np.array([[0.35, 0.03, 200], [-0.02, 0.33, 120], [2e-5, -1e-5, 1.0]])
    return H + rng.normal(0, 1, (3, 3)) * np.array([[0.01, 0.01, 20], [0.01, 0.01, 20], [2e-6, 2e-6, 0]])


def project(H, uv):
    p = np.column_stack((uv, np.ones(len(uv)))) @ H.T
    return p[:, :2] / p[:, 2:]


def pose(rng, noise=0.01, image_shift=None, turn=0.0):
    """FrameShifts of one pose: per-frame corners through the display maps, then the camera's motion"""
    H = homography(rng)
    q = project(H, UV)
    disp = map_displacement(OFFSETS, LIN0, CENTRE, UV)
    per = np.stack([project(H, UV + d) for d in disp]) + rng.normal(0, noise, (8, len(UV), 2))
    if image_shift is not None:
        per[4:] += image_shift
    if turn:
        c = q.mean(axis=0)
        for k in range(8):
            a = turn * k / 7
            R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
            per[k] = c + (per[k] - c) @ R.T
    idx = np.linspace(0, len(UV) - 1, 32).astype(int)  # as the pipeline: 32 corners refined frame by frame
    return frame_shifts(per[:, idx], q[idx], LABELS[idx], PITCH, centre=CENTRE)


def test_one_pose_recovers_the_maps():
    s = pose(np.random.default_rng(0), noise=0.0)
    assert np.abs(s.offsets - OFFSETS).max() < 2e-3
    assert np.abs(s.linear - LIN0).max() < 3e-6  # 3 ppm
    assert s.residual_px < 1e-3


@pytest.fixture(scope="module")
def still():
    rng = np.random.default_rng(2)
    return {f"pose{i:03d}": pose(rng) for i in range(8)}


def test_still_poses_kept_and_the_maps_reported(still):
    c = dataset_offsets(still)
    assert c.moved() == [] and max(c.motion_px.values()) < 0.05
    assert np.abs(c.offsets - OFFSETS).max() < 0.02 and np.abs(c.linear - LIN0).max() < 20e-6
    text = c.summary()
    assert "display maps (per frame" in text and "frame 3: shift" in text and "ppm" in text
    assert " y +6" in text.splitlines()[4] and "(+0.00, +0.00)" in text.splitlines()[1]  # frame 3: +640 ppm
    assert c.as_dict()["linear"][3][1][1] == pytest.approx(560e-6, abs=20e-6)


def test_a_clean_display_shows_none():
    rng = np.random.default_rng(3)
    global OFFSETS, LIN0
    saved = OFFSETS, LIN0
    try:
        OFFSETS, LIN0 = np.zeros((8, 2)), np.zeros((8, 2, 2))
        c = dataset_offsets({f"pose{i:03d}": pose(rng) for i in range(8)})
    finally:
        OFFSETS, LIN0 = saved
    assert not c.significant() and c.summary().startswith("display maps: none")


@pytest.mark.parametrize("motion", [dict(image_shift=(0.3, 0.0)), dict(image_shift=(0.0, -0.3)),
                                    dict(turn=np.radians(0.06))])
def test_a_camera_that_moved_is_caught_alone(still, motion):
    """0.3 px sideways from frame 4 on, or the image turned 0.06 degrees over the sequence (0.2-0.3 px at the
    board's edge): the motion the maps of every other pose do not have"""
    poses = dict(still)
    poses["pose008"] = pose(np.random.default_rng(4), **motion)
    c = dataset_offsets(poses)
    assert c.moved() == ["pose008"], c.motion_px
    if "image_shift" in motion:
        assert 0.8 * 0.3 < c.motion_px["pose008"] < 1.25 * 0.3


def test_the_display_is_what_the_still_poses_show(still):
    """Moved poses are left out of the maps (their verdicts kept); too few still poses: no maps"""
    from rotstar_mrcal.detect.display_offsets import still_display

    rng = np.random.default_rng(5)
    poses = dict(still)
    poses.update({f"moved{i}": pose(rng, turn=np.radians(0.2)) for i in range(3)})
    c = still_display(poses)
    assert sorted(c.moved()) == ["moved0", "moved1", "moved2"] and c.poses == 8
    assert np.abs(c.linear - LIN0).max() < 20e-6
    few = dict(list(still.items())[:3]) | {f"moved{i}": poses[f"moved{i}"] for i in range(2)}
    c = still_display(few)
    assert sorted(c.moved()) == ["moved0", "moved1"] and c.offsets is None and "not separable" in c.summary()


def test_few_poses_not_separable(still):
    c = dataset_offsets(dict(list(still.items())[:3]))
    assert c.offsets is None and "not separable" in c.summary() and c.moved(MAX_MOTION) == []


def test_a_pose_is_refined_again_only_where_the_dataset_maps_differ_from_its_own(still):
    """The second pass (detect.run.refine_with_dataset_maps) skips poses whose refinement used the same maps"""
    from rotstar_mrcal.detect.run import REFINE_AGAIN_PX, maps_change_px

    c = dataset_offsets(still)
    s = dataclasses.replace(still["pose000"], applied=True)
    own = (s.offsets, s.linear, s.centre)
    assert maps_change_px(s, own) == 0.0
    assert REFINE_AGAIN_PX < maps_change_px(s, c.refinement_maps()) < 0.02  # the pose's own maps' noise
    s = dataclasses.replace(s, applied=False)  # its refinement used no maps: the display's are all to add
    assert maps_change_px(s, c.refinement_maps()) > 0.5
    zero = (np.zeros((8, 2)), np.zeros((8, 2, 2)), np.zeros(2))
    assert maps_change_px(s, zero) == 0.0


@pytest.mark.slow
def test_tiny_renders_of_a_real_monitors_maps(tmp_path):
    """End to end on tiny renders: whole-pixel shifts and one frame one display pixel taller, the same in every
    pose: every still pose kept, the maps reported, a camera that moved 0.3 px skipped alone"""
    import mrcal

    from rotstar_mrcal.dataset import open_dataset
    from rotstar_mrcal.detect.run import detect_dataset
    from rotstar_mrcal.pattern.layout import make_layout
    from rotstar_mrcal.simulate.camera import preset_model
    from rotstar_mrcal.simulate.dataset import Settings, write_dataset
    from rotstar_mrcal.simulate.display import parse_display_maps
    from rotstar_mrcal.simulate.poses import random_poses

    layout, model = make_layout(screen=(800, 600), pitch=100, band=24, identity=False), preset_model("pinhole-small")
    rts = list(random_poses(model, layout, 5, np.random.default_rng(1), max_tilt_deg=35.0))
    depth = mrcal.transform_point_rt(rts[0], layout.board_points()).reshape(-1, 3)[:, 2].mean()
    move = np.repeat(rts[0][None], len(layout.frames()), axis=0)
    move[4:, 3] += 0.3 * depth / model.intrinsics()[1][0]
    maps = parse_display_maps("2:0,2;3:0,1,0,1px@bottom;4:0,1;5:0,-1;6:0,1;7:0,1", 8, (800, 600))
    seq = str(tmp_path / "seq")
    write_dataset(seq, layout, model, rts + [move], Settings(supersample=2, seed=1), display_maps=maps)
    d = detect_dataset(open_dataset(seq)).cameras[0]
    assert [r.pose for r in d.found] == [f"pose{i:03d}" for i in range(5)], [r.error for r in d.results]
    assert [r.pose for r in d.rejected] == ["pose005"] and "camera moved" in d.rejected[0].error
    assert d.display.significant() and d.display.linear[3, 1, 1] == pytest.approx(1 / 600 * 7 / 8, rel=0.1)
    # psf-sim (which pools its correction over the poses) takes the same second pass with the dataset's maps
    from rotstar_mrcal.detect import run
    from rotstar_mrcal.peers.registry import REFINERS

    again = []
    real = run.refine_with_dataset_maps
    run.refine_with_dataset_maps = lambda *a, **k: (again.append(1), real(*a, **k))
    try:
        p = detect_dataset(open_dataset(seq), refine=REFINERS["psf-sim"]).cameras[0]
    finally:
        run.refine_with_dataset_maps = real
    assert again and [r.pose for r in p.found] == [r.pose for r in d.found]
    for a, b in zip(p.found, d.found):  # (no coma in this lens: psf-sim leaves the corners as they are)
        assert np.nanmax(np.abs(a.corners.corners - b.corners.corners)) < 1e-3

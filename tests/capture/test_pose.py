"""rotstar-capture's quick look at a pose (capture.pose.quick_check): a board hanging over the edge is labelled"""

from __future__ import annotations

import numpy as np

from rotstar_mrcal import dataset
from rotstar_lab.benchmark.coverage import corners_in_view, hanging_pose
from rotstar_mrcal.capture.pose import quick_check
from rotstar_mrcal.capture.segment import Segmentation
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.simulate import Settings, preset_model, true_corners, write_dataset


def test_quick_check_labels_a_board_hanging_over_the_edge(tmp_path):
    """The identity frames reach the detection: the corners in view, labelled, where the truth puts them"""
    model, layout = preset_model("pinhole-small"), make_layout(screen=(800, 600), pitch=100, band=24)
    rt = hanging_pose(model, layout, "top-right", 0, in_view=(0.5, 0.75))
    seq = str(tmp_path / "seq")
    write_dataset(seq, layout, model, [rt], Settings(bits=16, seed=0, supersample=2))  # (labels, 0.1 px)
    pattern, _ = dataset.read_pattern(seq)
    images = {f["file"]: dataset.read_image(f"{seq}/pose000/{f['file']}")[0].astype(np.float64)
              for f in pattern["frames"]}
    seg = Segmentation(images, {}, [], np.zeros(0, bool), [], 0, np.zeros(0), np.zeros(0), 0.0)
    r = quick_check(seg, layout, pattern, 65535.0)
    assert r.found, r.error
    seen = np.isfinite(r.corners[..., 0])
    assert 0 < seen.sum() < layout.nx * layout.ny and not seen[~corners_in_view(model, layout, rt, 0)].any()
    err = np.linalg.norm(r.corners - true_corners(model, layout, rt), axis=-1)[seen]
    assert err.max() < 0.1


def test_quick_check_reads_a_pose_without_one_identity_frame(tmp_path):
    """Segmentation that missed an identity frame (and the checkerboard): the same corners in view, labelled"""
    model, layout = preset_model("pinhole-small"), make_layout(screen=(800, 600), pitch=100, band=24)
    rt = hanging_pose(model, layout, "top-right", 0, in_view=(0.5, 0.75))
    seq = str(tmp_path / "seq")
    write_dataset(seq, layout, model, [rt], Settings(bits=16, seed=0, supersample=2))
    pattern, _ = dataset.read_pattern(seq)
    images = {f["file"]: dataset.read_image(f"{seq}/pose000/{f['file']}")[0].astype(np.float64)
              for f in pattern["frames"]}
    seg = lambda imgs: Segmentation(imgs, {}, [], np.zeros(0, bool), [], 0, np.zeros(0), np.zeros(0), 0.0)  # noqa: E731
    whole = quick_check(seg(images), layout, pattern, 65535.0)
    lacking = {f: img for f, img in images.items() if f not in ("identity_04.png", "checkerboard.png")}
    r = quick_check(seg(lacking), layout, pattern, 65535.0)
    assert whole.found and r.found, r.error
    seen = np.isfinite(whole.corners[..., 0])
    assert np.array_equal(np.isfinite(r.corners[..., 0]), seen)
    assert np.abs(r.corners - whole.corners)[seen].max() < 1e-3

"""The registry of corner methods and refiners (rotstar_mrcal.peers.registry) on one small simulated pose"""

from __future__ import annotations

import numpy as np
import pytest

from rotstar_mrcal.peers import registry as methods
from rotstar_mrcal import simulate
from rotstar_mrcal.peers.registry import METHODS, REFINERS, Found, PoseImages, method_names
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.simulate.captures import averaged_captures


@pytest.fixture(scope="module")
def pose():
    """A 6 x 4 board seen by a small pinhole camera: 8 frames, the identity frames, the 8-times averaged
    checkerboard, the truth"""
    layout = make_layout(screen=(800, 600), pitch=100, band=24)
    n = layout.nframes
    model = simulate.preset_model("pinhole-small")
    rt = simulate.random_poses(model, layout, 1, np.random.default_rng(1))[0]
    screen = simulate.make_screen(simulate.exact_frames(layout), layout)
    E = simulate.render_irradiance(screen, model, rt, supersample=4, psf=1.0)
    rng = np.random.default_rng(1)

    def expose(img):
        return simulate.expose(img, noise=0.01, bits=16, rng=rng)

    return dict(layout=layout, frames=expose(E[:n]), identity=expose(E[n:-1]),
                checker=averaged_captures(E[-1], expose, 8), truth=simulate.true_corners(model, layout, rt))


def test_registry_entries_are_well_formed():
    for name, m in METHODS.items():
        assert m.name == name and m.title and m.description and callable(m.run)
        assert m.needs in ("rotstar", "checkerboard", "square", "phase", "star") and m.start in ("own", "rotstar")
        assert not m.variant_of or m.variant_of in METHODS
    for name, r in REFINERS.items():
        assert r.name == name and r.needs in ("rotstar", "checkerboard") and callable(r.refine)


def test_selections_keep_the_experiments_methods():
    # the demo's comparison and the benchmark's rows, as before the registry
    assert method_names(needs=("rotstar", "checkerboard"), demo=True) == [
        "rotstar", "rotstar-weighted", "opencv-sb", "cornersubpix", "saddle", "rotstar-psf-sim"]
    assert method_names(needs="square", demo=True) == ["mrgingham"]
    assert method_names(variants=False) == ["rotstar", "opencv-sb", "opencv-classic", "cornersubpix", "saddle",
                                            "phase", "phase-keep", "star", "mrgingham", "mrgingham-noclahe",
                                            "rotstar-psf", "rotstar-psf-sim"]
    assert method_names(start="rotstar") == ["cornersubpix", "saddle", "phase", "phase-keep", "star"]
    assert method_names(needs=("phase", "star"), demo=True) == ["phase", "phase-keep", "star"]  # the paper's table


def test_unknown_names():
    with pytest.raises(ValueError, match="known: rotstar"):
        methods.method("nonsense")
    with pytest.raises(ValueError, match="known: symmetric, psf, psf-sim, opencv, saddle"):
        methods.refiner("nonsense")
    assert methods.description("my-own-set") == ""


@pytest.mark.parametrize("name", method_names(needs=("rotstar", "checkerboard")))
def test_every_method_finds_the_board(pose, name):
    p = PoseImages(pose["layout"], 65535.0, frames=pose["frames"], checkerboard=pose["checker"],
                   identity=pose["identity"])
    f = METHODS[name](p)
    assert isinstance(f, Found) and f.corners is not None, f.why
    if METHODS[name].relabel:
        from rotstar_mrcal.peers.checkerboard import match_to_reference

        f.corners = match_to_reference(f.corners, pose["truth"], 3.0)
    err = np.linalg.norm(f.corners - pose["truth"], axis=-1)
    assert np.nanmax(err) < 0.5
    assert (f.weights is not None) == (name == "rotstar-weighted")


def test_rotstar_is_detected_once_per_input(pose):
    p = PoseImages(pose["layout"], 65535.0, frames=pose["frames"], checkerboard=pose["checker"])
    METHODS["rotstar"](p)
    first = p.detection
    METHODS["saddle"](p)
    METHODS["rotstar-weighted"](p)
    assert p.detection is first


def test_start_methods_without_a_start(pose):
    p = PoseImages(pose["layout"], 65535.0, checkerboard=pose["checker"])
    assert METHODS["saddle"](p).why == "no start (rotstar found no board)"
    assert METHODS["opencv-sb"](PoseImages(pose["layout"], 65535.0)).why == "no checkerboard frame"
    start = pose["truth"] + 0.3
    q = METHODS["cornersubpix"](PoseImages(pose["layout"], 65535.0, checkerboard=pose["checker"], start=start,
                                           start_window=np.full(start.shape[:2], 5.0))).corners
    assert np.nanmax(np.linalg.norm(q - pose["truth"], axis=-1)) < 0.3


@pytest.mark.parametrize("name", list(REFINERS))
def test_every_refiner_refines(pose, name):
    images = pose["frames"] if REFINERS[name].needs == "rotstar" else pose["checker"]
    starts = pose["truth"].reshape(-1, 2) + 0.4
    q = REFINERS[name].refine(images, starts, 4)
    assert q.shape == starts.shape
    assert np.nanmedian(np.linalg.norm(q - pose["truth"].reshape(-1, 2), axis=-1)) < 0.1


def test_detect_methods_reads_the_registry(pose):
    from rotstar_mrcal.peers.cornersets import dataset_methods, detect_methods

    assert dataset_methods() == method_names(needs=("rotstar", "checkerboard"))
    found = detect_methods(pose["frames"], pose["layout"], 65535.0, pose["checker"], identity=pose["identity"])
    assert list(found) == dataset_methods()
    # a method without its own orientation is given rotstar's numbering
    assert np.nanmax(np.linalg.norm(found["opencv-sb"].corners - found["rotstar"].corners, axis=-1)) < 1
    with pytest.raises(ValueError, match="need other images"):
        detect_methods(pose["frames"], pose["layout"], 65535.0, pose["checker"], ["mrgingham"])

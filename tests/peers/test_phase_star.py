"""The paper's other screen patterns, detected from rotstar's corners: phase shifting and Schops et al.'s star

One small simulated D435 dataset of the paper's whole sequence (rotstar-pattern --paper-sequence on a
1000 x 860 screen: 5 x 4 corners, pitch 150, fringe period 150): two poses at 0.3 m, face-on and tilted
by 40 degrees. rotstar-detect --method phase / star must land within a fraction of a pixel of the truth;
saturated fringes reject the phase corners with the reason; a sequence without the frames is refused.
"""

from __future__ import annotations

import io

import numpy as np
import pytest

from rotstar_mrcal import dataset as ds, simulate
from rotstar_mrcal.peers.phase import phase_corners
from rotstar_mrcal.peers.registry import METHODS, PoseImages
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.vnl import read_corners

from conftest import TEST_SUPERSAMPLE

PAPER = make_layout(screen=(1000, 860), pitch=150, band=40, phase_period=150, star_segments=16)


def poses(model, layout):
    return [simulate.look_at_pose(model, layout, (640, 400), 0.3, tilt=np.radians(t), tilt_axis=0.3)
            for t in (0, 40)]


@pytest.fixture(scope="module")
def paper_seq(tmp_path_factory):
    seq = str(tmp_path_factory.mktemp("paper") / "seq")
    model = simulate.preset_model("d435")
    truth = simulate.write_dataset(seq, PAPER, model, poses(model, PAPER), simulate.Settings(seed=1, supersample=TEST_SUPERSAMPLE))
    return seq, truth


def errors(vnl: str, seq: str, truth) -> dict[str, np.ndarray]:
    """{pose: (ny, nx) distance of each corner from the truth, NaN where missing}"""
    c = read_corners(io.StringIO(vnl), PAPER.nx, PAPER.ny)
    return {k.split("/")[-2]: np.linalg.norm(v - truth.corners[k.split("/")[-2]], axis=-1) for k, v in c.items()
            if v is not None}


@pytest.mark.parametrize("method, rms, worst", [("phase", 0.03, 0.06), ("phase-keep", 0.03, 0.06), ("star", 0.03, 0.06)])
def test_corners_near_the_truth(paper_seq, run_cli, method, rms, worst):
    seq, truth = paper_seq
    r = run_cli("rotstar-detect", seq, "--method", method, "-q")
    assert r.returncode == 0, r.stderr
    e = errors(r.stdout, seq, truth)
    assert sorted(e) == ["pose000", "pose001"]
    for pose, d in e.items():
        assert np.isfinite(d).all(), (pose, d)  # every corner, face-on and at 40 degrees
        print(f"{method} {pose}: {np.sqrt(np.mean(d**2)):.4f} px RMS, max {d.max():.4f} px")
        assert np.sqrt(np.mean(d**2)) < rms and d.max() < worst


def test_phase_saturation_rejects_corners_with_the_reason(paper_seq):
    """Fringes clipped at full scale on the left half of the image: those corners NaN, 'saturated'; the others kept"""
    seq, truth = paper_seq
    p = ds.load_pose(seq, "pose000", PAPER)
    start = truth.corners["pose000"] + 0.2  # a start a little off, as rotstar's corners might be
    left = np.arange(p.phase.shape[-1]) < 655  # between two columns of corners (about 31 px apart)
    clipped = np.where(left, np.minimum(1.4 * p.phase, p.full_scale), p.phase)
    r = phase_corners(clipped, start, PAPER.corner_phase(), p.full_scale)
    on_left = start[..., 0] < 655
    assert on_left.any() and (~on_left).any()
    assert np.isnan(r.corners[on_left]).all() and set(r.reason[on_left]) == {"saturated: a sample of the window at full scale"}
    assert np.isfinite(r.corners[~on_left]).all() and set(r.reason[~on_left]) == {""}
    assert np.linalg.norm(r.corners[~on_left] - truth.corners["pose000"][~on_left], axis=-1).max() < 0.06
    # saturation="keep" (no check): the clipped corners are kept, and are worse
    kept = phase_corners(clipped, start, PAPER.corner_phase(), p.full_scale, saturation="keep")
    assert np.isfinite(kept.corners).all()
    err = np.linalg.norm(kept.corners - truth.corners["pose000"], axis=-1)
    assert err[on_left].mean() > 2 * err[~on_left].mean()
    # no fringes at all (a flat grey): every corner 'fringe modulation too low'
    flat = phase_corners(np.full_like(p.phase, 0.5 * p.full_scale), start, PAPER.corner_phase(), p.full_scale)
    assert np.isnan(flat.corners).all() and set(flat.reason.ravel()) == {"fringe modulation too low"}
    # through the registry: the corners and the reasons
    f = METHODS["phase"](PoseImages(PAPER, p.full_scale, phase=clipped, start=start, start_window=np.full(start.shape[:2], 5.0)))
    assert np.array_equal(np.isnan(f.corners[..., 0]), on_left) and f.reasons[on_left][0].startswith("saturated")


@pytest.mark.slow  # make test-slow: a longer end-to-end run
def test_saturated_exposure_cli(tmp_path, run_cli):
    """Overexposed (the white at 1.3 x full scale): rotstar still finds the board; phase says every corner is
    saturated and writes no board"""
    seq = str(tmp_path / "bright")
    model = simulate.preset_model("d435")
    simulate.write_dataset(seq, PAPER, model, poses(model, PAPER)[:1], simulate.Settings(seed=2, gain=1.3))
    assert run_cli("rotstar-detect", seq, "-q").returncode == 0
    r = run_cli("rotstar-detect", seq, "--method", "phase", "-q")
    assert r.returncode == 1
    assert "pose000: skipped: phase: no corner: 20 saturated: a sample of the window at full scale" in r.stderr
    assert "0 of 1 poses gave a board" in r.stderr


def test_sequence_without_the_frames(tmp_path, run_cli):
    """The default sequence (no --paper-sequence): --method phase | star says in one line, naming pattern.json,
    that it cannot run and that the rotating-star corners are written instead, writes them, and exits 1"""
    plain = make_layout(screen=(1000, 860), pitch=150, band=40)
    seq = str(tmp_path / "seq")
    model = simulate.preset_model("d435")
    simulate.write_dataset(seq, plain, model, poses(model, plain)[:1], simulate.Settings(seed=3, supersample=1))  # (counts only)
    ref = run_cli("rotstar-detect", seq, "-q")
    assert ref.returncode == 0 and ref.stdout.count("rotstar_00.png") == plain.nx * plain.ny
    for method, what in (("phase", "phase-shift frames"), ("star", "star frame")):
        r = run_cli("rotstar-detect", seq, "--method", method, "-q")
        assert r.returncode == 1 and r.stdout == ref.stdout
        line = next(x for x in r.stderr.splitlines() if "cannot run" in x)
        assert "pattern.json" in line and f"no {what}" in line and "--paper-sequence" in line
        assert "writing the rotating-star corners (--method rotstar) instead" in line
    r = run_cli("rotstar-detect", seq, "--method", "phase", "--weights")
    assert r.returncode == 2 and "--weights and --refine are rotstar's" in r.stderr

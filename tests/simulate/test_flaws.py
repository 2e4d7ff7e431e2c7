"""rotstar-simulate's display and lens flaws: --screen-gamma (a screen whose gamma is not the pattern's) and
--seidel (a field-dependent wavefront PSF), on tiny renders"""

import json
import os
import pickle

import numpy as np
import pytest

from rotstar_mrcal import dataset as ds
from rotstar_mrcal.cli.simulate import main
from rotstar_mrcal.optics import LensPSF, Seidel
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.simulate import load_truth

PAPER = make_layout(screen=(800, 600), pitch=100, band=24, phase_period=100, star_segments=16, identity=False)
QUIET = ["--camera", "pinhole-small", "--poses", "1", "--noise", "0", "--supersample", "2"]


@pytest.fixture
def pat(tmp_path):
    p = tmp_path / "pat"
    ds.write_pattern(str(p), PAPER)
    return p


def render(tmp_path, pat, name, *extra):
    out = str(tmp_path / name)
    assert main(["--out", out, "--pattern", str(pat), *QUIET, *extra]) == 0
    return ds.load_pose(out, "pose000", PAPER), load_truth(out)


def test_screen_gamma(tmp_path, pat, capsys):
    """A screen of higher gamma than the pattern's 2.2 darkens the fringes' greys; binary frames keep all but
    their anti-aliased edge pixels"""
    a, _ = render(tmp_path, pat, "same")
    b, t = render(tmp_path, pat, "high", "--screen-gamma", "2.6")
    assert t.settings["display_gamma"] == 2.2 and t.settings["screen_gamma"] == 2.6
    white = np.percentile(a.checkerboard, 99)
    mid = (a.phase > 0.45 * white) & (a.phase < 0.55 * white)
    ratio = np.median(b.phase[mid] / a.phase[mid])  # luminance^(2.6 / 2.2): 0.5 -> 0.44
    assert 0.84 < ratio < 0.92, ratio
    for x, y in ((a.rotstar, b.rotstar), (a.checkerboard, b.checkerboard)):  # only anti-aliased edge pixels move
        flat = (x < 0.05 * white) | (x > 0.97 * white)
        assert flat.mean() > 0.5 and np.abs(x[flat] - y[flat]).max() < 0.01 * white
    # the gamma pattern.json records is the encoded one: the same screen gamma is no mismatch
    d = json.load(open(pat / "pattern.json"))
    d["display_gamma"] = 2.6
    json.dump(d, open(pat / "pattern.json", "w"))
    c, t = render(tmp_path, pat, "recorded", "--screen-gamma", "2.6")
    assert t.settings["display_gamma"] == 2.6
    assert np.abs(c.phase.astype(float) - a.phase).max() < 0.01 * 65535  # 8-bit steps only
    capsys.readouterr()


def test_seidel(tmp_path, pat, capsys):
    """--seidel renders through the field-dependent wavefront PSF, the same in worker processes"""
    g, _ = render(tmp_path, pat, "gauss", "--blur", "0")
    s, t = render(tmp_path, pat, "seidel", "--seidel", "coma=1.5,focus=0.3")
    assert t.settings["psf"]["kind"] == "seidel-field"
    assert t.settings["psf"]["seidel_at_corners"]["tilt"] == -1.5
    edges = lambda img: np.abs(np.diff(img.astype(float), axis=1)).max()  # noqa: E731
    assert edges(s.checkerboard) < 0.8 * edges(g.checkerboard)  # the lens blurs
    out = str(tmp_path / "two")
    assert main(["--out", out, "--pattern", str(pat), *QUIET, "--poses", "2", "--jobs", "2",
                 "--seidel", "coma=1.5,focus=0.3"]) == 0
    assert np.array_equal(ds.load_pose(out, "pose000", PAPER).checkerboard, s.checkerboard)
    capsys.readouterr()


def test_lens_psf_pickles():
    psf = LensPSF(Seidel(coma=1.0, astigmatism=0.5), (64, 48))
    r = psf.radius_px
    q = pickle.loads(pickle.dumps(psf))
    assert q._psf is None and q.radius_px == r and q.seidel == psf.seidel


@pytest.mark.parametrize("args, says", [
    (["--seidel", "coma=x"], "coma must be a finite number"),
    (["--seidel", "spin=1"], "TERM one of tilt, focus"),
    (["--seidel", "coma=1,coma=2"], "coma given twice"),
    (["--seidel", "coma=1", "--blur", "1"], "--seidel replaces the Gaussian --blur"),
    (["--screen-gamma", "-1"], "--screen-gamma"),
    (["--screen-gamma", "nan"], "--screen-gamma"),
])
def test_bad_values(tmp_path, pat, capsys, args, says):
    with pytest.raises(SystemExit) as e:
        main(["--out", str(tmp_path / "x"), "--pattern", str(pat), *QUIET, *args])
    err = capsys.readouterr().err
    last = err.strip().splitlines()[-1]  # after the usage, one line
    assert e.value.code == 2 and last.startswith("rotstar-simulate: error:") and says in last
    assert not os.path.exists(tmp_path / "x")


def test_bad_recorded_gamma(tmp_path, pat, capsys):
    d = json.load(open(pat / "pattern.json"))
    d["display_gamma"] = "bright"
    json.dump(d, open(pat / "pattern.json", "w"))
    assert main(["--out", str(tmp_path / "x"), "--pattern", str(pat), *QUIET, "--screen-gamma", "2.4"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "display_gamma 'bright'" in err and str(pat) in err

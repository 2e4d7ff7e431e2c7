"""rotstar-calibrate's checks of its inputs and of the fit itself (issue 20: items 1-3 and 9)

Fast: hand-made corner sets (test_validate.corner_dataset: noisy true corners
of a simulated D435, no rendering) calibrated in this process.
"""

from __future__ import annotations

import codecs
import json
import os

import mrcal
import numpy as np
import pytest

from rotstar_mrcal.cli import calibrate as calibrate_cli
from rotstar_mrcal.calibrate import solve as cal
from rotstar_mrcal.calibrate.cornerset import SourceError, load_corner_set
from evaluate.test_validate import corner_dataset


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    """A 10-board corner set (0.01 px noise) and its lean calibration"""
    root = tmp_path_factory.mktemp("clean")
    vnl = corner_dataset(str(root / "d"), 10, seed=5, sigma=0.01)
    c = cal.calibrate(load_corner_set(vnl), str(root / "cal"), in_process=True)
    assert c.ok and c.model_path, c.failures
    return vnl, c


def _encoded(text: str, how: str) -> bytes:
    if how == "crlf":
        return text.replace("\n", "\r\n").encode("ascii")
    if how == "cr":
        return text.replace("\n", "\r").encode("ascii")
    if how == "utf-8-bom":
        return codecs.BOM_UTF8 + text.encode("utf-8")
    if how == "utf-16":
        return text.replace("\n", "\r\n").encode("utf-16")  # with its byte-order mark, as Windows tools write it
    raise ValueError(how)


@pytest.mark.parametrize("how", ["crlf", "cr", "utf-8-bom", "utf-16"])
def test_corners_file_in_any_line_end_and_encoding_is_read_as_text(clean, tmp_path, how):
    vnl, _ = clean
    other = tmp_path / os.path.basename(vnl)
    other.write_bytes(_encoded(open(vnl).read(), how))
    a = load_corner_set(vnl)
    b = load_corner_set(str(other), pattern=os.path.dirname(vnl), imagersize=a.imagersize)
    assert a.files == b.files and np.array_equal(a.corners, b.corners) and a.weights == b.weights
    copy = cal.mrcal_corners(str(other), str(tmp_path / "m"))
    assert copy != str(other) and open(copy, "rb").read() == open(vnl, "rb").read()  # what mrcal reads


def test_crlf_corners_file_calibrates_as_the_plain_one(clean, tmp_path):
    """mrcal read a CRLF file's level '0.5\\r' wrongly: fits of 0.007 to 0.46 px, models 12 px off"""
    vnl, c = clean
    crlf = tmp_path / "d" / "corners.vnl"
    os.makedirs(crlf.parent)
    for f in os.listdir(os.path.dirname(vnl)):  # the dataset next to it (pattern.json, truth)
        if f != "corners.vnl" and os.path.isfile(os.path.join(os.path.dirname(vnl), f)):
            os.symlink(os.path.join(os.path.dirname(vnl), f), crlf.parent / f)
    crlf.write_bytes(_encoded(open(vnl).read(), "crlf"))
    c2 = cal.calibrate(load_corner_set(str(crlf)), str(tmp_path / "cal"), in_process=True)
    assert c2.ok and c2.model_path
    assert "--corners-cache " + str(tmp_path / "cal" / "candidates" / "corners.vnl") in c2.candidates[0].command
    m1, m2 = mrcal.cameramodel(c.model_path), mrcal.cameramodel(c2.model_path)
    assert np.allclose(m1.intrinsics()[1], m2.intrinsics()[1], rtol=0, atol=1e-6)


def test_corners_file_that_is_not_text_is_refused_in_one_line(clean, tmp_path, capsys):
    vnl, _ = clean
    bad = tmp_path / "bad.vnl"
    bad.write_bytes(b"# filename x y level\n\xff\xfe\x00garbage\x80\n")
    rc = calibrate_cli.main([os.path.dirname(vnl), "--corners", str(bad), "--outdir", str(tmp_path / "cal")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and str(bad) in err[0] and "not a text file" in err[0], err


def test_non_finite_corner_is_named(clean, tmp_path, capsys):
    """Was: 'the valid-intrinsics region is empty' after a solve"""
    vnl, _ = clean
    lines = open(vnl).read().splitlines(keepends=True)
    name, _, _, level = lines[5].split()
    for i, value in enumerate(("nan", "inf")):
        bad = tmp_path / f"bad{i}.vnl"
        bad.write_text("".join(lines[:5]) + f"{name} {value} 12.5 {level}\n" + "".join(lines[6:]))
        rc = calibrate_cli.main([os.path.dirname(vnl), "--corners", str(bad), "--outdir", str(tmp_path / "cal")])
        err = capsys.readouterr().err.strip().splitlines()
        assert rc == 2 and len(err) == 1 and str(bad) in err[0] and name in err[0], err
        assert f"{value} 12.5 are not finite" in err[0] and "mrcal" not in err[0], err


def test_imagersize_that_is_not_the_images_is_named(clean, tmp_path):
    """Was: 'images of size 1280x800 among 640x400 ones'"""
    vnl, _ = clean
    with pytest.raises(SourceError, match=r"the imager size given, 640x400, is not the size of the images .*\(1280x800"):
        load_corner_set(vnl, imagersize=(640, 400))
    assert load_corner_set(vnl, imagersize=(1280, 800)).imagersize == (1280, 800)


def _copy_with(vnl: str, dest, rewrite) -> str:
    """vnl's dataset (symlinked) with a corners file rewritten by rewrite(lines) -> lines"""
    os.makedirs(dest)
    src = os.path.dirname(vnl)
    for f in os.listdir(src):
        if f != os.path.basename(vnl):
            os.symlink(os.path.join(src, f), os.path.join(dest, f))
    out = os.path.join(dest, os.path.basename(vnl))
    with open(out, "w") as f:
        f.write("".join(rewrite(open(vnl).read().splitlines(keepends=True))))
    return out


def _truth_error(model_path, vnl):
    from rotstar_mrcal.simulate import load_truth
    from rotstar_mrcal.evaluate.truth import truth_error, truth_poses_of

    truth = load_truth(os.path.dirname(vnl))
    m = mrcal.cameramodel(model_path)
    return truth_error(m, truth.model, truth_poses_of(m, truth.rt_cam_board)).median


def test_board_with_shuffled_rows_is_dropped_and_named(clean, tmp_path, capsys):
    """Was: the model written with exit 0, fit 44.5 px, 30.9 px from the true camera"""
    vnl, c = clean
    board = slice(1 + 3 * 126, 1 + 4 * 126)  # pose003's rows

    def shuffle(lines):
        rows = lines[board]
        lines[board] = [rows[i] for i in np.random.default_rng(1).permutation(len(rows))]
        return lines

    bad = _copy_with(vnl, tmp_path / "d", shuffle)
    rc = calibrate_cli.main([os.path.dirname(bad), "--corners", bad, "--outdir", str(tmp_path / "cal")])
    out = capsys.readouterr()
    assert rc == 0, out.err
    assert "dropping pose003/rotstar_00.png: its corners are not in grid order" in out.err
    c2 = json.load(open(tmp_path / "cal" / "calibration.json"))
    assert list(c2["dropped"]) == ["pose003"] and c2["candidates"][0]["stats"]["boards"] == 9
    assert _truth_error(out.out.strip(), vnl) < 2 * _truth_error(c.model_path, vnl) + 0.05  # was 30.9 px
    assert "--corners-cache " + str(tmp_path / "cal" / "candidates" / "corners.vnl") in c2["candidates"][0]["command"]


def test_transposed_boards_are_named(clean, tmp_path, capsys):
    """Every board written in rows of 9 for a 14 x 9 pattern: was 'the valid-intrinsics region is empty'"""
    vnl, _ = clean
    cs = load_corner_set(vnl)

    def transpose(lines):
        from rotstar_mrcal.vnl import write_corners
        import io

        s = io.StringIO()
        write_corners(s, [(f, g.transpose(1, 0, 2).reshape(9, 14, 2)) for f, g in zip(cs.files, cs.corners)])
        return s.getvalue().splitlines(keepends=True)

    bad = _copy_with(vnl, tmp_path / "d", transpose)
    rc = calibrate_cli.main([os.path.dirname(bad), "--corners", bad, "--outdir", str(tmp_path / "cal")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and bad in err[0], err
    assert "the board is transposed" in err[0] and "rows of 9, not of 14" in err[0], err


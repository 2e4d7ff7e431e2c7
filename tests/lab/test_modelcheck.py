"""The calib-bench table and the doc block it rewrites (rotstar_lab.modelcheck); the runs themselves: make calib-bench"""

from rotstar_lab.modelcheck import TOLERANCE, printed_command, table


def test_printed_command_is_parsed():
    stderr = ("rotstar-detect: 3 of 3 poses gave a board\nnext, calibrate with:\n"
              "  mrcal-calibrate-cameras --corners-cache c.vnl --focal 640 --outdir . 'seq/*/rotstar_00.png'\n")
    assert printed_command(stderr) == ["mrcal-calibrate-cameras", "--corners-cache", "c.vnl", "--focal", "640",
                                       "--outdir", ".", "seq/*/rotstar_00.png"]


def test_table_says_which_default_failed():
    good = {"median_px": 0.006, "worst_px": 0.02, "lensmodel": "LENSMODEL_OPENCV8", "reason": "lean"}
    rows = [{"poses": 12, "boards": 12, "default": good, "printed": good, "splined": {"error": "x"}, "ok": True},
            {"poses": 20, "boards": 20, "default": {**good, "median_px": 0.05}, "printed": good,
             "splined": good, "ok": 0.05 <= TOLERANCE * 0.006}]
    t = table(rows)
    lines = [x for x in t.splitlines() if x.startswith("| 1") or x.startswith("| 2")]
    assert lines[0].endswith("| yes |") and lines[1].endswith("| NO |") and "0.0500 / 0.020" in lines[1]
    assert "12 poses, rotstar-calibrate's reason: lean" in t



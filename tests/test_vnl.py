"""corners.vnl as mrcal reads it"""

import io
import os

import mrcal
import numpy as np
import pytest

from rotstar_mrcal.vnl import read_corners, write_corners


def boards(nx=5, ny=4, n=4, seed=0):
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        j, i = np.mgrid[0:ny, 0:nx]
        g = np.stack((100 + 30 * i, 50 + 30 * j), -1) + rng.uniform(-1, 1, (ny, nx, 2))
        out.append((f"seq/pose{k:03d}/rotstar_00.png", g))
    return out


def test_mrcal_reads_what_we_write(tmp_path):
    nx, ny = 5, 4
    b = boards(nx, ny)
    b[1][1][2, 3] = np.nan  # one missing corner
    b.append(("seq/pose004/rotstar_00.png", None))  # a pose without a board
    fn = tmp_path / "corners.vnl"
    with open(fn, "w") as f:
        write_corners(f, b)
    obs, indices, paths = mrcal.compute_chessboard_corners(
        nx, ny, globs_per_camera=("seq/*/rotstar_00.png",), corners_cache_vnl=str(fn), weight_column_kind="level")
    # mrcal's order is board point (i, j) at record j*nx + i, i.e. our (ny, nx) grid
    assert obs.shape == (4, ny, nx, 3)
    for k in range(4):
        g = b[k][1]
        ok = np.isfinite(g[..., 0])
        assert np.allclose(obs[k][..., :2][ok], g[ok], atol=1e-6)
        assert np.all(obs[k][..., 2][ok] == 1.0)  # level 0.5 is read as level 0: weight 1
        assert np.all(obs[k][..., 2][~ok] < 0)  # missing -> outlier weight


def test_weights_column_and_roundtrip(tmp_path):
    nx, ny = 5, 4
    b = boards(nx, ny, 3)
    w = [np.full((ny, nx), 0.5), np.full((ny, nx), 2.0), np.ones((ny, nx))]
    w[2][0, 0] = np.nan
    fn = tmp_path / "w.vnl"
    with open(fn, "w") as f:
        write_corners(f, b, weights=w)
    text = fn.read_text()
    assert text.startswith("# filename x y weight\n")
    obs, *_ = mrcal.compute_chessboard_corners(
        nx, ny, globs_per_camera=("seq/*/rotstar_00.png",), corners_cache_vnl=str(fn), weight_column_kind="weight")
    assert np.allclose(obs[0][..., 2], 0.5) and np.allclose(obs[1][..., 2], 2.0)
    assert obs[2][0, 0, 2] < 0
    back = read_corners(io.StringIO(text), nx, ny)
    assert np.allclose(back["seq/pose000/rotstar_00.png"], b[0][1], atol=1e-6)


def test_rejects_names_mrcal_cannot_parse():
    with pytest.raises(ValueError, match="ASCII"):
        write_corners(io.StringIO(), [("seq/pose 1/a.png", None)])
    with pytest.raises(ValueError, match="ASCII"):
        write_corners(io.StringIO(), [("seq/posé/a.png", None)])


def test_every_mrcal_tool_reads_the_level_column(tmp_path):
    """mrcal-cull-corners reads the 4th column as a weight, mrcal-calibrate-cameras as a level: both keep every corner"""
    import os
    import subprocess
    import sys

    nx, ny = 5, 4
    b = boards(nx, ny, 6)
    b[1][1][2, 3] = np.nan
    fn = tmp_path / "corners.vnl"
    with open(fn, "w") as f:
        write_corners(f, b)
    as_weight, *_ = mrcal.compute_chessboard_corners(
        nx, ny, globs_per_camera=("seq/*/rotstar_00.png",), corners_cache_vnl=str(fn), weight_column_kind="weight")
    as_level, *_ = mrcal.compute_chessboard_corners(
        nx, ny, globs_per_camera=("seq/*/rotstar_00.png",), corners_cache_vnl=str(fn), weight_column_kind="level")
    valid = as_level[..., 2] > 0
    assert np.array_equal(valid, as_weight[..., 2] > 0) and valid.sum() == 6 * nx * ny - 1
    assert np.all(as_level[..., 2][valid] == 1.0)  # mrcal-calibrate-cameras: weight 1, residuals in pixels
    assert np.ptp(as_weight[..., 2][valid]) == 0  # mrcal-cull-corners: one weight for all
    cull = os.path.join(os.path.dirname(sys.executable), "mrcal-cull-corners")
    r = subprocess.run([cull, "--cull-random-observations-ratio", "0.5", "--object-width-n", str(nx),
                        "--object-height-n", str(ny)], stdin=open(fn), capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    rows = [line.split() for line in r.stdout.splitlines() if not line.startswith("#")]
    assert len({row[0] for row in rows}) == 3  # half of the 6 boards kept, ...
    assert sum(row[3] == "0" for row in rows) >= 3 * nx * ny - 1  # ... their corners kept, as level 0
    r = subprocess.run([cull, "--cull-left-of", "150"], stdin=open(fn), capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    culled = [line.split() for line in r.stdout.splitlines() if not line.startswith("#")]
    assert any(row[3] == "-" for row in culled) and any(row[3] == "0.5" for row in culled)


# ---------------------------------------------------------------------------
# mrcal's row rule: a board needs more than 2 * min(nx, ny) valid corners
# ---------------------------------------------------------------------------
def raw_vnl(path, boards, nx, ny):
    """A corners.vnl written row by row, without write_corners' rule: what another detector might write"""
    with open(path, "w") as f:
        f.write("# filename x y level\n")
        for fn, g in boards:
            for x, y in np.asarray(g, float).reshape(-1, 2):
                f.write(f"{fn} - - -\n" if not np.isfinite(x) else f"{fn} {x:.6f} {y:.6f} 0\n")


def with_valid(grid, n):
    """grid with only its first n corners (mrcal order) kept"""
    g = np.array(grid, float).reshape(-1, 2)
    g[n:] = np.nan
    return g.reshape(np.shape(grid))


@pytest.mark.parametrize("nx, ny", [(5, 4), (14, 9)])
def test_mrcal_drops_boards_at_the_limit_and_we_agree(tmp_path, nx, ny):
    """mrcal itself (not our reading of its source) keeps a board only above 2 * min(nx, ny) corners"""
    from rotstar_mrcal.vnl import mrcal_keeps, mrcal_min_corners

    limit = mrcal_min_corners(nx, ny)
    assert limit == 2 * min(nx, ny)
    full = boards(nx, ny, 3)
    b = [(full[0][0], with_valid(full[0][1], limit)), (full[1][0], with_valid(full[1][1], limit + 1)), full[2]]
    fn = tmp_path / "raw.vnl"
    raw_vnl(fn, b, nx, ny)
    _, _, paths = mrcal.compute_chessboard_corners(
        nx, ny, globs_per_camera=("seq/*/rotstar_00.png",), corners_cache_vnl=str(fn), weight_column_kind="level")
    assert [os.path.basename(os.path.dirname(p)) for p in paths] == ["pose001", "pose002"]
    assert [mrcal_keeps(g) for _, g in b] == [False, True, True]


def test_sparse_board_written_as_no_board(tmp_path):
    nx, ny = 14, 9
    full = boards(nx, ny, 3)
    b = [(full[0][0], with_valid(full[0][1], 14)), full[1], (full[2][0], None)]
    out = io.StringIO()
    sparse = write_corners(out, b)
    assert [(s.file, s.corners, s.limit) for s in sparse] == [("seq/pose000/rotstar_00.png", 14, 18)]
    rows = [r for r in out.getvalue().splitlines()[1:] if r.startswith("seq/pose000/")]
    assert rows == ["seq/pose000/rotstar_00.png - - -"]  # one row: mrcal's "no board"
    back = read_corners(io.StringIO(out.getvalue()), nx, ny)
    assert back["seq/pose000/rotstar_00.png"] is None and back["seq/pose001/rotstar_00.png"] is not None
    # mrcal reads the same observations from our file as from the raw one
    raw, ours = tmp_path / "raw.vnl", tmp_path / "ours.vnl"
    raw_vnl(raw, [x for x in b if x[1] is not None], nx, ny)
    ours.write_text(out.getvalue())
    got = [mrcal.compute_chessboard_corners(nx, ny, globs_per_camera=("seq/*/rotstar_00.png",),
                                            corners_cache_vnl=str(f), weight_column_kind="level") for f in (raw, ours)]
    assert got[0][2] == got[1][2] and np.array_equal(got[0][0], got[1][0])


def test_counts_what_mrcal_counts_negative_coordinates_and_weights():
    """x < 0 or y < 0 is 'missing' to mrcal, and so is a weight <= 0: neither counts toward the limit"""
    from rotstar_mrcal.vnl import mrcal_valid

    nx, ny = 5, 4
    g = boards(nx, ny, 1)[0][1]
    g[0, 0] = (-0.2, 10.0)
    g[0, 1] = (10.0, -0.01)
    w = np.ones((ny, nx))
    w[1, :3] = (0.0, -1.0, np.nan)
    assert mrcal_valid(g).sum() == nx * ny - 2 and mrcal_valid(g, w).sum() == nx * ny - 5
    out = io.StringIO()
    write_corners(out, [("a/x.png", g)])
    assert out.getvalue().splitlines()[1:3] == ["a/x.png - - -", "a/x.png - - -"]
    g2 = with_valid(g, 9)  # 9 given, 2 of them negative: 7 valid <= 8
    assert [s.corners for s in write_corners(io.StringIO(), [("a/x.png", g2)])] == [7]
    w2 = np.ones((ny, nx)); w2[2:] = 0  # 10 corners given, 10 with weight > 0, 2 negative: 8 <= 8
    assert [s.corners for s in write_corners(io.StringIO(), [("a/x.png", g)], weights=[w2])] == [8]


def test_calibration_uses_the_boards_we_say(tmp_path):
    """The real mrcal-calibrate-cameras on a file with a sparse board: it solves exactly the boards written"""
    from rotstar_mrcal.pattern.layout import make_layout
    from rotstar_mrcal.simulate import preset_model, random_poses, true_corners
    from rotstar_mrcal.calibrate.solve import calibrate_argv, run_calibration

    model, layout = preset_model("d435"), make_layout()
    rts = random_poses(model, layout, 7, np.random.default_rng(3), max_tilt_deg=40.0)
    rng = np.random.default_rng(4)
    grids = true_corners(model, layout, rts) + rng.normal(0, 0.02, (7, layout.ny, layout.nx, 2))
    b = [(f"seq/pose{k:03d}/rotstar_00.png", g) for k, g in enumerate(grids)]
    b[2] = (b[2][0], with_valid(b[2][1], 18))  # 18 corners: mrcal would drop it
    b[5] = (b[5][0], with_valid(b[5][1], 19))  # 19: kept
    fn = tmp_path / "corners.vnl"
    with open(fn, "w") as f:
        sparse = write_corners(f, b)
    assert [s.file for s in sparse] == ["seq/pose002/rotstar_00.png"]
    argv = calibrate_argv(str(fn), layout, model.imagersize(), 640, "LENSMODEL_OPENCV4", str(tmp_path / "cal"),
                          "*/rotstar_00.png")
    m = run_calibration(argv, in_process=True)
    used = sorted(os.path.basename(os.path.dirname(p)) for p in m.optimization_inputs()["imagepaths"])
    assert used == [f"pose{k:03d}" for k in range(7) if k != 2]


def test_corner_sets_count_the_boards_mrcal_uses(tmp_path):
    """A file another detector wrote, with a sparse board: rotstar-calibrate's checks count what mrcal will use"""
    from rotstar_mrcal import dataset
    from rotstar_mrcal.pattern.layout import make_layout
    from rotstar_mrcal.calibrate.cornerset import load_corner_set

    layout = make_layout()
    dataset.write_pattern(str(tmp_path), layout)
    b = boards(layout.nx, layout.ny, 4)
    b[1] = (b[1][0], with_valid(b[1][1], 18))
    raw_vnl(tmp_path / "corners.vnl", b, layout.nx, layout.ny)
    cs = load_corner_set(str(tmp_path / "corners.vnl"), imagersize=(1280, 800), truth=False)
    assert cs.files == [b[k][0] for k in (0, 2, 3)]

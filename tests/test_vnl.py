"""corners.vnl as mrcal reads it"""

import io

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

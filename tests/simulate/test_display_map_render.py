"""rotstar-simulate --display-map: frames shown shifted or stretched by a per-frame affine in display pixels"""

import mrcal
import numpy as np
import pytest

from rotstar_mrcal import dataset as ds
from rotstar_mrcal.cli.simulate import main
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal.simulate import load_truth
from rotstar_mrcal.simulate.camera import camera_rays, preset_model
from rotstar_mrcal.simulate.dataset import frame_maps
from rotstar_mrcal.simulate.display import centred_maps, parse_display_maps, show_frames
from rotstar_mrcal.simulate.irradiance import board_hits, render_irradiance
from rotstar_mrcal.simulate.screen import exact_frames, make_screen

LAYOUT = make_layout(screen=(800, 600), pitch=100, band=24, identity=False)


def edge_position(column: np.ndarray) -> float:
    """Where a dark-to-bright step of a column lies, in the area sense (pixel v covers [v, v+1))"""
    return len(column) - float(column.sum())


@pytest.mark.parametrize("spec, want", [("0:0,2", 302.0), ("0:0,-1.25", 298.75),
                                        ("0:0,0,0,1px@bottom", 299.5), ("0:0,0,0,1px@top", 300.5),
                                        ("0:0,0,0,-2000@bottom", 300.6), ("0:0,0,0,1px", 300.0)])
def test_an_edge_is_shown_where_the_map_puts_it(spec, want):
    """A horizontal edge at v = 300 of a 600-row screen: shifted, or one display pixel taller about an anchor

    Bilinear resampling puts a stretched edge within |stretch| / 2 display px (here 1e-3) of the map's point."""
    f = np.zeros((1, 600, 40), np.float32)
    f[:, 300:] = 1
    g = show_frames(f, parse_display_maps(spec, 1, (40, 600)))
    assert edge_position(g[0, :, 20]) == pytest.approx(want, abs=1e-3 if ',0,0,' in spec else 1e-4)


def test_maps_relative_to_their_mean_and_other_frames_at_the_mean():
    m = frame_maps(LAYOUT, display_maps=parse_display_maps("3:0,0,0,1px@bottom;2:0,2", 8, (800, 600)))
    star = np.array([f["kind"] == "rotstar" for f in LAYOUT.frames()])
    assert np.allclose(m[star].mean(axis=0), np.eye(2, 3), atol=1e-12)
    assert np.array_equal(m[~star], np.repeat(np.eye(2, 3)[None], (~star).sum(), axis=0))
    assert m[2, 1, 2] - m[1, 1, 2] == pytest.approx(2.0, abs=1e-3)
    assert m[3, 1, 1] / m[1, 1, 1] == pytest.approx(1 + 1 / 600, abs=1e-9)
    assert np.allclose(centred_maps(m[star]), m[star])


def test_a_shifted_frame_renders_as_the_board_moved_by_the_same_display_pixels():
    """The map acts in the screen's plane: 2 display px down = the board moved 2 pixel pitches along its y"""
    model = preset_model("pinhole-small")
    rt = np.array((0.05, -0.1, 0.02, -0.0385, -0.0289, 0.12))
    frames = exact_frames(LAYOUT)[:1]
    shown = show_frames(frames, parse_display_maps("0:0,2", 1, (800, 600)))
    a = render_irradiance(make_screen(shown, LAYOUT), model, rt, supersample=2, psf=0.0)
    moved = rt.copy()
    moved[3:] += mrcal.R_from_r(rt[:3]) @ np.array([0, 2 * LAYOUT.pixel_pitch_m, 0])
    b = render_irradiance(make_screen(frames, LAYOUT), model, moved, supersample=2, psf=0.0)
    grid = camera_rays(model)
    u, v = (x[grid.pad:grid.pad + 400, grid.pad:grid.pad + 640] for x in board_hits(grid.rays, rt, LAYOUT))
    inner = (u > 10) & (u < 790) & (v > 10) & (v < 590)  # away from the screen's edge (the shown frame extended)
    assert inner.sum() > 20000 and a[0][inner].std() > 0.2
    assert np.abs(a[0][inner] - b[0][inner]).max() < 1e-6


def test_display_map_cli(tmp_path, capsys):
    """--display-map goes into the truth; bad specs are one line naming --display-map, no traceback"""
    out, pat = str(tmp_path / "s"), str(tmp_path / "pat")
    ds.write_pattern(pat, LAYOUT)
    args = ["--pattern", pat, "--camera", "pinhole-small", "--poses", "1", "--noise", "0", "--supersample", "1"]
    assert main(["--out", out, *args, "--display-map", "2:0,2;3:0,1,0,1px@bottom"]) == 0
    assert np.array(load_truth(out).settings["display_maps"]).shape == (8, 2, 3)
    assert ds.load_pose(out, "pose000", ds.read_pattern(out)[1]).rotstar.shape[0] == 8
    for bad, why in [("9:1,1", "out of range"), ("2:0", "2 numbers"), ("2:0,x", "not numbers"),
                     ("2:0,0,0,1@middle", "anchor"), ("1:0,0;1:0,1", "twice"), ("2:0,0,0,5e5", "ppm"),
                     (";", "no entry")]:
        capsys.readouterr()
        assert main(["--out", str(tmp_path / "t"), *args, "--display-map", bad]) != 0
        err = capsys.readouterr().err
        assert "--display-map" in err and why in err and len(err.strip().splitlines()) == 1, err

"""Identity codes: every element's word read back, every misreading rejected, never mislabelled"""

import itertools

import numpy as np
import pytest

from rotstar_mrcal.pattern.identity import IdentityCode, code_from_dict
from rotstar_mrcal.pattern.layout import layout_from_dict, make_layout
from rotstar_mrcal.pattern.render import render_frame


@pytest.mark.parametrize("nx, ny", [(3, 3), (9, 9), (14, 9), (20, 15), (30, 20)])
def test_code_names_every_element_with_distance_four(nx, ny):
    code = IdentityCode.for_grid(nx, ny)
    W = code.codewords.astype(int)
    assert W.shape == (nx * ny, code.nframes)
    assert np.all(W.sum(axis=1) == code.weight)
    D = (W[:, None, :] != W[None, :, :]).sum(-1)
    np.fill_diagonal(D, 99)
    assert D.min() >= 4
    assert np.all(np.abs(W.mean(axis=0) - 0.5) < 0.15), "every frame shows about half the elements white"


def test_fewest_frames_for_the_default_grid():
    assert IdentityCode.for_grid(14, 9).nframes == 13


def test_reads_back_under_any_exposure_and_gamma():
    code = IdentityCode.for_grid(14, 9)
    W = code.codewords.astype(float)
    rng = np.random.default_rng(1)
    black = rng.uniform(0, 60, (len(W), 1))
    white = black + rng.uniform(30, 200, (len(W), 1))  # vignetting: every element its own contrast
    levels = (black + (white - black) * W) ** rng.uniform(0.5, 2.0)
    levels = np.minimum(levels, np.percentile(levels, 70))  # saturation clips the brightest elements
    index, reason = code.decode(levels, noise=0.01)
    assert index.tolist() == list(range(len(W)))
    assert set(reason) == {""}


def test_every_single_and_double_misreading_is_rejected():
    code = IdentityCode.for_grid(14, 9)
    W = code.codewords
    n = code.nframes
    cases = [(e, flips) for e in range(len(W))
             for flips in itertools.chain(itertools.combinations(range(n), 1), itertools.combinations(range(n), 2),
                                          itertools.combinations(range(n), 3))]
    bad = np.array([W[e] for e, _ in cases])
    for k, (_, flips) in enumerate(cases):
        bad[k, list(flips)] ^= 1
    index, reason = code.decode(20 + 180 * bad.astype(float))  # each row is read on its own
    wrong = [case for case, i, r in zip(cases, index, reason) if i != -1 or not r]
    assert not wrong, wrong[:5]


def test_a_dropped_repeated_or_inverted_frame_never_mislabels():
    code = IdentityCode.for_grid(14, 9)
    W = code.codewords.astype(float)
    levels = 30 + 150 * W
    n = code.nframes
    for k in range(n):
        cases = {
            "inverted": np.where(np.arange(n) == k, 210 - levels, levels),
            "repeated": levels[:, [j - (j == k) if k else (1 if j == 0 else j) for j in range(n)]],
            "dropped": np.concatenate((np.delete(levels, k, axis=1), np.full((len(W), 1), 30.0)), axis=1),
        }
        for what, lv in cases.items():
            index, reason = code.decode(lv, noise=1.0)
            good = index >= 0
            assert np.all(index[good] == np.flatnonzero(good)), (what, k)
            assert np.all(reason[~good] != ""), (what, k)
            assert (~good).sum() > 0, (what, k)


def test_noise_rejects_rather_than_mislabels():
    code = IdentityCode.for_grid(14, 9)
    W = code.codewords.astype(float)
    rng = np.random.default_rng(3)
    wrong = read = 0
    for _ in range(200):
        levels = 100 + 20 * W + rng.normal(0, 8, W.shape)  # contrast 20, noise 8: many unreadable
        index, reason = code.decode(levels, noise=8 / 3)
        good = index >= 0
        read += good.sum()
        wrong += np.sum(index[good] != np.flatnonzero(good))
        assert np.all(reason[~good] != "")
    assert wrong == 0 and read > 0


def test_no_contrast_is_unreadable():
    code = IdentityCode.for_grid(14, 9)
    index, reason = code.decode(np.full((2, 13), 50.0), noise=1.0)
    assert index.tolist() == [-1, -1]
    assert "no contrast" in reason[0]


def test_pattern_json_lists_the_identity_frames_and_the_code():
    layout = make_layout()
    d = layout.to_dict()
    kinds = [f["kind"] for f in d["frames"]]
    assert kinds == ["rotstar"] * 8 + ["identity"] * 13 + ["checkerboard"]
    assert d["identity"]["frames"] == 13 and len(d["identity"]["codewords"]) == 126
    assert layout_from_dict(d) == layout
    lean = make_layout(identity=False)
    assert "identity" not in lean.to_dict() and layout_from_dict(lean.to_dict()) == lean
    d["identity"]["weight"] = 7
    with pytest.raises(ValueError, match="identity: frames 13, weight 7"):
        layout_from_dict(d)
    d = layout.to_dict()
    d["frames"] = [f for f in d["frames"] if f.get("index") != 4 or f["kind"] != "identity"]
    with pytest.raises(ValueError, match="identity frames with indices"):
        layout_from_dict(d)
    with pytest.raises(ValueError, match="differ"):
        code_from_dict(dict(layout.to_dict()["identity"], codewords=["0"] * 126), 14, 9)


def test_identity_frame_shows_each_elements_bit():
    layout = make_layout(screen=(800, 600), pitch=100, band=24)
    code = layout.identity_code
    c = layout.corner_screen_xy().astype(int)
    for b in range(code.nframes):
        img = render_frame(layout, layout.frames()[layout.nframes + b])
        # the pixel just below-right of every corner is inside its element's square
        assert np.array_equal(img[c[..., 1] + 5, c[..., 0] + 5], code.frame_bits(b).astype(float))
        x0, y0, _, _ = layout.board_extent()
        assert img[y0 + 2, x0 + 2] == 0.0 and img[2, 2] == layout.background

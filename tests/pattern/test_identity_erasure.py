"""One identity frame missing from a recording (its levels NaN): read from the other 12, never mislabelled"""

import numpy as np
import pytest

from rotstar_mrcal.pattern.identity import IdentityCode

CODE = IdentityCode.for_grid(14, 9)


def exposed(words: np.ndarray, rng, noise: float = 0.0) -> np.ndarray:
    """Levels of words (N, n) under every element's own black and contrast, plus Gaussian noise of `noise` times
    the element's contrast"""
    black = rng.uniform(0, 60, (len(words), 1))
    contrast = rng.uniform(60, 200, (len(words), 1))
    return black + contrast * (words + rng.normal(0, noise, words.shape))


def erased(levels: np.ndarray, k) -> np.ndarray:
    out = np.array(levels, float)
    out[np.arange(len(out)), k] = np.nan
    return out


def test_every_word_reads_with_any_one_frame_missing():
    W = CODE.codewords.astype(float)
    levels = exposed(W, np.random.default_rng(3)) ** 1.8  # any display gamma
    for k in range(CODE.nframes):
        index, reason = CODE.decode(erased(levels, k), noise=0.5)
        assert index.tolist() == list(range(len(W))), (k, set(reason))
        assert set(reason) == {""}


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_missing_column_reads_as_the_true_column_under_noise(seed):
    """Per element one random frame erased: the same indices as with it, at a noise every element reads through;
    at a noise that loses elements, a missing frame may lose more but never names a wrong element"""
    rng = np.random.default_rng(seed)
    e = np.repeat(np.arange(CODE.nx * CODE.ny), 8)
    W = CODE.codewords[e].astype(float)
    k = rng.integers(0, CODE.nframes, len(W))
    low = exposed(W, rng, noise=0.05)
    whole, _ = CODE.decode(low, noise=1.0)
    assert np.array_equal(whole, e)
    assert np.array_equal(CODE.decode(erased(low, k), noise=1.0)[0], whole)
    high = exposed(W, rng, noise=0.2)
    index, reason = CODE.decode(erased(high, k), noise=1.0)
    assert 0 < np.sum(index < 0) < len(W)  # the test is at the noise where some elements are lost
    assert np.all((index == e) | (index == -1))
    assert all(r for r, i in zip(reason, index) if i < 0)


def test_one_missing_frame_and_one_misread_bit_never_name_a_wrong_element():
    """Brute force over the code: every word, every missing frame, every one of the 12 others misread (d = 4)"""
    W = CODE.codewords
    n = CODE.nframes
    e, miss, flip = np.meshgrid(np.arange(len(W)), np.arange(n), np.arange(n), indexing="ij")
    e, miss, flip = e[miss != flip], miss[miss != flip], flip[miss != flip]
    words = W[e].astype(float)
    words[np.arange(len(words)), flip] = 1 - words[np.arange(len(words)), flip]
    index, reason = CODE.decode(erased(20 + 180 * words, miss), noise=1.0)
    assert len(index) == len(W) * n * (n - 1)
    assert np.all(index == -1), f"{np.sum(index >= 0)} read, {np.sum((index >= 0) & (index != e))} wrongly"
    assert all(reason)
    # ... and the same words without the misread bit all read, each as itself
    clean, _ = CODE.decode(erased(20 + 180 * W[e].astype(float), miss), noise=1.0)
    assert np.array_equal(clean, e)


def test_two_missing_frames_are_rejected_with_the_count():
    levels = 20 + 180 * CODE.codewords[:5].astype(float)
    levels[:, [2, 9]] = np.nan
    levels[4, 0] = np.nan
    index, reason = CODE.decode(levels, noise=1.0)
    assert index.tolist() == [-1] * 5
    assert reason.tolist() == ["identity unreadable: 2 identity frames missing"] * 4 + [
        "identity unreadable: 3 identity frames missing"]


def test_a_middle_level_that_fits_both_counts_is_rejected():
    """Levels of three kinds with a frame missing: w - 1 bright, one halfway, the rest dark fit w and w - 1 ones"""
    word = CODE.codewords[10].astype(float)
    ones = np.flatnonzero(word)
    levels = 20 + 180 * word
    levels[ones[0]] = 110.0  # halfway: one of w and w - 1 splits must take it as white, the other as black
    zeros = np.flatnonzero(word == 0)
    index, reason = CODE.decode(erased(levels[None], [zeros[0]]), noise=1.0)
    assert index.tolist() == [-1] and "fit 6 and 5 white frames alike" in reason[0]


def test_misordered_names_nothing_when_a_frame_is_missing():
    levels = 20 + 180 * CODE.codewords.astype(float)
    levels[:, [3, 7]] = levels[:, [7, 3]]  # a swap it would name with every frame there
    assert CODE.misordered(levels)[:3] == ("swapped", 3, 7)
    levels[:, 0] = np.nan
    assert CODE.misordered(levels) == ()

"""Identity codes (issue 13, first piece): a misread element is rejected, never mislabelled"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from rotstar_mrcal.pattern.identity import IdentityCode, decide


@pytest.mark.parametrize("nx, ny", [(14, 9), (3, 3), (20, 16), (2, 1)])
def test_every_index_round_trips(nx, ny):
    code = IdentityCode(nx, ny)
    idx = np.arange(nx * ny)
    assert code.decode(code.encode(idx)).tolist() == idx.tolist()


def test_codewords_are_distinct_by_at_least_four_bits():
    code = IdentityCode(14, 9)
    w = code.encode(np.arange(126)).astype(int)
    d = (w[:, None, :] != w[None, :, :]).sum(axis=-1)
    np.fill_diagonal(d, 99)
    assert d.min() >= code.min_distance == 4


@pytest.mark.parametrize("nerr", [1, 2, 3])
def test_every_error_of_up_to_three_bits_is_rejected(nerr):
    """Exhaustive over all 126 codewords and every set of nerr flipped bits"""
    code = IdentityCode(14, 9)
    w = code.encode(np.arange(126))
    flips = list(itertools.combinations(range(code.nbits), nerr))
    bad = np.repeat(w[:, None, :], len(flips), axis=1)
    for f, pos in enumerate(flips):
        bad[:, f, list(pos)] ^= 1
    assert np.all(code.decode(bad) == -1)


def test_words_of_indices_beyond_the_grid_are_rejected():
    """7 data bits hold 0..127; 126 and 127 are not elements of a 14 x 9 grid"""
    big = IdentityCode(16, 8)  # the same 12-bit code, with 128 elements
    small = IdentityCode(14, 9)
    assert big.nbits == small.nbits
    assert small.decode(big.encode(np.array([126, 127]))).tolist() == [-1, -1]
    with pytest.raises(ValueError):
        small.encode(np.array([126]))


def test_unreliable_bits_reject_the_element():
    code = IdentityCode(14, 9)
    w = code.encode(np.array([42, 43]))
    reliable = np.ones_like(w, bool)
    reliable[1, 5] = False
    assert code.decode(w, reliable).tolist() == [42, -1]


def test_decide_from_complementary_frames_under_gain_and_noise():
    """Bits from on/off pairs survive any exposure gain and offset; near-equal pairs are unreliable"""
    code = IdentityCode(14, 9)
    rng = np.random.default_rng(0)
    w = code.encode(np.arange(126)).astype(float)
    gain, offset, noise = rng.uniform(0.2, 3.0, (126, 1)), rng.uniform(0, 50, (126, 1)), 1.0
    on = offset + gain * 100 * w + rng.normal(0, noise, w.shape)
    off = offset + gain * 100 * (1 - w) + rng.normal(0, noise, w.shape)
    bits, ok = decide(on, off, noise)
    assert code.decode(bits, ok).tolist() == list(range(126))
    bits, ok = decide(np.full(w.shape, 50.0), np.full(w.shape, 50.5), noise)  # no contrast: all unreliable
    assert np.all(code.decode(bits, ok) == -1)

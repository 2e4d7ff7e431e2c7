"""Identity codes: each element's grid index written in bits, read back or rejected, never mislabelled

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.pattern.identity import IdentityCode
    >>> code = IdentityCode(nx=14, ny=9)
    >>> code.nbits, code.min_distance            # 7 data bits, 4 Hamming checks, 1 overall parity
    (12, 4)
    >>> bits = code.encode(np.array([0, 5, 125]))  # element index j * nx + i
    >>> bits.shape
    (3, 12)
    >>> code.decode(bits).tolist()
    [0, 5, 125]
    >>> bad = bits.copy(); bad[1, 3] ^= 1; bad[2, [0, 7, 9]] ^= 1   # one and three bits misread
    >>> code.decode(bad).tolist()                # rejected (-1), not corrected, not mislabelled
    [0, -1, -1]

The code is an extended Hamming code over the element index (d = 4): any
one, two or three misread bits give a word that is not a codeword, and the
element is rejected. Nothing is corrected: a calibration loses one element
rather than gaining a wrong label. Words that are codewords of indices
beyond the grid (nx * ny <= index < 2^k) are rejected too.

How a bit is read is the caller's business (issue 13's identity frames: a
frame per bit and its complement, each bit decided by comparing the same
pixels in the two frames, robust to exposure, vignetting and gamma); `decide`
turns such pairs into bits and marks the ones too close to call, which
`decode` then rejects with the element.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np


def _check_bits(k: int) -> int:
    """Hamming check bits r for k data bits: the smallest r with 2^r >= k + r + 1"""
    r = 1
    while 2**r < k + r + 1:
        r += 1
    return r


@dataclasses.dataclass(frozen=True)
class IdentityCode:
    """Extended Hamming code of the indices j * nx + i of an nx x ny grid"""

    nx: int
    ny: int

    @property
    def data_bits(self) -> int:
        return max(1, math.ceil(math.log2(self.nx * self.ny)))

    @property
    def check_bits(self) -> int:
        return _check_bits(self.data_bits)

    @property
    def nbits(self) -> int:
        """Bits per element: data, Hamming checks, one overall parity"""
        return self.data_bits + self.check_bits + 1

    @property
    def min_distance(self) -> int:
        return 4

    def _positions(self) -> tuple[np.ndarray, np.ndarray]:
        """Hamming positions (1-based) of the data bits and of the check bits"""
        n = self.data_bits + self.check_bits
        pos = np.arange(1, n + 1)
        check = (pos & (pos - 1)) == 0  # powers of two
        return pos[~check], pos[check]

    def encode(self, index) -> np.ndarray:
        """(..., nbits) uint8 codewords of element indices (...,); bit order: Hamming positions 1..n, then parity"""
        index = np.asarray(index, np.int64)
        if np.any((index < 0) | (index >= self.nx * self.ny)):
            raise ValueError(f"element index outside 0..{self.nx * self.ny - 1}")
        dpos, cpos = self._positions()
        n = self.data_bits + self.check_bits
        word = np.zeros(index.shape + (n,), np.uint8)
        data = (index[..., None] >> np.arange(self.data_bits)) & 1
        word[..., dpos - 1] = data
        for c in cpos:  # check bit c covers the positions whose binary expansion holds c
            cover = (np.arange(1, n + 1) & c) != 0
            word[..., c - 1] = np.bitwise_xor.reduce(word[..., cover], axis=-1)
        parity = np.bitwise_xor.reduce(word, axis=-1)
        return np.concatenate((word, parity[..., None]), axis=-1)

    def decode(self, bits, reliable=None) -> np.ndarray:
        """(...,) element indices of words (..., nbits), -1 where a word is not a valid codeword

        reliable: optional (..., nbits) bool; a word with an unreliable bit is rejected.
        """
        bits = np.asarray(bits, np.uint8)
        if bits.shape[-1] != self.nbits:
            raise ValueError(f"words of {self.nbits} bits expected, not {bits.shape[-1]}")
        n = self.data_bits + self.check_bits
        pos = np.arange(1, n + 1)
        syndrome = np.bitwise_xor.reduce(np.where(bits[..., :n].astype(bool), pos, 0), axis=-1)
        parity = np.bitwise_xor.reduce(bits, axis=-1)
        dpos, _ = self._positions()
        index = np.sum(bits[..., dpos - 1].astype(np.int64) << np.arange(self.data_bits), axis=-1)
        ok = (syndrome == 0) & (parity == 0) & (index < self.nx * self.ny)
        if reliable is not None:
            ok &= np.all(np.asarray(reliable, bool), axis=-1)
        return np.where(ok, index, -1)


def decide(on: np.ndarray, off: np.ndarray, noise: float, k: float = 4.0) -> tuple[np.ndarray, np.ndarray]:
    """(bits, reliable) from a bit's frame and its complement, measured over the same pixels

        >>> bits, ok = decide(np.array([200., 90., 101.]), np.array([20., 180., 100.]), noise=2.0)
        >>> bits.tolist(), ok.tolist()
        ([1, 0, 1], [True, True, False])

    A bit is 1 where the element is brighter in its frame than in the
    complement; it is reliable when the difference exceeds k times the noise
    of the difference (noise: of one measurement).
    """
    d = np.asarray(on, float) - np.asarray(off, float)
    return (d > 0).astype(np.uint8), np.abs(d) > k * noise * math.sqrt(2)

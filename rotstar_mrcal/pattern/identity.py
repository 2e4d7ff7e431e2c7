"""Identity codes: each element's grid index written in time, read back or rejected, never mislabelled

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.pattern.identity import IdentityCode
    >>> code = IdentityCode.for_grid(nx=14, ny=9)
    >>> code.nframes, code.weight, code.min_distance   # 13 identity frames, 6 of them white per element
    (13, 6, 4)
    >>> words = code.encode(np.array([0, 5, 125]))      # element index j * nx + i
    >>> words.shape, words.sum(axis=1).tolist()
    ((3, 13), [6, 6, 6])
    >>> levels = 20 + 180 * words                       # what the camera sees: any exposure, any gamma
    >>> code.decode(levels, noise=2.0)[0].tolist()
    [0, 5, 125]
    >>> levels[1, np.flatnonzero(words[1])[0]] = 20       # element 5 misread in one frame
    >>> index, reason = code.decode(levels, noise=2.0)
    >>> index.tolist(), reason[1]
    ([0, -1, 125], 'identity unreadable: 5 white frames, the code has 6 (a frame dropped, repeated or misread)')

The code is a constant-weight code (Graham and Sloane's construction): the
words of n bits with exactly w ones whose positions sum to 0 modulo n. Two
such words differ in at least 4 bits (d = 4). 13 frames name the 126
elements of a 14x9 grid; every frame shows about half of the elements white.

Reading needs no threshold and no reference frame: in each element the w
brightest of the n identity frames are the ones. This is a comparison of
the same pixels across frames, so exposure, vignetting, display gamma and
saturation cancel; the element is rejected unless the w-th and (w+1)-th
brightest frames are separated by half the element's own contrast (a frame
dropped, repeated or inverted changes the number of white frames in most
elements, which this rejects) and the word read is one of the codewords
(any one or two bits misread, with the weight kept, give a word outside the
code). Nothing is corrected: a calibration loses an element rather than
gaining a wrong label. When most elements do not read, `misordered` names
the one simple fault that explains it (a frame inverted, two frames swapped)
so that the pose is refused with what was seen.

One identity frame missing from a recording (its levels NaN) is still read:
the other n - 1 frames hold w ones (the missing bit is 0) or w - 1 (it is
1), and the same gap rule picks which (rejected when both or neither
pass). With d = 4 the word so completed plus one misread bit is never a
codeword (tests/pattern/test_identity_erasure.py checks every case), so a missing
frame costs no label safety; two missing frames are not read.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import math

import numpy as np

MIN_GAP_FRACTION = 0.5  # the w-th and (w+1)-th brightest frames must differ by this part of the contrast
MIN_CONTRAST_NOISE = 6.0  # ... and the contrast must exceed this many times the noise of an element's mean
MISORDER_READ = 0.8  # a frame inverted or two swapped are named when undoing it reads this part of the elements


@functools.lru_cache(maxsize=32)
def _codewords(n: int, w: int) -> np.ndarray:
    """All weight-w words of n bits whose one-positions sum to 0 mod n, in lexicographic order of positions"""
    words = [c for c in itertools.combinations(range(n), w) if sum(c) % n == 0]
    out = np.zeros((len(words), n), np.uint8)
    for r, c in enumerate(words):
        out[r, list(c)] = 1
    return out


@functools.lru_cache(maxsize=32)
def _spread(n: int, w: int, count: int) -> np.ndarray:
    all_words = _codewords(n, w)
    return all_words[np.round(np.linspace(0, len(all_words) - 1, count)).astype(int)]


def _split(s: np.ndarray, k: int, m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(hi, lo, gap) of descending levels s[:, :m] read as k ones and m - k zeros: the medians and the gap between"""
    return np.median(s[:, :k], axis=1), np.median(s[:, k:m], axis=1), s[:, k - 1] - s[:, k]


def code_size(n: int, w: int) -> int:
    """Number of codewords of length n and weight w (without building them for large n)"""
    return len(_codewords(n, w)) if n <= 20 else math.comb(n, w) // n


@dataclasses.dataclass(frozen=True)
class IdentityCode:
    """A constant-weight code of the element indices j * nx + i of an nx x ny grid"""

    nx: int
    ny: int
    nframes: int
    weight: int

    @classmethod
    def for_grid(cls, nx: int, ny: int) -> "IdentityCode":
        """The shortest code (fewest frames) with a word for every element"""
        need = nx * ny
        for n in range(4, 21):
            for w in (n // 2, (n + 1) // 2):
                if code_size(n, w) >= need:
                    return cls(nx, ny, n, w)
        raise ValueError(f"a {nx}x{ny} grid needs more than 20 identity frames")

    @property
    def min_distance(self) -> int:
        return 4

    @property
    def codewords(self) -> np.ndarray:
        """(nx * ny, nframes) uint8: row e is the word of element e = j * nx + i

        The elements take words evenly spread over the code's list (not its
        first ones), so that every frame shows about half of them white.
        """
        return _spread(self.nframes, self.weight, self.nx * self.ny)

    def encode(self, index) -> np.ndarray:
        """(..., nframes) uint8 codewords of element indices (...,)"""
        index = np.asarray(index, np.int64)
        if np.any((index < 0) | (index >= self.nx * self.ny)):
            raise ValueError(f"element index outside 0..{self.nx * self.ny - 1}")
        return self.codewords[index]

    def frame_bits(self, frame: int) -> np.ndarray:
        """(ny, nx) uint8: which elements are white in identity frame `frame`"""
        return self.codewords[:, frame].reshape(self.ny, self.nx)

    def _table(self) -> dict:
        return {w.tobytes(): e for e, w in enumerate(self.codewords)}

    def decode(self, levels, noise: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """(index (...,), reason (...,)): the element indices read from levels (..., nframes), -1 and why where not

        levels: each element's mean intensity in each identity frame, in any
        units, NaN in the column of an identity frame that was not recorded;
        noise: the standard deviation of one such mean (0: not checked).
        One missing frame per element is read from the other 12 (the module
        doc); two or more are not.

        >>> code = IdentityCode.for_grid(nx=14, ny=9)
        >>> levels = 20 + 180 * code.encode([3, 77]).astype(float)
        >>> levels[:, 6] = np.nan                              # identity_06.png not recorded
        >>> code.decode(levels, noise=2.0)[0].tolist()
        [3, 77]
        >>> levels[1, 2] = np.nan
        >>> code.decode(levels, noise=2.0)[1].tolist()
        ['', 'identity unreadable: 2 identity frames missing']
        """
        v = np.asarray(levels, float)
        if v.shape[-1] != self.nframes:
            raise ValueError(f"levels of {self.nframes} identity frames expected, not {v.shape[-1]}")
        shape = v.shape[:-1]
        v = v.reshape(-1, self.nframes)
        missing = np.isnan(v).sum(axis=1)
        index = np.full(len(v), -1, np.int64)
        reason = np.full(len(v), "", dtype=object)
        whole, one = missing == 0, missing == 1
        index[whole], reason[whole] = self._decode_whole(v[whole], noise)
        index[one], reason[one] = self._decode_erased(v[one], noise)
        many = missing >= 2
        reason[many] = [f"identity unreadable: {m} identity frames missing" for m in missing[many]]
        return index.reshape(shape), reason.reshape(shape)

    def _decode_whole(self, v: np.ndarray, noise: float) -> tuple[np.ndarray, np.ndarray]:
        """decode of (N, nframes) levels, every frame recorded: the w brightest are the ones"""
        w = self.weight
        s = -np.sort(-v, axis=1)  # descending
        hi, lo, gap = _split(s, w, self.nframes)
        contrast = hi - lo
        bits = (v >= s[:, w - 1 : w]).astype(np.uint8)
        index = self._lookup(bits)
        reason = np.full(len(v), "", dtype=object)
        white = np.sum(v - lo[:, None] > 0.5 * contrast[:, None], axis=1)
        readable = gap >= MIN_GAP_FRACTION * contrast
        reason[index < 0] = "identity not a codeword (misread bits)"
        bad_count = ~readable
        reason[bad_count] = [f"identity unreadable: {n} white frames, the code has {w} "
                             "(a frame dropped, repeated or misread)" for n in white[bad_count]]
        return self._dim(index, reason, contrast, noise)

    def _decode_erased(self, v: np.ndarray, noise: float) -> tuple[np.ndarray, np.ndarray]:
        """decode of (N, nframes) levels with one NaN per row: the erased bit from the other frames' count

        The n - 1 known levels hold w ones (the erased bit is 0) or w - 1 (it
        is 1): the split whose gap passes MIN_GAP_FRACTION of its contrast
        names it, unless both pass (read as neither).
        """
        n, w = self.nframes, self.weight
        s = -np.sort(-v, axis=1)  # descending, the NaN last
        splits = [_split(s, k, n - 1) for k in (w, w - 1)]
        passes = [gap >= MIN_GAP_FRACTION * (hi - lo) for hi, lo, gap in splits]
        one = passes[1] & ~passes[0]  # the w - 1 split alone passes: the erased bit is 1
        hi, lo, gap = (np.where(one, b, a) for a, b in zip(*splits))
        contrast = hi - lo
        k = np.where(one, w - 1, w)
        erased = np.isnan(v)
        with np.errstate(invalid="ignore"):
            bits = (v >= s[np.arange(len(v)), k - 1][:, None]).astype(np.uint8)
            white = np.sum(v - lo[:, None] > 0.5 * contrast[:, None], axis=1)
        bits[erased] = one
        index = self._lookup(bits)
        reason = np.full(len(v), "", dtype=object)
        reason[index < 0] = "identity not a codeword (misread bits)"
        both = passes[0] & passes[1]
        reason[both] = (f"identity unreadable: the {n - 1} frames read fit {w} and {w - 1} white frames alike "
                        "(one identity frame missing)")
        neither = ~passes[0] & ~passes[1]
        reason[neither] = [f"identity unreadable: {c} white frames of the {n - 1} read (one missing), the code has "
                           f"{w} (a frame dropped, repeated or misread)" for c in white[neither]]
        return self._dim(index, reason, contrast, noise)

    def _lookup(self, bits: np.ndarray) -> np.ndarray:
        table = self._table()
        return np.array([table.get(b.tobytes(), -1) for b in bits], np.int64)

    @staticmethod
    def _dim(index, reason, contrast, noise) -> tuple[np.ndarray, np.ndarray]:
        """(index, reason) with the elements whose contrast does not beat the noise rejected, and -1 where rejected"""
        dim = ~(contrast > max(MIN_CONTRAST_NOISE * noise, 0.0)) | ~np.isfinite(contrast)
        reason[dim] = "identity unreadable: no contrast between the identity frames"
        index[reason != ""] = -1
        return index, reason

    def misordered(self, levels, noise: float = 0.0) -> tuple:
        """() or what happened to the identity frames, when one simple fault explains why most codes do not read

        ('inverted', k, read, fixed, n): frame k's white and black exchanged;
        ('swapped', a, b, read, fixed, n): frames a and b in each other's place
        (on disk or in pattern.json); read: the elements of n (those with
        contrast) whose codes read as recorded, fixed: with the fault undone.
        Either fault leaves most elements unreadable and none misread (an
        inverted frame changes every word's weight; a swap changes two bits of
        the words that differ there, and d = 4). Named only when undoing it
        reads at least MISORDER_READ of the elements and most of those the
        levels as recorded did not: what the detector saw, not a guess.

        >>> code = IdentityCode.for_grid(nx=14, ny=9)
        >>> levels = 20 + 180 * code.codewords.astype(float)
        >>> code.misordered(levels)
        ()
        >>> code.misordered(levels[:, [0, 1, 2, 7, 4, 5, 6, 3, 8, 9, 10, 11, 12]])[:3]
        ('swapped', 3, 7)
        >>> inv = levels.copy(); inv[:, 5] = 220 - inv[:, 5]
        >>> code.misordered(inv)
        ('inverted', 5, 0, 126, 126)
        >>> levels[:, 4] = np.nan; code.misordered(levels)     # a frame not recorded: no fault named
        ()
        """
        v = np.asarray(levels, float).reshape(-1, self.nframes)
        if np.isnan(v).any():  # a frame missing: undoing a fault would need its level
            return ()
        index, reason = self.decode(v, noise)
        n = int(np.sum(reason != "identity unreadable: no contrast between the identity frames"))
        read = int(np.sum(index >= 0))
        if n < 4 or read >= MISORDER_READ * n:
            return ()
        hi, lo = v.max(axis=1, keepdims=True), v.min(axis=1, keepdims=True)
        faults = [(("inverted", k), np.where(np.arange(self.nframes) == k, hi + lo - v, v))
                  for k in range(self.nframes)]
        for a, b in itertools.combinations(range(self.nframes), 2):
            order = np.arange(self.nframes)
            order[[a, b]] = b, a
            faults.append((("swapped", a, b), v[:, order]))
        best = max(((name, int(np.sum(self.decode(u, noise)[0] >= 0))) for name, u in faults), key=lambda f: f[1])
        name, fixed = best
        if fixed < MISORDER_READ * n or fixed - read < 0.5 * (n - read):
            return ()
        return (*name, read, fixed, n)

    def describe(self) -> dict:
        """pattern.json's "identity" section: the code and every element's word"""
        return {
            "code": "constant weight: the words of n bits with w ones whose positions (0-based) sum to 0 mod n, "
                    "in lexicographic order of those positions; element e = j*nx+i takes word round(e * (M - 1) / (nx*ny - 1)) "
                    "of the M words (listed in codewords)",
            "frames": self.nframes,
            "weight": self.weight,
            "min_distance": self.min_distance,
            "reading": "in each element, the w brightest identity frames are the ones",
            "codewords": ["".join(map(str, w)) for w in self.codewords],
        }


def code_from_dict(d: dict, nx: int, ny: int) -> IdentityCode:
    """The code of pattern.json's "identity" section; ValueError when it is not ours"""
    code = IdentityCode.for_grid(nx, ny)
    if not isinstance(d, dict):
        raise ValueError("identity is not an object")
    if d.get("frames") != code.nframes or d.get("weight") != code.weight:
        raise ValueError(f"identity: frames {d.get('frames')}, weight {d.get('weight')}; a {nx}x{ny} grid's "
                         f"code has {code.nframes} frames of weight {code.weight}")
    words = d.get("codewords")
    if words is not None and words != code.describe()["codewords"]:
        raise ValueError("identity.codewords differ from the code this version writes")
    return code

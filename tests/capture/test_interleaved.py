"""Y12I / Y8I unpacking, byte for byte against packings of known values"""

from __future__ import annotations

import numpy as np
import pytest

from rotstar_mrcal.capture import interleaved as il


def test_y12i_bytes_of_known_values():
    """librealsense's y12i_pixel {rl:8, rh:4, ll:4, lh:8}: byte 0 = right[7:0], byte 1 = left[3:0] << 4 | right[11:8],
    byte 2 = left[11:4]; written out by hand, not by our packer"""
    assert il.Y12I_LEFT == "high"
    left = np.array([[0xABC, 0x000, 0xFFF, 0x801]], np.uint16)
    right = np.array([[0x123, 0xFFF, 0x000, 0x010]], np.uint16)
    by_hand = bytes([0x23, 0xC1, 0xAB,  # L abc, R 123
                     0xFF, 0x0F, 0x00,  # L 000, R fff
                     0x00, 0xF0, 0xFF,  # L fff, R 000
                     0x10, 0x10, 0x80])  # L 801, R 010
    assert il.pack_y12i(left, right).tobytes() == by_hand
    l, r = il.unpack_y12i(by_hand, 4, 1)
    assert l.dtype == np.uint16 and r.dtype == np.uint16 and l.shape == (1, 4)
    np.testing.assert_array_equal(l, left)
    np.testing.assert_array_equal(r, right)
    # every bit of each value lands where it belongs: one bit at a time
    for bit in range(12):
        l, r = il.unpack_y12i(il.pack_y12i(np.uint16([[1 << bit]]), np.uint16([[0]])), 1, 1)
        assert (int(l[0, 0]), int(r[0, 0])) == (1 << bit, 0)
        word = int.from_bytes(il.pack_y12i(np.uint16([[0]]), np.uint16([[1 << bit]])).tobytes(), "little")
        assert word == 1 << bit  # the right imager in the low 12 bits of the 24-bit word


def test_y12i_layout_is_one_switch(monkeypatch):
    """The kernel's reading (left in the low 12 bits) is the same code with Y12I_LEFT = 'low'"""
    buf = bytes([0x23, 0xC1, 0xAB])
    monkeypatch.setattr(il, "Y12I_LEFT", "low")
    l, r = il.unpack_y12i(buf, 1, 1)
    assert (int(l[0, 0]), int(r[0, 0])) == (0x123, 0xABC)
    # the kernel's own formula: left0 = 0xfff & *(u16 *)buf; right0 = *(u16 *)(buf + 1) >> 4
    assert int.from_bytes(buf[0:2], "little") & 0xFFF == 0x123 and int.from_bytes(buf[1:3], "little") >> 4 == 0xABC


def test_y12i_round_trip_with_line_padding():
    rng = np.random.default_rng(1)
    h, w, pad = 5, 7, 11
    left, right = rng.integers(0, 4096, (2, h, w)).astype(np.uint16)
    rows = np.zeros((h, w * 3 + pad), np.uint8)
    rows[:, : w * 3] = il.pack_y12i(left, right)
    rows[:, w * 3:] = 0xEE  # padding must not leak into the image
    l, r = il.unpack_y12i(rows.tobytes(), w, h, bytesperline=w * 3 + pad)
    np.testing.assert_array_equal(l, left)
    np.testing.assert_array_equal(r, right)
    # the last line without its padding, as some drivers report bytesused
    l2, _ = il.unpack_y12i(rows.tobytes()[:-pad], w, h, bytesperline=w * 3 + pad)
    np.testing.assert_array_equal(l2, left)


def test_y8i_bytes_of_known_values():
    """Kernel pixfmt-y8i and librealsense y8i_pixel {l, r}: byte 0 left, byte 1 right"""
    by_hand = bytes([0x01, 0xF0, 0x02, 0xE0, 0x03, 0xD0, 0x04, 0xC0])
    l, r = il.unpack_y8i(by_hand, 2, 2)
    assert l.tolist() == [[1, 2], [3, 4]] and r.tolist() == [[0xF0, 0xE0], [0xD0, 0xC0]]
    assert il.pack_y8i(l, r).tobytes() == by_hand
    # as a little-endian 16-bit word: left in the low byte
    assert np.frombuffer(by_hand, "<u2")[0] == 0xF001


@pytest.mark.parametrize("code,size,msg", [
    ("Y12I", 3 * 1280 * 800 - 1, r"Y12I 1280x800: the buffer holds 3071999 bytes, a frame needs 3072000 \(3 bytes a pixel\)"),
    ("Y12I", 2 * 1280 * 800, r"Y12I 1280x800: the buffer holds 2048000 bytes, a frame needs 3072000"),
    ("Y8I", 2 * 1280 * 800 + 2, r"Y8I 1280x800: the buffer holds 2048002 bytes, a frame needs 2048000"),
])
def test_a_wrong_length_says_size_and_format(code, size, msg):
    with pytest.raises(il.InterleavedError, match=msg):
        il.unpack(code, bytes(size), 1280, 800)


def test_bad_packer_input():
    with pytest.raises(il.InterleavedError, match="12-bit"):
        il.pack_y12i(np.uint16([[4096]]), np.uint16([[0]]))
    with pytest.raises(il.InterleavedError, match="one size"):
        il.pack_y8i(np.zeros((2, 2)), np.zeros((2, 3)))
    with pytest.raises(il.InterleavedError, match="not an interleaved"):
        il.unpack("Y16", bytes(8), 2, 2)

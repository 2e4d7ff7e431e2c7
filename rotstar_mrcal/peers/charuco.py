"""A ChArUco board on the rotating-star screen: OpenCV's board, its exact rendering, its corner labels

SYNOPSIS

    >>> from rotstar_mrcal.pattern.layout import make_layout
    >>> from rotstar_mrcal.peers.charuco import charuco_board, corner_labels, marker_side, render_charuco
    >>> layout = make_layout()                                   # 14 x 9 corners, pitch 150
    >>> board = charuco_board(layout)
    >>> board.getChessboardSize(), marker_side(layout)           # 15 x 10 squares, markers 6 x 20 px
    ((15, 10), 120)
    >>> img = render_charuco(layout)
    >>> img.shape, float(img[layout.origin[1] - 75, layout.origin[0] - 75])   # square (0, 0): black
    ((1640, 2360), 0.0)
    >>> corner_labels([0, 1, 14, 125], layout.nx)                # ChArUco id -> (i, j)
    array([[ 0,  0],
           [ 1,  0],
           [ 0,  1],
           [13,  8]])

    corners = detect_charuco(image, layout, full_scale=65535.0)   # (ny, nx, 2), NaN = not reported

The partial-view benchmark's anchor (issue 13): cv2.aruco.CharucoDetector on
a ChArUco board shown on the same screen at the same poses. Its chessboard
is the layout's checkerboard (render.render_checkerboard): (nx+1) x (ny+1)
squares of side pitch from origin - pitch, so its inner corners are the
rotating-star grid corners, on the same screen pixels; the top-left square
is black, as in OpenCV's board. Every white square holds a marker of
DICTIONARY (ids 0, 1, ... row by row, as cv2.aruco.CharucoBoard places them),
centred, of 6 x 6 cells (4 x 4 bits and a black border of one cell), each
cell an even number of display pixels, the largest with the marker at most
MARKER_FRACTION of the square: every edge on a pixel boundary, the render
exact (tests/lab/test_partial_bench.py compares it with OpenCV's generateImage).
OpenCV's chessboard corner id k is corner (i, j) = (k mod nx, k div nx): the
same numbering as mrcal's records (checked on whole boards by the tests).

The board's design gives the detector its best chance on our views: on 12
hanging views per lens and 8 whole boards at 30-65 degrees on the wide
lens, the in-view corners it reported were 63 % / 62 % / 16 % with 4 x 4-bit
markers of 0.8 x the square, against 52 % / 51 % / 7 % with 5 x 5 bits and
46 % / 48 % / 4 % with 6 x 6 (the cells are larger); larger markers leave
less white around them than OpenCV asks for (70 % of a cell, which it warns
about).
"""

from __future__ import annotations

import cv2
import numpy as np

from rotstar_mrcal.pattern.layout import Layout

DICTIONARY = cv2.aruco.DICT_4X4_100  # 100 markers: enough for (15 x 10) / 2 = 75 white squares
MARKER_CELLS = 6  # 4 x 4 bits and a one-cell border
MARKER_FRACTION = 0.8  # marker side at most this part of the square's


def dictionary() -> cv2.aruco.Dictionary:
    return cv2.aruco.getPredefinedDictionary(DICTIONARY)


def marker_side(layout: Layout) -> int:
    """Marker side, display pixels: MARKER_CELLS cells of an even number of pixels, at most MARKER_FRACTION x pitch"""
    cell = int(MARKER_FRACTION * layout.pitch / MARKER_CELLS) // 2 * 2
    if cell < 2:
        raise ValueError(f"pitch {layout.pitch}: too small for {MARKER_CELLS} x {MARKER_CELLS}-cell markers")
    return MARKER_CELLS * cell


def charuco_board(layout: Layout) -> cv2.aruco.CharucoBoard:
    """OpenCV's board: (nx+1) x (ny+1) squares, lengths in display pixels"""
    n = (layout.nx + 1) * (layout.ny + 1) // 2
    if n > 100:
        raise ValueError(f"a {layout.nx}x{layout.ny} grid needs {n} markers; the dictionary has 100")
    return cv2.aruco.CharucoBoard((layout.nx + 1, layout.ny + 1), float(layout.pitch), float(marker_side(layout)),
                                  dictionary())


def marker_bits(marker_id: int) -> np.ndarray:
    """(MARKER_CELLS, MARKER_CELLS) 0/1 cells of one marker, its black border included"""
    return (cv2.aruco.generateImageMarker(dictionary(), int(marker_id), MARKER_CELLS, borderBits=1) > 127
            ).astype(np.uint8)


def render_charuco(layout: Layout) -> np.ndarray:
    """The ChArUco board on the layout's screen, (height, width) float in {0, 1}, white around it

    The squares are render_checkerboard's; each marker is drawn where
    charuco_board puts it (its object points, display pixels from the
    checkerboard's top-left corner).
    """
    from rotstar_mrcal.pattern.render import render_checkerboard

    img = render_checkerboard(layout)
    board = charuco_board(layout)
    x0, y0, _, _ = layout.checkerboard_extent()
    side = marker_side(layout)
    cell = side // MARKER_CELLS
    for mid, obj in zip(board.getIds().ravel(), board.getObjPoints()):
        u, v = np.round(obj[0, :2]).astype(int) + (x0, y0)  # the marker's top-left corner
        img[v:v + side, u:u + side] = np.kron(marker_bits(mid), np.ones((cell, cell)))
    return img


def detect_charuco(image, layout: Layout, full_scale: float = 255.0, detector=None) -> np.ndarray:
    """(ny, nx, 2) the corners cv2.aruco.CharucoDetector (its defaults) reports, by grid label; NaN = not reported

    image: the ChArUco frame, values 0..full_scale, given to OpenCV as 8 bits
    (detect.baselines.to_uint8, as for OpenCV's chessboard finders; its ArUco
    detector takes 8-bit images only). detector: a
    CharucoDetector of charuco_board(layout) to reuse.
    """
    from rotstar_mrcal.peers.checkerboard import to_uint8

    det = cv2.aruco.CharucoDetector(charuco_board(layout)) if detector is None else detector
    corners, ids, _, _ = det.detectBoard(to_uint8(image, full_scale))
    out = np.full((layout.ny, layout.nx, 2), np.nan)
    if ids is not None and len(ids):
        ij = corner_labels(ids, layout.nx)
        out[ij[:, 1], ij[:, 0]] = np.asarray(corners, float).reshape(-1, 2)
    return out


def corner_labels(ids, nx: int) -> np.ndarray:
    """(N, 2) grid labels (i, j) of OpenCV's chessboard corner ids (N,) on the board of an nx-column grid"""
    ids = np.asarray(ids, int).reshape(-1)
    return np.stack((ids % nx, ids // nx), axis=-1)

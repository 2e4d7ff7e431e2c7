"""Baseline (peer) corner detectors that the rotating-star detector is compared against

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.peers.checkerboard import (
    ...     opencv_subpix, saddle_refine, match_to_reference)
    >>> y, x = np.mgrid[0:40, 0:40].astype(float)
    >>> u, v = x - 20.3, y - 19.6             # one X corner at (20.3, 19.6)
    >>> image = (127.5 + 100 * np.tanh(u) * np.tanh(v)).astype(np.float32)
    >>> p0 = np.array((21., 19.))
    >>> np.round(opencv_subpix(image, p0), 1)
    array([20.3, 19.6])
    >>> np.round(saddle_refine(image, p0, win=3), 2)
    array([20.3, 19.6])
    >>> grid = np.stack(np.meshgrid(np.arange(4.), np.arange(3.)), axis=-1) * 10
    >>> bool(np.all(match_to_reference(grid[::-1, ::-1], grid, 1.) == grid))
    True

Every function here is pure: images in, corners out, in mrcal's pixel
convention (the centre of the top-left pixel is (0, 0); integer coordinates
are pixel centres). OpenCV (cornerSubPix, findChessboardCorners[SB]) and
mrgingham use the same convention; this is checked by tests/peers/test_checkerboard.py
on synthetic images whose true corners are known, and no offset is applied.

Images are 2-D float arrays in recorded units (0..255 or 0..65535);
`full_scale` is the white level, used only where OpenCV needs 8 bits (the
chessboard finders). Corner grids are (ny, nx, 2) arrays in mrcal order (row
j outer, column i inner) with NaN for a corner that was not found.

- average_frames:          the paper's fairness rule for the checkerboard
- opencv_subpix:           cv2.cornerSubPix (Forstner) from initial corners
- opencv_find_chessboard:  cv2.findChessboardCornersSB or findChessboardCorners
- match_to_reference:      relabel a detected grid by the grid symmetries
- saddle_refine:           Lucchese-Mitra quadratic saddle fit (with cone filter)
- mrgingham_detect:        the mrgingham CLI, parsed
"""

from __future__ import annotations

import functools
import glob
import os
import shutil

import cv2
import numpy as np

from rotstar_mrcal.programs import run_tool

__all__ = [
    "average_frames",
    "opencv_subpix",
    "opencv_find_chessboard",
    "match_to_reference",
    "relabelled_boards",
    "saddle_refine",
    "cone_kernel",
    "mrgingham_detect",
    "MrginghamNotInstalled",
    "to_uint8",
]


# ---------------------------------------------------------------------------
# averaging
# ---------------------------------------------------------------------------
def average_frames(frames) -> np.ndarray:
    """Mean of N captures of the same static frame, the paper's fairness rule

    SYNOPSIS

        >>> import numpy as np
        >>> frames = np.stack([np.full((2, 3), 10.), np.full((2, 3), 14.)])
        >>> average_frames(frames)
        array([[12., 12., 12.],
               [12., 12., 12.]], dtype=float32)

    The rotating-star detector sees N frames per pose; for a fair comparison
    the checkerboard baseline gets the same photon budget: N independently
    noisy captures of the checkerboard frame, averaged, which divides the
    noise standard deviation by sqrt(N). `frames` is a sequence of equally
    shaped 2-D images or an (N, H, W) array; the mean is accumulated in
    float64 and returned as float32 in the same units.
    """
    stack = np.asarray(frames if isinstance(frames, np.ndarray) else list(frames))
    if stack.ndim != 3 or stack.shape[0] == 0:
        raise ValueError(f"average_frames needs N >= 1 images of the same 2-D shape; got shape {stack.shape}")
    return np.mean(stack, axis=0, dtype=np.float64).astype(np.float32)


# ---------------------------------------------------------------------------
# OpenCV
# ---------------------------------------------------------------------------
def to_uint8(image: np.ndarray, full_scale: float) -> np.ndarray:
    """Recorded units -> 8 bits, 0..full_scale mapped to 0..255"""
    img = np.asarray(image, np.float64) * (255.0 / float(full_scale))
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def _inside(p: np.ndarray, shape: tuple[int, int], margin: float) -> np.ndarray:
    """Finite points whose distance to every image edge is at least margin"""
    H, W = shape
    with np.errstate(invalid="ignore"):
        return (
            np.all(np.isfinite(p), axis=-1)
            & (p[..., 0] >= margin)
            & (p[..., 0] <= W - 1 - margin)
            & (p[..., 1] >= margin)
            & (p[..., 1] <= H - 1 - margin)
        )


def opencv_subpix(image, corners0, win: int = 5, full_scale: float = 255.0,
                  eps: float = 1e-3, max_iter: int = 100) -> np.ndarray:
    """cv2.cornerSubPix (Forstner) from initial corners, mrcal convention

    SYNOPSIS

        >>> import numpy as np
        >>> y, x = np.mgrid[0:30, 0:30].astype(float)
        >>> image = 128 + 100 * np.tanh(x - 14.25) * np.tanh(y - 15.5)
        >>> np.round(opencv_subpix(image, [[15., 15.], [1., 1.]]), 1)
        array([[14.3, 15.5],
               [ nan,  nan]])

    corners0 has any shape (..., 2); the result has the same shape. The
    (2 win + 1)^2 window is refined until a step is shorter than eps pixels
    or after max_iter iterations (OpenCV caps it at 100). OpenCV asserts on
    corners outside the image and resamples a (2 win + 3)^2 patch around the
    current estimate, so corners that start closer than win + 1 to the border
    (and NaN starts) are returned as NaN. OpenCV returns the start when the
    solution leaves the window. The refinement runs on the float32 image
    (the solution does not depend on the intensity scale, so full_scale is
    unused; it is accepted for a uniform signature).
    """
    del full_scale
    img = np.ascontiguousarray(image, dtype=np.float32)
    if img.ndim != 2:
        raise ValueError(f"opencv_subpix needs a 2-D image; got shape {img.shape}")
    p0 = np.asarray(corners0, np.float64)
    flat = p0.reshape(-1, 2)
    out = np.full(flat.shape, np.nan)
    ok = _inside(flat, img.shape, win + 1)
    if np.any(ok):
        criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_MAX_ITER, int(max_iter), float(eps))
        pts = np.ascontiguousarray(flat[ok], np.float32).reshape(-1, 1, 2)
        pts = cv2.cornerSubPix(img, pts, (int(win), int(win)), (-1, -1), criteria)
        out[ok] = pts.reshape(-1, 2)
    return out.reshape(p0.shape)


# CALIB_CB_NORMALIZE_IMAGE (histogram equalisation) is left out: on a two-level
# board it stretches the noise about each level ~10x and made SB ~10x less
# accurate on our test images (0.04 px -> 0.2-0.6 px RMS).
CHESSBOARD_SB_FLAGS = cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
CHESSBOARD_CLASSIC_FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE


def opencv_find_chessboard(image, nx: int, ny: int, full_scale: float = 255.0,
                           method: str = "sb", subpix_win: int = 5, flags: int | None = None):
    """OpenCV's chessboard finders; (ny, nx, 2) in OpenCV's order, or None

    SYNOPSIS

        >>> import numpy as np
        >>> y, x = np.mgrid[0:120, 0:160] + 0.5
        >>> sq = ((x - 20) // 20 + (y - 20) // 20) % 2
        >>> inside = (x > 20) & (x < 140) & (y > 20) & (y < 100)
        >>> image = np.where(inside, 255 * sq, 255.).astype(np.float32)
        >>> c = opencv_find_chessboard(image, 5, 3, 255.)
        >>> c.shape
        (3, 5, 2)
        >>> bool(np.all(np.abs(np.sort(c[..., 0].ravel()) - np.repeat(np.arange(39.5, 120, 20), 3)) < 0.3))
        True

    The image (recorded units, white = full_scale) is converted to 8 bits.
    method "sb": cv2.findChessboardCornersSB with CALIB_CB_EXHAUSTIVE |
    CALIB_CB_ACCURACY (CHESSBOARD_SB_FLAGS), whose sub-pixel positions are
    returned as they are. method "classic": cv2.findChessboardCorners with
    CALIB_CB_ADAPTIVE_THRESH | CALIB_CB_NORMALIZE_IMAGE
    (CHESSBOARD_CLASSIC_FLAGS) followed by opencv_subpix on the
    full-precision image with window subpix_win; a corner too close to the
    border for cornerSubPix keeps the finder's position. `flags` overrides
    the finder's flags (CHESSBOARD_SB_FLAGS or CHESSBOARD_CLASSIC_FLAGS).

    Measured on the synthetic boards of tests/peers/test_checkerboard.py (squares of
    ~28 px, Gaussian blur sigma 1 px, levels 20 and 230): "sb" with the
    flags above has 0.06-0.1 px RMS without noise and sometimes one corner
    3-5 px off, and 0.23 px RMS with noise sigma 2: histogram equalisation
    of a two-level image stretches the noise about each level ~10x. Without
    CALIB_CB_NORMALIZE_IMAGE it has 0.02-0.045 px with or without that
    noise. "classic" has cornerSubPix's accuracy (0.016 px, 0.026 noisy).

    nx, ny are the inner corners across and down (OpenCV's patternSize). The
    board's labelling is OpenCV's: it may start at any of the four corners
    (and run down first for a square board), so relabel with
    match_to_reference before comparing with anything.
    """
    img8 = to_uint8(image, full_scale)
    if img8.ndim != 2:
        raise ValueError(f"opencv_find_chessboard needs a 2-D image; got shape {img8.shape}")
    if method == "sb":
        f = CHESSBOARD_SB_FLAGS if flags is None else int(flags)
        found, corners = cv2.findChessboardCornersSB(img8, (int(nx), int(ny)), flags=f)
    elif method == "classic":
        f = CHESSBOARD_CLASSIC_FLAGS if flags is None else int(flags)
        found, corners = cv2.findChessboardCorners(img8, (int(nx), int(ny)), flags=f)
    else:
        raise ValueError(f"method must be 'sb' or 'classic'; got {method!r}")
    if not found or corners is None or corners.size != 2 * nx * ny:
        return None
    corners = corners.reshape(ny, nx, 2).astype(np.float64)
    if method == "classic":
        refined = opencv_subpix(image, corners, win=subpix_win)
        corners = np.where(np.isfinite(refined), refined, corners)
    return corners


# ---------------------------------------------------------------------------
# relabelling
# ---------------------------------------------------------------------------
def relabelled_boards(corners: np.ndarray):
    """The 8 relabellings of a (rows, cols, ...) grid by the dihedral group

    SYNOPSIS

        >>> import numpy as np
        >>> names = [name for name, g in relabelled_boards(np.zeros((3, 4, 2)))]
        >>> names[:4]
        ['identity', 'flip_x', 'flip_y', 'rot180']
        >>> [g.shape for name, g in relabelled_boards(np.zeros((3, 4, 2)))][4]
        (4, 3, 2)

    Yields (name, view): the four flips of the array, then the same applied
    to its transpose (rows <-> columns); views, not copies.
    """
    t = np.swapaxes(corners, 0, 1)
    yield "identity", corners
    yield "flip_x", corners[:, ::-1]
    yield "flip_y", corners[::-1, :]
    yield "rot180", corners[::-1, ::-1]
    yield "transpose", t
    yield "transpose+flip_x", t[:, ::-1]
    yield "transpose+flip_y", t[::-1, :]
    yield "transpose+rot180", t[::-1, ::-1]


def match_to_reference(corners, reference, max_dist: float, return_name: bool = False):
    """Relabel a detected grid to a reference grid's labelling, or None

    SYNOPSIS

        >>> import numpy as np
        >>> ref = np.stack(np.meshgrid(np.arange(5.), np.arange(3.)), axis=-1) * 20
        >>> detected = ref[::-1, :] + 0.1          # found bottom row first
        >>> m, name = match_to_reference(detected, ref, 2., return_name=True)
        >>> name, float(np.abs(m - ref).max().round(6))
        ('flip_y', 0.1)
        >>> print(match_to_reference(detected + 5, ref, 2.))
        None

    corners (rows, cols, 2) and reference (ny, nx, 2), NaN allowed in both.
    Of the grid symmetries (flips, the 180-degree turn and, when the shape
    calls for it, the transposes) whose shape matches the reference, those
    that bring every corner present in both within max_dist of its reference
    are kept, and the one with the smallest RMS distance wins. Returns the
    relabelled copy (ny, nx, 2), or None if no symmetry qualifies (wrong
    grid, wrong size, nothing in common, or corners None, as a finder
    returns when it found nothing). With max_dist below half the
    corner spacing at most one symmetry can qualify.
    """
    if corners is None:  # passed straight from a finder that found nothing
        return (None, None) if return_name else None
    corners = np.asarray(corners, np.float64)
    reference = np.asarray(reference, np.float64)
    best = None
    for name, g in relabelled_boards(corners):
        if g.shape != reference.shape:
            continue
        d = np.linalg.norm(g - reference, axis=-1)
        both = np.isfinite(d)
        if not np.any(both) or np.max(d[both]) > max_dist:
            continue
        score = np.mean(d[both] ** 2)
        if best is None or score < best[0]:
            best = (score, name, g)
    if best is None:
        return (None, None) if return_name else None
    out = np.array(best[2])
    return (out, best[1]) if return_name else out


# ---------------------------------------------------------------------------
# Lucchese-Mitra saddle fit
# ---------------------------------------------------------------------------
def cone_kernel(radius: int) -> np.ndarray:
    """The (2r+1)^2 cone low-pass kernel of ROCHADE / libcbdetect, summing to 1

    SYNOPSIS

        >>> k = cone_kernel(1)
        >>> k.shape, float(k.sum().round(12)), bool(k[1, 1] == k.max())
        ((3, 3), 1.0, True)

    Weight max(0, r + 1 - |(x, y)|) at integer offsets (x, y): a linear
    fall-off from the centre, zero outside the disc of radius r + 1.
    """
    r = int(radius)
    y, x = np.mgrid[-r : r + 1, -r : r + 1]
    k = np.maximum(0.0, r + 1 - np.hypot(x, y))
    return k / k.sum()


@functools.lru_cache(maxsize=16)
def _saddle_design(win: int):
    """Window offsets (m, 2) and the pseudo-inverse (6, m) of the quadratic fit"""
    oy, ox = np.mgrid[-win : win + 1, -win : win + 1]
    ox = ox.ravel().astype(float)
    oy = oy.ravel().astype(float)
    A = np.stack((ox * ox, ox * oy, oy * oy, ox, oy, np.ones_like(ox)), axis=-1)
    P = np.linalg.pinv(A)
    P.setflags(write=False)
    offsets = np.stack((ox, oy), axis=-1)
    offsets.setflags(write=False)
    return offsets, P


def _bilinear(img: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """img sampled at (x, y) (mrcal convention), 0 <= x < W-1, 0 <= y < H-1"""
    x0 = np.floor(x).astype(np.intp)
    y0 = np.floor(y).astype(np.intp)
    fx = x - x0
    fy = y - y0
    i00 = img[y0, x0]
    i01 = img[y0, x0 + 1]
    i10 = img[y0 + 1, x0]
    i11 = img[y0 + 1, x0 + 1]
    return (i00 * (1 - fx) + i01 * fx) * (1 - fy) + (i10 * (1 - fx) + i11 * fx) * fy


def saddle_refine(image, corners0, win: int = 5, cone_radius: int | None = None,
                  max_iter: int = 20, eps: float = 1e-3) -> np.ndarray:
    """Lucchese-Mitra saddle-point refinement, vectorised over corners

    SYNOPSIS

        >>> import numpy as np
        >>> y, x = np.mgrid[0:30, 0:30].astype(float)
        >>> image = 128 + 100 * np.tanh(x - 14.25) * np.tanh(y - 15.5)
        >>> np.round(saddle_refine(image, [[15., 15.], [14., 16.]], win=3), 2)
        array([[14.25, 15.5 ],
               [14.25, 15.5 ]])
        >>> blob = 100 * np.exp(-((x - 15) ** 2 + (y - 15) ** 2) / 20)
        >>> saddle_refine(blob, [15., 15.], win=3)      # a peak, not a saddle
        array([nan, nan])

    Lucchese & Mitra (2002): near a checkerboard corner a low-passed image is
    a hyperbolic paraboloid. Per corner and iteration:

    1. sample the (2 win + 1)^2 window centred on the current estimate p by
       bilinear interpolation (re-centring on the sub-pixel estimate, as
       cv2.cornerSubPix does: at convergence the window is symmetric about
       the corner, so terms of the image beyond quadratic, which are even
       about a point-symmetric corner, cannot pull the solution);
    2. fit f = a x^2 + b xy + c y^2 + d x + e y + g by linear least squares
       (the design matrix is the same for every window: its pseudo-inverse
       is precomputed);
    3. reject the corner if 4ac - b^2 >= 0 (not a saddle);
    4. step to the stationary point, [2a b; b 2c] (x, y) = -(d, e).

    Iteration stops when the step is shorter than eps pixels; a corner that
    has not converged after max_iter iterations keeps its last estimate (as
    libcbdetect and OpenCV do). A corner that moves more than win from its
    start, or whose window (plus one pixel for interpolation, plus the cone
    radius) leaves the image, is rejected. Rejected corners, and NaN starts,
    come back as NaN.

    cone_radius: if given (> 0), the image is first convolved with
    cone_kernel(cone_radius), the low-pass of ROCHADE and libcbdetect; None
    or 0 fits the image as it is (fine for images that are already smooth,
    e.g. blurred by the optics).

    corners0 has any shape (..., 2); the result has the same shape. The
    solution does not depend on the intensity scale.
    """
    img = np.asarray(image, np.float64)
    if img.ndim != 2:
        raise ValueError(f"saddle_refine needs a 2-D image; got shape {img.shape}")
    win = int(win)
    if win < 1:
        raise ValueError(f"win must be >= 1; got {win}")
    r = int(cone_radius or 0)
    if r > 0:
        img = cv2.filter2D(img, cv2.CV_64F, cone_kernel(r), borderType=cv2.BORDER_REFLECT)
    offsets, P = _saddle_design(win)
    margin = win + 1 + r

    p0 = np.asarray(corners0, np.float64)
    flat = p0.reshape(-1, 2)
    p = flat.copy()
    alive = _inside(flat, img.shape, margin)  # still a candidate
    active = alive.copy()  # still iterating
    for _ in range(int(max_iter)):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        q = p[idx, None, :] + offsets  # (n, m, 2)
        patch = _bilinear(img, q[..., 0], q[..., 1])  # (n, m)
        a, b, c, d, e, _g = np.moveaxis(patch @ P.T, -1, 0)
        det = 4 * a * c - b * b
        saddle = det < 0
        with np.errstate(divide="ignore", invalid="ignore"):
            step = -np.stack((2 * c * d - b * e, 2 * a * e - b * d), axis=-1) / det[:, None]
        p[idx] += np.where(saddle[:, None], step, 0.0)
        bad = (
            ~saddle
            | (np.linalg.norm(p[idx] - flat[idx], axis=-1) > win)
            | ~_inside(p[idx], img.shape, margin)
        )
        alive[idx[bad]] = False
        active[idx[bad]] = False
        active[idx[~bad & (np.linalg.norm(step, axis=-1) < eps)]] = False
    p[~alive] = np.nan
    return p.reshape(p0.shape)


def refine_by_window(refine, image, start, window) -> np.ndarray:
    """refine(image, points, win) once per whole-pixel window; NaN where a corner moved beyond its window

    SYNOPSIS

        >>> import numpy as np
        >>> start = np.array([[10.0, 10.0], [20.0, 20.0], [np.nan, np.nan]])
        >>> refiner = lambda image, p, win: p + 0.25 * win * (p > 15) * (1, 0)   # a stand-in
        >>> refine_by_window(refiner, None, start, np.array([3.2, 6.0, 4.0])).tolist()
        [[10.0, 10.0], [21.5, 20.0], [nan, nan]]
        >>> refine_by_window(refiner, None, start, np.array([3.2, 1.2, 4.0]))[1]   # win 2, moved 0.5
        array([20.5, 20. ])
        >>> refine_by_window(lambda image, p, win: p + 5.0, None, start, np.full(3, 3.0))[:2].tolist()
        [[nan, nan], [nan, nan]]

    start: (..., 2) points (NaN: none), window: (...) half-window per point
    (px, as detect_pose's PoseCorners.window). Each point is refined with
    win = floor(window), at least 2; a result farther than `window` from
    its start is dropped, as detect_pose(refine=REFINERS['opencv'|'saddle']) does.
    """
    start = np.asarray(start, float)
    window = np.asarray(window, float)
    out = np.full(start.shape, np.nan)
    ok = np.isfinite(start).all(axis=-1) & np.isfinite(window)
    win = np.where(ok, np.maximum(np.floor(np.nan_to_num(window)), 2), 0).astype(int)
    for w in np.unique(win[ok]):
        sel = ok & (win == w)
        out[sel] = refine(image, start[sel], int(w))
    with np.errstate(invalid="ignore"):
        out[np.linalg.norm(out - start, axis=-1) > window] = np.nan
    return out


# ---------------------------------------------------------------------------
# mrgingham
# ---------------------------------------------------------------------------
class MrginghamNotInstalled(FileNotFoundError):
    """The mrgingham executable is not on PATH"""


def _parse_mrgingham_vnlog(text: str, gridn: int) -> dict[str, np.ndarray | None]:
    """mrgingham's `# filename x y level` vnlog -> {filename: (gridn, gridn, 2) or None}

    SYNOPSIS

        >>> out = _parse_mrgingham_vnlog("# filename x y level\\na.png - - -\\n"
        ...     + "".join(f"b c.png {x} {y} 0\\n" for y in (5, 6) for x in (1, 2)), 2)
        >>> out["a.png"], out["b c.png"][1, 0]
        (None, array([1., 6.]))

    Filenames may contain spaces (the last three fields are split off).
    """
    rows: dict[str, list] = {}
    for line in text.splitlines():
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        fields = line.rsplit(None, 3)
        if len(fields) != 4:
            raise ValueError(f"unexpected mrgingham output line {line!r}")
        name, x, y, _level = fields
        lst = rows.setdefault(name, [])
        if x != "-" and y != "-":
            lst.append((float(x), float(y)))
    out = {}
    for name, pts in rows.items():
        if len(pts) == gridn * gridn:
            out[name] = np.array(pts).reshape(gridn, gridn, 2)
        else:
            out[name] = None
    return out


def mrgingham_detect(image_paths, gridn: int, jobs: int = 1, extra_args=()) -> dict:
    """Run the mrgingham CLI; {path: (gridn, gridn, 2) corners or None}

    SYNOPSIS

        >>> import shutil, tempfile, os, cv2, numpy as np
        >>> y, x = np.mgrid[0:200, 0:200] + 0.5      # pixel boundaries at 20, 40, ...
        >>> sq = ((x - 20) // 20 + (y - 20) // 20) % 2
        >>> inside = (x > 20) & (x < 180) & (y > 20) & (y < 180)
        >>> board = np.where(inside, 230 * sq + 20, 250).astype(np.float32)
        >>> board = cv2.GaussianBlur(board, (0, 0), 1.)  # mrgingham wants soft edges
        >>> path = os.path.join(tempfile.mkdtemp(), "board.png")
        >>> _ = cv2.imwrite(path, np.round(board).astype(np.uint8))
        >>> c = mrgingham_detect([path], 7)[path]   # Debian's mrgingham: make setup installs it
        >>> c.shape, bool(np.abs(c[0, 0] - 39.5).max() < 0.1)
        ((7, 7, 2), True)

    mrgingham (gridn x gridn inner corners: square boards only) is run once
    on all the paths, `mrgingham --jobs J --gridn N extra_args paths`, and its
    vnlog output parsed. Each path is passed as a glob pattern that matches
    only itself (glob characters escaped), since mrgingham expands globs.
    An image where no complete board was found maps to None. The keys are the
    image_paths as given.

    mrgingham's pixel convention is mrcal's (its own output is what mrcal
    reads), so no offset is applied. Its ordering is image-space "top-left
    first, horizontal direction first", returned as given: (gridn, gridn, 2)
    with row j outer; relabel with match_to_reference.

    Raises MrginghamNotInstalled if the executable is not on PATH (Debian
    package "mrgingham"), FileNotFoundError for a missing image, and
    RuntimeError if mrgingham fails.
    """
    exe = shutil.which("mrgingham")
    if exe is None:
        raise MrginghamNotInstalled("mrgingham is not installed (not on PATH); on Debian: apt-get install mrgingham")
    paths = list(image_paths)
    if not paths:
        return {}
    for p in paths:
        if not os.path.isfile(p):
            raise FileNotFoundError(f"{p}: no such image")
    cmd = [exe, "--jobs", str(int(jobs)), "--gridn", str(int(gridn)), *map(str, extra_args)]
    cmd += [glob.escape(os.fspath(p)) for p in paths]
    run = run_tool(cmd, capture_output=True, text=True)
    if run.returncode != 0:
        raise RuntimeError(f"mrgingham failed (exit {run.returncode}): {run.stderr.strip()[-2000:]}")
    parsed = _parse_mrgingham_vnlog(run.stdout, int(gridn))
    normed = {os.path.normpath(k): v for k, v in parsed.items()}
    out = {}
    for p in paths:
        s = os.fspath(p)
        if s in parsed:
            out[p] = parsed[s]
        else:
            out[p] = normed.get(os.path.normpath(s))
    return out

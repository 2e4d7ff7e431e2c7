"""The checks of a calibration: its inputs before mrcal runs, its fit after each solve

SYNOPSIS

    >>> far_boards({"pose000": 0.011, "pose001": 0.009, "pose002": 0.01, "pose003": 3.2})
    {'pose003': 3.2}
    >>> mostly_line({"pose022": [37, 42]})
    'pose022 (37 of 42)'

    check_inputs(cs)                   # InputError: fewer than MIN_BOARDS boards, mixed image sizes
    check_inputs(cs, lensmodel)        # ... and a splined model the boards cannot constrain
    misordered_boards(cs.corners, cs.files, cs.layout)   # {file: why}: boards out of grid order
    fit_failures(stats, focal)         # why a fit (solve.model_stats) is no calibration
    model_failures(stats)              # the checks a written model must pass

Inputs that cannot
give a model raise InputError before mrcal runs (check_inputs): fewer than
MIN_BOARDS boards, images of different sizes, a focal seed that the boards
do not agree on. A splined model needs SPLINED_MIN_BOARDS boards whose corners
reach SPLINED_MIN_COVERAGE of the cells of a knot-sized grid over the imager
(splined_supported).

Boards out of the pattern's grid order (misordered_boards: shuffled rows, a
transposed board) are found before mrcal runs. After each solve, a fit is
implausible (fit_failures) when its focal lengths are not within
FOCAL_FIT_FACTOR of the boards' estimate, its RMS is above MAX_FIT_RMS_PX,
or boards are far off the rest (far_boards); calibrate.solve then searches
the board that explains it (up to MAX_DROP_SEARCH boards).

Checks on the model written (Calibration.failures; rotstar-calibrate exits 1
unless --keep): mrcal rejected more than MAX_OUTLIER_FRACTION of the corners
as outliers, or most of the corners of one board (MOSTLY_OUTLIERS), or the
valid-intrinsics region is empty.
"""

from __future__ import annotations

import numpy as np

from rotstar_mrcal.calibrate.command import DEFAULT_KNOTS_X, InputError, resolve_image

MIN_BOARDS = 4
"""Fewer boards than this are not calibrated (mrcal would, and badly: one board gives a model 34 px off)"""

SPLINED_MIN_BOARDS = 40
"""Below this many boards a splined model is poorly constrained (doc/validation.md)"""

SPLINED_MIN_COVERAGE = 0.9
"""... and below this fraction of the knot grid's cells holding a corner"""

MAX_OUTLIER_FRACTION = 0.02
"""A calibration that rejects more of its corners than this fails its checks"""

MOSTLY_OUTLIERS = 0.5
"""A board of which mrcal rejected more than this fraction of its corners was seeded badly (module doc)"""

GRID_BEND_MAX = 0.5
"""A second difference of neighbouring corners longer than this fraction of their spacing is a break in the grid"""

GRID_DISORDER_MAX = 0.05
"""A board with more than this fraction of breaks is not in the pattern's grid order (misordered_boards)"""

MAX_FIT_RMS_PX = 1.0
"""A fit RMS above this (2-D, px) is no calibration: corners labelled wrongly or from another camera (fit_failures)"""

BOARD_FAR_FACTOR = 5.0

BOARD_FAR_MIN_PX = 0.05
"""A board whose fit RMS is above BOARD_FAR_FACTOR x the median board's and above BOARD_FAR_MIN_PX is far off the rest"""

FOCAL_FIT_FACTOR = 2.0
"""The solved fx, fy must be within this factor of the focal seed (and positive)"""

MAX_DROP_SEARCH = 40
"""An implausible fit is searched for the one pose that explains it (a solve without each) up to this many poses"""


# ---------------------------------------------------------------------------
# the inputs of a calibration, checked before mrcal runs
# ---------------------------------------------------------------------------
def png_size(path: str) -> tuple[int, int] | None:
    """(width, height) from a PNG's header, None for another or unreadable file

    SYNOPSIS

        >>> import cv2, numpy as np, tempfile, os
        >>> fn = os.path.join(tempfile.mkdtemp(), "a.png"); _ = cv2.imwrite(fn, np.zeros((8, 12), np.uint8))
        >>> png_size(fn)
        (12, 8)
    """
    try:
        with open(path, "rb") as f:
            head = f.read(24)
    except OSError:
        return None
    if len(head) < 24 or head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        return None
    return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")


def grid_disorder(grid) -> float:
    """The fraction of breaks in a board's grid (GRID_BEND_MAX): ~0 for corners in grid order, ~1 for shuffled ones

    Under perspective and lens distortion neighbouring steps of the grid
    change little; corners out of order (rows shuffled, a board read with
    rows and columns swapped) break it. Missing corners (NaN) are skipped.

    SYNOPSIS

        >>> j, i = np.mgrid[0:9, 0:14]
        >>> grid = np.stack([40.0 * i + 0.3 * i * j, 40.0 * j], axis=-1)      # a sheared 14 x 9 grid
        >>> grid_disorder(grid), grid_disorder(grid.reshape(-1, 2).reshape(14, 9, 2)) > GRID_DISORDER_MAX
        (0.0, True)
    """
    q = np.asarray(grid, float)
    bends = []
    for g in (q, q.transpose(1, 0, 2)):
        step = np.diff(g, axis=1)
        d2 = np.linalg.norm(np.diff(step, axis=1), axis=-1)
        scale = 0.5 * (np.linalg.norm(step[:, 1:], axis=-1) + np.linalg.norm(step[:, :-1], axis=-1))
        ok = np.isfinite(d2) & np.isfinite(scale)
        bends.append(d2[ok] > GRID_BEND_MAX * scale[ok])
    b = np.concatenate(bends)
    return float(b.mean()) if len(b) else 0.0


def misordered_boards(corners, files, layout) -> dict[str, str]:
    """{file: why} for the boards whose corners are not in the pattern's grid order (grid_disorder)"""
    out = {}
    nx, ny = layout.nx, layout.ny
    for f, grid in zip(files, corners):
        d = grid_disorder(grid)
        if d <= GRID_DISORDER_MAX:
            continue
        if grid_disorder(np.asarray(grid).reshape(-1, 2).reshape(nx, ny, 2)) <= GRID_DISORDER_MAX:
            out[f] = (f"its corners are in rows of {ny}, not of {nx}: the board is transposed (pattern.json, "
                      f"--object-width-n, says {nx} x {ny})")
        else:
            out[f] = f"its corners are not in grid order ({100 * d:.0f}% of neighbouring steps break the grid)"
    return out


def check_inputs(cs, lensmodel: str | None = None, force: bool = False) -> None:
    """InputError (one line) for a corner set that cannot give a model with this lens model

    Always: at least MIN_BOARDS boards, and every image that can be read of
    the corner set's imager size. Splined models (unless force): at least
    SPLINED_MIN_BOARDS boards covering SPLINED_MIN_COVERAGE of the imager
    (lensmodel None: not checked).
    """
    n = len(cs.files)
    if n < MIN_BOARDS:
        raise InputError(f"{n} board{'s' * (n != 1)} in {cs.vnl}; a calibration needs at least {MIN_BOARDS} "
                         "(more, at many tilts and over the whole imager, for a good one)")
    sizes = {}
    for f in cs.files:
        size = png_size(resolve_image(f, cs.vnl))
        if size is not None:
            sizes.setdefault(size, []).append(f)
    other = {s: fs for s, fs in sizes.items() if s != tuple(cs.imagersize)}
    if other:
        s, fs = next(iter(other.items()))
        raise InputError(f"{len(fs)} image{'s' * (len(fs) != 1)} of size {s[0]}x{s[1]} (e.g. {fs[0]}) among "
                         f"{cs.imagersize[0]}x{cs.imagersize[1]} ones: one calibration is one imager; "
                         "remove them from the corners file or the dataset")
    if lensmodel and "SPLINED" in lensmodel and not force:
        ok, why = splined_supported(cs)
        if not ok:
            raise InputError(f"{why}; use the default model (--lensmodel auto) or --force to try anyway")


def coverage(cs, knots_x: int = DEFAULT_KNOTS_X) -> float:
    """Fraction of the cells of a knots_x-wide grid over the imager that hold a corner of some board"""
    W, H = cs.imagersize
    ny = max(2, int(round(knots_x * H / W)))
    q = cs.corners.reshape(-1, 2)
    q = q[np.isfinite(q).all(axis=1)]
    ix = np.clip((q[:, 0] / W * knots_x).astype(int), 0, knots_x - 1)
    iy = np.clip((q[:, 1] / H * ny).astype(int), 0, ny - 1)
    return len(set(zip(ix.tolist(), iy.tolist()))) / (knots_x * ny)


def splined_supported(cs, knots_x: int = DEFAULT_KNOTS_X) -> tuple[bool, str]:
    """(can the boards constrain a splined model, why not)"""
    n, c = len(cs.files), coverage(cs, knots_x)
    if n < SPLINED_MIN_BOARDS or c < SPLINED_MIN_COVERAGE:
        return False, (f"a splined model needs >= {SPLINED_MIN_BOARDS} boards covering >= "
                       f"{100 * SPLINED_MIN_COVERAGE:.0f}% of the imager; these are {n} boards covering {100 * c:.0f}%")
    return True, f"{n} boards covering {100 * c:.0f}% of the imager"


# ---------------------------------------------------------------------------
# the fit, checked after each solve
# ---------------------------------------------------------------------------
def far_boards(board_rms: dict) -> dict:
    """{board: its fit RMS} of the boards far off the rest (BOARD_FAR_FACTOR x the median board, BOARD_FAR_MIN_PX)

    >>> far_boards({"pose000": 0.011, "pose001": 0.009, "pose002": 0.01, "pose003": 3.2})
    {'pose003': 3.2}
    """
    if len(board_rms) < 3:
        return {}
    med = float(np.median(list(board_rms.values())))
    return {k: v for k, v in board_rms.items() if v > BOARD_FAR_FACTOR * med and v > BOARD_FAR_MIN_PX}


def fit_failures(s: dict, focal: float) -> list[str]:
    """Why a fit (model_stats) is no calibration: focal lengths far from the boards' estimate (focal), an RMS
    corners cannot have, boards far off the rest (far_boards); one reason each

    >>> fit_failures({"rms_px": 160.0, "focal_px": [-29.0, 640.0], "board_rms_px": {}}, 640)[0]
    "the solved focal length fx -29 px is not within 2x of the boards' estimate 640 px"
    """
    out = []
    for name, v in zip(("fx", "fy"), s["focal_px"]):
        if not focal / FOCAL_FIT_FACTOR <= v <= focal * FOCAL_FIT_FACTOR:
            out.append(f"the solved focal length {name} {v:.0f} px is not within {FOCAL_FIT_FACTOR:g}x of the boards' "
                       f"estimate {focal:.0f} px")
    med = float(np.median(list(s["board_rms_px"].values()))) if s.get("board_rms_px") else float("nan")
    if not s["rms_px"] <= MAX_FIT_RMS_PX:
        out.append(f"the fit RMS {s['rms_px']:.3g} px is more than corners can be off ({MAX_FIT_RMS_PX:g} px; "
                   f"the median board's {med:.3g} px): corners labelled wrongly, or not of this camera")
    far = far_boards(s.get("board_rms_px") or {})
    if far:
        out.append("boards far off the rest: " + ", ".join(f"{k} (fit RMS {v:.3g} px)" for k, v in far.items())
                   + f", the median board's {med:.3g} px")
    return out


def model_failures(s: dict) -> list[str]:
    """The checks a written model must pass; one reason per failure"""
    out = []
    if s["outlier_fraction"] > MAX_OUTLIER_FRACTION:
        out.append(f"mrcal rejected {s['outliers']} of the corners as outliers ({100 * s['outlier_fraction']:.1f}% > "
                   f"{100 * MAX_OUTLIER_FRACTION:.0f}%; where: "
                   + ", ".join(f"{k} {v}" for k, v in s["outliers_where"].items()) + ")")
    if s.get("boards_mostly_outliers"):
        out.append("mrcal rejected most corners of " + mostly_line(s["boards_mostly_outliers"])
                   + ": those boards' poses are barely constrained")
    if s.get("valid_region_fraction") == 0.0:
        out.append("the valid-intrinsics region is empty (no part of the imager is both seen and well "
                   "constrained)")
    return out


def mostly_line(mostly: dict) -> str:
    """'pose022 (37 of 42)' for model_stats' boards_mostly_outliers

    >>> mostly_line({"pose022": [37, 42], "pose025": [30, 40]})
    'pose022 (37 of 42), pose025 (30 of 40)'
    """
    return ", ".join(f"{k} ({a} of {b})" for k, (a, b) in mostly.items())

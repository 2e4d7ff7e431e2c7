"""mrcal's corners.vnl: writing and reading

SYNOPSIS

    >>> import io, numpy as np
    >>> from rotstar_mrcal.vnl import write_corners, read_corners, mrcal_keeps, mrcal_min_corners
    >>> grid = np.arange(12.0).reshape(2, 3, 2); grid[1, 2] = np.nan
    >>> out = io.StringIO()
    >>> write_corners(out, [("seq/a/rotstar_00.png", grid), ("seq/b/rotstar_00.png", None)])
    []
    >>> print(out.getvalue().splitlines()[1:3], out.getvalue().splitlines()[-1])
    ['seq/a/rotstar_00.png 0.000000 1.000000 0.5', 'seq/a/rotstar_00.png 2.000000 3.000000 0.5'] seq/b/rotstar_00.png - - -
    >>> boards = read_corners(io.StringIO(out.getvalue()), 3, 2)
    >>> boards["seq/a/rotstar_00.png"][1, 2].tolist(), boards["seq/b/rotstar_00.png"]
    ([nan, nan], None)
    >>> sparse = np.full((9, 14, 2), np.nan); sparse[0] = 1.0    # 14 corners of a 14 x 9 board
    >>> mrcal_min_corners(14, 9), mrcal_keeps(sparse)
    (18, False)
    >>> write_corners(io.StringIO(), [("seq/c/rotstar_00.png", sparse)])  # written as no board
    [SparseBoard(file='seq/c/rotstar_00.png', corners=14, limit=18)]
    >>> corners_text(b"\\xef\\xbb\\xbf# filename x y level\\r\\na.png 1 2 0.5\\r\\n", "c.vnl")   # BOM, CRLF
    '# filename x y level\\na.png 1 2 0.5\\n'
    >>> corners_text(b"# filename x y level\\na.png 1 2 0.5\\n", "c.vnl") is None   # plain: mrcal reads it as is
    True

The rules (mrcal 2.5, checked against mrcal.compute_chessboard_corners): a
header line `# filename x y level` (or `weight`), then per image either
exactly nx*ny rows in mrcal order (row j outer, column i inner; record
j*nx + i is board point (i, j) * spacing) or a single `filename - - -` row for
an image without a board. A missing corner is `filename - - -`. Coordinates
use mrcal's convention (centre of the top-left pixel = (0, 0)). Filenames must
be ASCII without whitespace. With weights (mrcal's
--corners-cache-has-weights) the fourth column is a weight proportional to
1/sigma; otherwise it is `level` LEVEL = 0.5 on every corner.

mrcal's row rule: a board with at most 2 * min(nx, ny) valid corners is
dropped without a word by mrcal-calibrate-cameras (18 for the default 14 x 9
board). write_corners writes such a board as one `filename - - -` row, the
way mrcal treats it, and returns it (a SparseBoard) so that the tool that
wrote the file can say so: the boards a user is told about are the boards
mrcal uses. Valid is mrcal's own test: x and y given and >= 0 (a negative
coordinate is "missing" to mrcal) and, with weights, a weight > 0
(mrcal_valid). mrcal_keeps reads it on a file's boards.

Why 0.5 and not 0. mrcal's tools disagree about the fourth column of a
`# filename x y level` file: mrcal-calibrate-cameras (and
mrcal.compute_chessboard_corners' default) read it as a decimation level,
weight 2^-int(level), but mrcal-cull-corners --cull-random-observations-ratio
(mrcal 2.5.2) reads the same file with weight_column_kind='weight', so level
0 becomes weight 0, "missing", and every board is lost; it then writes the
weights back as levels (int(weight)). A level in (0, 1) is read as weight 1
by the first (int(0.5) = 0: exactly mrgingham's level 0) and as weight 0.5,
a valid corner, by the second, which writes it back as level 0. So every
corner is kept by both, and the calibration's residuals stay in pixels (a
level of 1 would also work for mrcal-cull-corners, but makes every weight
1/2, and mrcal's residual plots and histograms, which show weighted
residuals, would read half the true error). mrcal-cull-corners needs the
header exactly `# filename x y level` and four columns (it sets the fourth to
'-' to cull a point), so dropping the column is no way out. Weighted files
(`# filename x y weight`) are read by mrcal-calibrate-cameras
--corners-cache-has-weights; mrcal-cull-corners refuses them (its header
check), as it refuses any weighted file.
"""

from __future__ import annotations

import codecs
import dataclasses
import io

import numpy as np

LEVEL = "0.5"
"""The fourth column of an unweighted corners.vnl (module doc: why not 0)"""


class CornersFileError(ValueError):
    """A corners file that cannot be read as text; the message names the file and the reason"""


_BOMS = ((codecs.BOM_UTF32_LE, "utf-32"), (codecs.BOM_UTF32_BE, "utf-32"), (codecs.BOM_UTF8, "utf-8-sig"),
         (codecs.BOM_UTF16_LE, "utf-16"), (codecs.BOM_UTF16_BE, "utf-16"))


def corners_text(data: bytes, path: str) -> str | None:
    """A corners file's bytes as the text mrcal needs (ASCII, '\\n' line ends), or None when they are that already

    Read as text in any common form: UTF-8 (with or without a byte-order
    mark), UTF-16 or UTF-32 with a byte-order mark, and CRLF, CR or LF line
    ends. mrcal's parser takes '\\r' as part of the last field (a level
    `0.5\\r` is misread: issue 20), so a file in another form is handed to
    mrcal as a normalised copy (mrcal_corners). CornersFileError (naming path)
    for bytes that are not such text, or text mrcal cannot read (not ASCII,
    NUL bytes).
    """
    enc = next((e for bom, e in _BOMS if data.startswith(bom)), "utf-8")
    try:
        text = data.decode(enc)
    except UnicodeDecodeError as e:
        raise CornersFileError(f"{path}: not a text file in UTF-8, or UTF-16/32 with a byte-order mark "
                               f"(undecodable byte at offset {e.start})") from None
    if "\0" in text:
        raise CornersFileError(f"{path}: holds NUL characters (UTF-16 without a byte-order mark?); "
                               "write it as ASCII text")
    lines = text.splitlines()
    bad = next((i for i, line in enumerate(lines) if not line.isascii()), None)
    if bad is not None:
        raise CornersFileError(f"{path}: line {bad + 1} is not ASCII (mrcal reads ASCII file names and numbers only)")
    norm = "".join(line + "\n" for line in lines)
    return None if norm.encode("ascii") == data else norm


def open_corners(path: str) -> io.StringIO:
    """A corners file as a text stream (corners_text: any common line end and encoding); CornersFileError"""
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError as e:
        raise CornersFileError(f"{path}: cannot be read ({e.strerror or e})") from None
    text = corners_text(data, path)
    return io.StringIO(data.decode("ascii") if text is None else text)


def mrcal_can_read(fn: str) -> bool:
    """mrcal's corners.vnl parser needs ASCII file names without whitespace"""
    return fn.isascii() and not any(c.isspace() for c in fn)


def _check_name(fn: str) -> str:
    if not mrcal_can_read(fn):
        raise ValueError(f"{fn!r}: mrcal needs ASCII file names without whitespace")
    return fn


@dataclasses.dataclass(frozen=True)
class SparseBoard:
    """A board mrcal would drop: written as no board (write_corners)"""

    file: str
    corners: int  # its valid corners
    limit: int  # mrcal keeps a board only with more than this many


def mrcal_min_corners(nx: int, ny: int) -> int:
    """mrcal keeps a board only if it has MORE valid corners than this: 2 * min(nx, ny)

    mrcal 2.5.2, mrcal/calibration.py, compute_chessboard_corners (which
    mrcal-calibrate-cameras calls without Npoint_observations_per_board_min):
    l.191-192 `Npoint_observations_per_board_min = 2*min(W,H)`, and l.326-327
    keeps a board only if `context['Nvalidpoints'] >
    Npoint_observations_per_board_min` (its docstring says "fewer than",
    the code drops equality too). W, H: --object-width-n, --object-height-n.
    """
    return 2 * min(int(nx), int(ny))


def mrcal_valid(grid, weights=None) -> np.ndarray:
    """(ny, nx) bool: the corners mrcal counts as observed

    mrcal/calibration.py parse_point (l.376-413): x and y not '-' and both
    >= 0; with a weight column, a weight > 0. NaN is how we write '-'.
    """
    xy = np.asarray(grid, float)
    ok = np.isfinite(xy).all(axis=-1) & (np.nan_to_num(xy, nan=-1.0) >= 0).all(axis=-1)
    if weights is not None:
        w = np.asarray(weights, float)
        ok &= np.isfinite(w) & (np.nan_to_num(w, nan=0.0) > 0)
    return ok


def mrcal_keeps(grid, weights=None) -> bool:
    """Does mrcal use this (ny, nx, 2) board (more than mrcal_min_corners valid corners)?"""
    if grid is None:
        return False
    ny, nx = np.shape(grid)[:2]
    return int(mrcal_valid(grid, weights).sum()) > mrcal_min_corners(nx, ny)


def write_corners(stream, boards, weights=None, precision: int = 6) -> list[SparseBoard]:
    """Write [(filename, (ny, nx, 2) array or None), ...] as corners.vnl; returns the boards written as none

    weights: optional list parallel to boards of (ny, nx) arrays (> 0) for the
    fourth column; NaN or <= 0 weights mark the corner missing. A board that
    mrcal would drop (mrcal_keeps) is written as one `filename - - -` row and
    returned as a SparseBoard, for the caller to say so.
    """
    stream.write("# filename x y " + ("weight" if weights is not None else "level") + "\n")
    sparse = []
    for b, (fn, grid) in enumerate(boards):
        fn = _check_name(fn)
        if grid is None:
            stream.write(f"{fn} - - -\n")
            continue
        wt = None if weights is None else np.asarray(weights[b], float)
        valid = mrcal_valid(grid, wt)
        ny, nx = valid.shape
        if not mrcal_keeps(grid, wt):
            sparse.append(SparseBoard(fn, int(valid.sum()), mrcal_min_corners(nx, ny)))
            stream.write(f"{fn} - - -\n")
            continue
        xy = np.asarray(grid, float).reshape(-1, 2)
        valid = valid.ravel()
        fourth = [f"{v:.6g}" for v in np.where(valid, wt.ravel(), 0)] if wt is not None else [LEVEL] * len(xy)
        for (x, y), ok, f4 in zip(xy, valid, fourth):
            stream.write(f"{fn} {x:.{precision}f} {y:.{precision}f} {f4}\n" if ok else f"{fn} - - -\n")
    return sparse


def read_corners(stream, nx: int, ny: int) -> dict:
    """{filename: (ny, nx, 2) array with NaN for missing, or None for no board}"""
    rows: dict[str, list] = {}
    order: list[str] = []
    for line in stream:
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        f = line.split()
        if f[0] not in rows:
            rows[f[0]] = []
            order.append(f[0])
        if len(f) < 3:
            raise ValueError(f"{f[0]}: a row of {len(f)} field{'s' * (len(f) != 1)}, expected filename x y [level]")
        if f[1] == "-":
            rows[f[0]].append([np.nan, np.nan])
            continue
        try:
            xy = [float(f[1]), float(f[2])]
        except ValueError:
            raise ValueError(f"{f[0]}: corner {len(rows[f[0]])}: coordinates {f[1]} {f[2]} are not numbers") from None
        if not np.isfinite(xy).all():
            raise ValueError(f"{f[0]}: corner {len(rows[f[0]])}: coordinates {f[1]} {f[2]} are not finite "
                             "(a missing corner is written '- - -')")
        rows[f[0]].append(xy)
    out = {}
    for fn in order:
        r = rows[fn]
        if len(r) == 1 and np.isnan(r[0][0]):
            out[fn] = None
        elif len(r) == nx * ny:
            out[fn] = np.array(r).reshape(ny, nx, 2)
        else:
            raise ValueError(f"{fn}: {len(r)} rows, expected {nx * ny} (the pattern's {nx} x {ny} corners) or 1")
    return out

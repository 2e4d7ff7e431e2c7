"""The mrcal-calibrate-cameras command for a corners.vnl, running it, and choosing the model

SYNOPSIS

    >>> from rotstar_mrcal.pattern.layout import make_layout
    >>> from rotstar_mrcal.calibrate.solve import recommended_lensmodel, calibrate_argv, image_glob
    >>> recommended_lensmodel((1280, 800), focal=640)
    'LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx=16_Ny=10_fov_x_deg=117'
    >>> resolve_lensmodel("auto", (1280, 800), 640), resolve_lensmodel("opencv5", (1280, 800), 640)
    ('LENSMODEL_OPENCV8', 'LENSMODEL_OPENCV5')
    >>> image_glob(["seq/pose000/rotstar_00.png", "seq/pose010/rotstar_00.png"])
    '*/rotstar_00.png'
    >>> argv = calibrate_argv("corners.vnl", make_layout(), (1280, 800), 640,
    ...                       "LENSMODEL_OPENCV8", "cal", "*/rotstar_00.png")
    >>> print(command_line(argv))
    mrcal-calibrate-cameras --corners-cache corners.vnl --lensmodel LENSMODEL_OPENCV8 --focal 640 --imagersize 1280 800 --object-spacing 0.0144318182 --object-width-n 14 --object-height-n 9 --valid-intrinsics-region-parameters 5 0.05 2 3 0 --outdir cal '*/rotstar_00.png'

    # the whole calibration, as rotstar-calibrate runs it:
    cs = sources.load_corner_set("cal/corners.vnl", truth=False)
    c = calibrate(cs, "cal")            # a Calibration; c.ok, c.reason, c.to_json()
    print("\n".join(c.summary_lines()))

The lens model. mrcal's practice (doc/how-to-calibrate.org, "Model
choice", and the tour) is to fit a lean model first and a rich one when the
data can constrain it, and to compare them. The default ('auto') here:

1. LENSMODEL_OPENCV8, the lean model, on every board (LEAN_LENSMODEL; this is
   also the model of rotstar-detect's printed command and of rotstar-crossval).
2. mrcal's recommended LENSMODEL_SPLINED_STEREOGRAPHIC (order 3, dense knots
   whose Ny/Nx follows the imager's aspect ratio, a field of view of
   4 atan(W / 4f) + 10% from the focal seed f) only when the boards can
   constrain it: at least SPLINED_MIN_BOARDS boards whose corners reach
   SPLINED_MIN_COVERAGE of the cells of a knot-sized grid over the imager.
3. Both are compared with mrcal.projection_diff against the sum of their
   projection uncertainties. The splined model is written only when it
   explains the corners clearly better (fit RMS below SPLINED_BETTER_RMS of
   the lean one's) and the two differ beyond their uncertainty: the lean
   model does not fit the lens. When the splined fit is no better, the lean
   model is written (the splined one's extra freedom is not supported by the
   boards). When they fit equally well but disagree, the check fails.

Checks on the model written (Calibration.failures; rotstar-calibrate exits 1
unless --keep): mrcal rejected more than MAX_OUTLIER_FRACTION of the corners
as outliers, or most of the corners of one board (MOSTLY_OUTLIERS), or the
valid-intrinsics region is empty.

A board mrcal seeds badly. mrcal-calibrate-cameras seeds every board's pose
from a stereographic core without distortion and rejects outliers from the
first full solve on. A board far into an image corner, close and tilted (a
board hanging over the edge, which the identity frames make possible) can
be seeded so far off that mrcal rejects most of its corners, leaving a few
in a line: a board pose the data no longer pins down, which makes the
projection uncertainty explode (measured on a simulated 20-pose capture: 37
of 42 corners of one such board rejected, the uncertainty at the imager
corners 5000 px instead of 0.05). Short of that, which corners of such
boards mrcal rejects depends on the random start it gives the distortion
terms (measured: 0, 5 or 8 good corners of the same 20 boards over eight
starts). So whenever mrcal rejected corners, calibrate() solves again,
seeded from the model of the first solve (mrcal-calibrate-cameras --seed
instead of --focal: every board's pose then starts from a model with
distortion, and no term starts at random), and keeps that solve if it
rejects fewer corners; real outliers are rejected by both. Inputs that cannot
give a model raise InputError before mrcal runs (check_inputs): fewer than
MIN_BOARDS boards, images of different sizes, a focal seed that the boards
do not agree on.

The valid-intrinsics region: mrcal-calibrate-cameras computes it from the
parameters (uncertainty, mean, stdev, count, distance); the region is the
part of the imager where the projection uncertainty is below
uncertainty*sigma, and, for a lean model, where in cells of a 30-wide grid
the residuals' mean is below `mean` px, their spread below stdev*sigma and
more than `count` corners were seen (sigma: the residuals' spread). mrcal's
defaults (1, 0.5, 1.5, 3, 0) suit corners of ~0.3 px; with sigma of
0.004-0.01 px an uncertainty below 1 sigma is found nowhere and the region
comes out empty. VALID_REGION_PARAMETERS (5, 0.05, 2, 3, 0) asks for an
uncertainty below 5 sigma (0.02-0.05 px for rotstar corners), a residual
bias below 0.05 px, and the corner count and spread of mrcal's defaults (2
sigma instead of 1.5).

mrcal-calibrate-cameras matches the file names of the corners.vnl against the
image globs (fnmatch, '*' also matches '/'); one glob per camera. The images
need not exist: the imager size is given. With a weight column (header
`# filename x y weight`, rotstar-detect --weights) the command gets
--corners-cache-has-weights.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import runpy
import shlex
import shutil
import sys
import tempfile

import mrcal
import numpy as np

from rotstar_mrcal.atomic import atomic_path
from rotstar_mrcal.programs import run_tool

LEAN_LENSMODEL = "LENSMODEL_OPENCV8"
"""The lean model: rotstar-detect's printed command, rotstar-crossval, the first fit of rotstar-calibrate"""

SPLINED_MIN_BOARDS = 40
"""Below this many boards a splined model is poorly constrained (doc/validation.md)"""

SPLINED_MIN_COVERAGE = 0.9
"""... and below this fraction of the knot grid's cells holding a corner"""

SPLINED_BETTER_RMS = 0.8
"""The splined model replaces the lean one only if its fit RMS is below this fraction of the lean one's"""

DEFAULT_KNOTS_X = 16

MIN_BOARDS = 4
"""Fewer boards than this are not calibrated (mrcal would, and badly: one board gives a model 34 px off)"""

MAX_OUTLIER_FRACTION = 0.02
"""A calibration that rejects more of its corners than this fails its checks"""

MOSTLY_OUTLIERS = 0.5
"""A board of which mrcal rejected more than this fraction of its corners was seeded badly (module doc)"""

VALID_REGION_PARAMETERS = (5, 0.05, 2, 3, 0)
"""mrcal-calibrate-cameras --valid-intrinsics-region-parameters for sub-0.05 px corners (module doc)"""

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

FOCAL_MIN_BOARDS = 3
FOCAL_MAX_SPREAD = 0.15
"""The focal seed needs this many boards whose estimates agree to this (median absolute deviation / median)"""


class CalibrationError(RuntimeError):
    """mrcal-calibrate-cameras failed; the message ends with its last output lines"""


class InputError(ValueError):
    """Inputs that cannot give a model (too few boards, mixed image sizes, no focal seed); one line"""


def splined_fov_deg(imagersize, focal: float, margin: float = 1.1) -> int:
    """Horizontal field of view (whole degrees, rounded up) for a splined model

    SYNOPSIS

        >>> splined_fov_deg((1280, 800), 640)
        117
    """
    W = float(imagersize[0])
    return int(math.ceil(margin * math.degrees(4 * math.atan(W / (4 * focal)))))


def recommended_lensmodel(imagersize, focal: float, knots_x: int = DEFAULT_KNOTS_X) -> str:
    """mrcal's recommended splined model for this imager and focal seed"""
    W, H = (float(v) for v in imagersize)
    ny = max(2, int(round(knots_x * H / W)))
    return (f"LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx={knots_x}_Ny={ny}"
            f"_fov_x_deg={splined_fov_deg(imagersize, focal)}")


def resolve_lensmodel(spec: str, imagersize, focal: float, knots_x: int = DEFAULT_KNOTS_X) -> str:
    """'auto' / 'lean' / 'splined' / 'opencv8' / LENSMODEL_... -> the lens model string

    'auto' and 'lean' give LEAN_LENSMODEL (rotstar-calibrate's 'auto' may
    then add a splined model: calibrate()).
    """
    s = spec.strip()
    if s.lower() in ("auto", "lean"):
        return LEAN_LENSMODEL
    if s.lower() == "splined":
        return recommended_lensmodel(imagersize, focal, knots_x)
    if s.lower() in ("opencv8", "opencv4", "opencv5", "opencv12", "pinhole", "stereographic"):
        return "LENSMODEL_" + s.upper()
    if not s.startswith("LENSMODEL_"):
        raise InputError(f"--lensmodel {spec!r}: use 'auto', 'splined', 'opencv8' or an mrcal LENSMODEL_... string")
    return s


def image_glob(filenames) -> str:
    """A glob matching every file name of one camera: '*' + their common tail

    The tail starts at its first '/' (or after the leading digits when the
    names have no folder in common), so that the glob reads like the file
    layout: seq/poseNNN/rotstar_00.png -> '*/rotstar_00.png'.
    """
    names = [str(f) for f in filenames]
    if not names:
        raise ValueError("no file names to make a glob from")
    tail = os.path.commonprefix([n[::-1] for n in names])[::-1]
    if len(names) == 1:
        tail = "/" + os.path.basename(names[0])
    if "/" in tail:
        tail = tail[tail.index("/"):]
    else:
        tail = tail.lstrip("0123456789")
    return "*" + tail


def vnl_has_weights(path: str) -> bool:
    """Does a corners.vnl say (in its `# filename x y ...` header) that column 4 is a weight?"""
    from rotstar_mrcal.vnl import open_corners

    with open_corners(path) as f:
        for line in f:
            s = line.strip()
            if not s:
                continue
            if not s.startswith("#"):
                return False
            fields = s.lstrip("#").split()
            if fields[:3] == ["filename", "x", "y"]:
                return len(fields) > 3 and fields[3] == "weight"
    return False


def mrcal_corners(vnl: str, folder: str, drop=()) -> str:
    """The corners file to hand mrcal: vnl itself when mrcal reads it as we do, else a copy in folder

    The copy (folder/corners.vnl, written atomically) is the text we read
    (vnl.corners_text: LF line ends, ASCII, no byte-order mark) without the
    rows of the image names in drop. CornersFileError for a file that is not
    such text.

    SYNOPSIS

        >>> import tempfile
        >>> d = tempfile.mkdtemp(); fn = os.path.join(d, "c.vnl")
        >>> _ = open(fn, "wb").write(b"# filename x y level\\r\\na/r.png 1 2 0.5\\r\\nb/r.png 3 4 0.5\\r\\n")
        >>> out = mrcal_corners(fn, os.path.join(d, "m"), drop={"b/r.png"})
        >>> out == os.path.join(d, "m", "corners.vnl"), open(out, "rb").read()
        (True, b'# filename x y level\\na/r.png 1 2 0.5\\n')
    """
    from rotstar_mrcal.vnl import corners_text

    with open(vnl, "rb") as f:
        data = f.read()
    text = corners_text(data, vnl)
    if text is None and not drop:
        return vnl
    text = data.decode("ascii") if text is None else text
    keep = [line for line in text.splitlines(keepends=True) if not (line.split()[:1] and line.split()[0] in drop)]
    out = os.path.join(folder, "corners.vnl")
    os.makedirs(folder, exist_ok=True)
    with atomic_path(out) as tmp, open(tmp, "w", encoding="ascii", newline="\n") as f:
        f.write("".join(keep))
    return out


def calibrate_argv(vnl: str, layout, imagersize, focal: float, lensmodel: str, outdir: str,
                   glob: str, weights: bool = False, extra=()) -> list[str]:
    """The mrcal-calibrate-cameras command line (a list, program first)"""
    argv = ["mrcal-calibrate-cameras"]
    if weights:
        argv.append("--corners-cache-has-weights")
    argv += [
        "--corners-cache", vnl,
        "--lensmodel", lensmodel,
        "--focal", f"{focal:.0f}",
        "--imagersize", str(int(imagersize[0])), str(int(imagersize[1])),
        *layout.mrcal_object_args(),
        "--valid-intrinsics-region-parameters", *(f"{v:g}" for v in VALID_REGION_PARAMETERS),
        "--outdir", outdir,
        *extra,
        glob,
    ]
    return argv


def command_line(argv) -> str:
    """argv as a shell would take it"""
    return shlex.join([str(a) for a in argv])


def _executable(name: str) -> str:
    """name on PATH, or next to this Python (the venv's bin, where mrcal's tools are)"""
    found = shutil.which(name)
    if found:
        return found
    here = os.path.join(os.path.dirname(sys.executable), name)
    if os.path.exists(here):
        return here
    raise CalibrationError(f"{name} not found on PATH nor next to {sys.executable}; "
                           "put the venv's bin first on PATH")


def run_calibration(argv, in_process: bool = False) -> mrcal.cameramodel:
    """Run a calibrate_argv command; return the model it wrote (camera-0)

    in_process: run the mrcal-calibrate-cameras script in this Python
    (runpy, with sys.argv set and its output captured) instead of a new
    process: the same program, without paying for Python and mrcal's start
    (a few seconds without cached bytecode). For worker processes that run
    many calibrations. Raises CalibrationError with the tail of mrcal's
    output when it fails.
    """
    argv = [str(a) for a in argv]
    outdir = argv[argv.index("--outdir") + 1]
    os.makedirs(outdir, exist_ok=True)
    exe = _executable(argv[0])
    if in_process:
        code, text = _run_script(exe, argv[1:])
    else:
        r = run_tool([exe] + argv[1:], capture_output=True, text=True)
        code, text = r.returncode, r.stdout + r.stderr
    if code != 0:
        tail = "\n".join(text.strip().splitlines()[-6:])
        raise CalibrationError(f"mrcal-calibrate-cameras exited with {code}:\n{tail}")
    fn = os.path.join(outdir, "camera-0.cameramodel")
    if not os.path.exists(fn):
        raise CalibrationError(f"mrcal-calibrate-cameras wrote no {fn}")
    return mrcal.cameramodel(fn)


def _dup_or_none(fd: int) -> int | None:
    """os.dup(fd), None if fd is not open"""
    try:
        return os.dup(fd)
    except OSError:
        return None


def _run_script(script: str, args) -> tuple[int, str]:
    """runpy a Python script as __main__ with sys.argv = [script, *args]; (exit code, its output)

    Its output, Python's and the C library's (file descriptors 1 and 2), is
    captured and returned; its standard input (sys.stdin and descriptor 0)
    is /dev/null meanwhile, as for the programs steps.run_tool starts, so
    that it never reads the terminal. Global state the script changes and we know of
    (sys.argv, numpy's print options: mrcal-calibrate-cameras sets
    linewidth=300) is put back.
    """
    saved_argv, saved_print = sys.argv, np.get_printoptions()
    sys.argv = [script, *args]
    code = 0
    sys.stdout.flush()
    sys.stderr.flush()
    saved_fds, saved_stdin = (os.dup(1), os.dup(2), _dup_or_none(0)), sys.stdin
    with tempfile.TemporaryFile(mode="w+") as tmp, open(os.devnull) as null:
        os.dup2(tmp.fileno(), 1)
        os.dup2(tmp.fileno(), 2)
        os.dup2(null.fileno(), 0)
        sys.stdin = null
        try:
            with contextlib.redirect_stdout(tmp), contextlib.redirect_stderr(tmp):
                runpy.run_path(script, run_name="__main__")
        except SystemExit as e:
            code = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
            if not isinstance(e.code, (int, type(None))):
                tmp.write(str(e.code))
        except Exception as e:  # the script raised: report it as a failed run
            code = 1
            tmp.write(f"{type(e).__name__}: {e}")
        finally:
            tmp.flush()
            os.dup2(saved_fds[0], 1)
            os.dup2(saved_fds[1], 2)
            if saved_fds[2] is None:
                os.close(0)
            else:
                os.dup2(saved_fds[2], 0)
                os.close(saved_fds[2])
            os.close(saved_fds[0])
            os.close(saved_fds[1])
            sys.argv, sys.stdin = saved_argv, saved_stdin
            np.set_printoptions(**saved_print)
        tmp.seek(0)
        return code, tmp.read()


def board_residuals(model: mrcal.cameramodel):
    """Unweighted reprojection errors of a calibration's own boards

    Returns (N, ny, nx) pixel distances between the observed corners and the
    solved model's projection of the (warped) board, NaN where a corner was
    missing or rejected as an outlier; each board through its own camera
    (several cameras solved jointly). mrcal's printed RMS is per axis, of
    weighted residuals, and counts missing points as zeros; this is the plain
    2-D error of the points the solve used.
    """
    oi = model.optimization_inputs()
    obs = oi["observations_board"]
    N, ny, nx = obs.shape[:3]
    obj = mrcal.ref_calibration_object(nx, ny, oi["calibration_object_spacing"],
                                       calobject_warp=oi.get("calobject_warp"))
    rt_ref_frame = oi["rt_ref_frame"][oi["indices_frame_camintrinsics_camextrinsics"][:, 0]]
    icam = oi["indices_frame_camintrinsics_camextrinsics"][:, 2]
    p = mrcal.transform_point_rt(rt_ref_frame[:, None, None, :], obj)
    if np.any(icam >= 0):
        p = np.where((icam >= 0)[:, None, None, None],
                     mrcal.transform_point_rt(oi["rt_cam_ref"][np.maximum(icam, 0)][:, None, None, :], p), p)
    intr = oi["intrinsics"][oi["indices_frame_camintrinsics_camextrinsics"][:, 1]]  # each board's camera
    q = mrcal.project(p, oi["lensmodel"], intr[:, None, None, :])
    e = np.linalg.norm(q - obs[..., :2], axis=-1)
    return np.where(obs[..., 2] > 0, e, np.nan)


def calibration_stats(model: mrcal.cameramodel) -> dict:
    """Numbers of a calibration: boards, points used, RMS and worst residual (2-D, unweighted)"""
    e = board_residuals(model)
    ok = np.isfinite(e)
    return {
        "lensmodel": model.intrinsics()[0],
        "boards": int(e.shape[0]),
        "points": int(ok.sum()),
        "rms_px": float(np.sqrt(np.mean(e[ok] ** 2))) if ok.any() else float("nan"),
        "mean_px": float(np.mean(e[ok])) if ok.any() else float("nan"),
        "max_px": float(np.max(e[ok])) if ok.any() else float("nan"),
        "focal_px": [float(v) for v in model.intrinsics()[1][:2]],
    }


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


def focal_seed(cs, check: bool = True) -> float:
    """The focal seed (pixels) of a corner set: the median of its boards' estimates

    With check, an InputError unless at least FOCAL_MIN_BOARDS boards give an
    estimate and they agree to FOCAL_MAX_SPREAD (median absolute deviation
    over the median): a seed the boards do not support makes mrcal start
    (and a splined model size its field of view) from a wrong focal length.
    """
    from rotstar_mrcal.calibrate.focal import focal_estimates

    est = focal_estimates(list(cs.corners), cs.layout.board_points()[..., :2], cs.imagersize)
    W = cs.imagersize[0]
    if not len(est):
        if check:
            raise InputError("no board constrains the focal length (give --focal)")
        return W / 2
    f = float(np.median(est))
    spread = float(np.median(np.abs(est - f)) / f)
    if check and (len(est) < FOCAL_MIN_BOARDS or spread > FOCAL_MAX_SPREAD or not 0.1 * W < f < 20 * W):
        raise InputError(f"the boards do not support a focal seed ({len(est)} estimates, median {f:.0f} px, "
                         f"spread {100 * spread:.0f}%; need >= {FOCAL_MIN_BOARDS} agreeing within "
                         f"{100 * FOCAL_MAX_SPREAD:.0f}%): give --focal, or record more poses")
    return f


def check_inputs(cs, lensmodel: str | None = None, force: bool = False) -> None:
    """InputError (one line) for a corner set that cannot give a model with this lens model

    Always: at least MIN_BOARDS boards, and every image that can be read of
    the corner set's imager size. Splined models (unless force): at least
    SPLINED_MIN_BOARDS boards covering SPLINED_MIN_COVERAGE of the imager
    (lensmodel None: not checked).
    """
    from rotstar_mrcal.calibrate.cornerset import resolve_image

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


def calibration_argv(cs, outdir: str, lensmodel: str, focal: float | None = None, vnl: str | None = None) -> list[str]:
    """The mrcal-calibrate-cameras command for a corner set (sources.CornerSet); vnl: mrcal's copy (mrcal_corners)"""
    focal = focal_seed(cs, check=False) if focal is None else focal
    return calibrate_argv(vnl or cs.vnl, cs.layout, cs.imagersize, focal, lensmodel, outdir,
                          image_glob(cs.files), weights=cs.weights)


def hint_command(layout, imagersize, focal: float, vnl_name: str, glob: str, weights: bool = False) -> str:
    """The command rotstar-detect prints: the lean model, the same builder as rotstar-calibrate's

    SYNOPSIS

        >>> from rotstar_mrcal.pattern.layout import make_layout
        >>> print(hint_command(make_layout(), (1280, 800), 640, "corners.vnl", "seq/*/rotstar_00.png"))
        mrcal-calibrate-cameras --corners-cache corners.vnl --lensmodel LENSMODEL_OPENCV8 --focal 640 --imagersize 1280 800 --object-spacing 0.0144318182 --object-width-n 14 --object-height-n 9 --valid-intrinsics-region-parameters 5 0.05 2 3 0 --outdir . 'seq/*/rotstar_00.png'
    """
    return command_line(calibrate_argv(vnl_name, layout, imagersize, focal, LEAN_LENSMODEL, ".", glob,
                                       weights=weights))


# ---------------------------------------------------------------------------
# what a calibration says about itself
# ---------------------------------------------------------------------------
REGIONS = ("top-left", "top", "top-right", "left", "centre", "right", "bottom-left", "bottom", "bottom-right")


def region_of(q, imagersize) -> np.ndarray:
    """Index into REGIONS (thirds of the imager) of pixels q (..., 2)"""
    W, H = imagersize
    q = np.asarray(q, float)
    ix = np.clip((q[..., 0] * 3 / W).astype(int), 0, 2)
    iy = np.clip((q[..., 1] * 3 / H).astype(int), 0, 2)
    return iy * 3 + ix


def _pose_of_path(p: str) -> str:
    return os.path.basename(os.path.dirname(str(p))) or str(p)


def model_stats(model: mrcal.cameramodel, cs=None) -> dict:
    """What a calibration reports about itself (JSON-able)

    boards and corners used, outliers (mrcal's rejections: corners the input
    had that the solve dropped; counted by imager region), the 2-D unweighted
    fit RMS and worst residual (pose, corner, pixel), mrcal's noise estimate
    sigma (per axis, of the weighted residuals), the 1-sigma projection
    uncertainty (worst direction, at infinity) at the imager centre and
    corners, and the valid-intrinsics region's share of the imager. cs (the
    corner set the model was calibrated from) tells input gaps from outliers.
    """
    from rotstar_mrcal.evaluate.uncertainty import projection_uncertainty

    oi = model.optimization_inputs()
    lens, intr = model.intrinsics()
    W, H = (int(v) for v in model.imagersize())
    obs = oi["observations_board"]
    e = board_residuals(model)
    ok = np.isfinite(e)
    ip = oi.get("imagepaths")
    paths = [_pose_of_path(p) for p in (ip if ip is not None else [])]
    if cs is not None and len(paths) == obs.shape[0]:
        byname = dict(zip(cs.names, cs.corners))
        given = np.stack([np.isfinite(byname[p]).all(axis=-1) if p in byname else np.ones(obs.shape[1:3], bool)
                          for p in paths])
    else:
        given = np.ones(obs.shape[:3], bool)
    outlier = given & (obs[..., 2] <= 0)
    where = np.bincount(region_of(obs[..., :2][outlier], (W, H)), minlength=9)
    lost, had = outlier.sum(axis=(1, 2)), given.sum(axis=(1, 2))
    mostly = {(paths[b] if len(paths) == obs.shape[0] else str(b)): [int(lost[b]), int(had[b])]
              for b in np.flatnonzero(lost > MOSTLY_OUTLIERS * had)} if cs is not None else {}
    stats = {
        "lensmodel": lens,
        "boards": int(obs.shape[0]),
        "corners": int(ok.sum()),
        "outliers": int(outlier.sum()),
        "outlier_fraction": float(outlier.sum() / max(1, given.sum())),
        "outliers_where": {r: int(c) for r, c in zip(REGIONS, where) if c},
        "boards_mostly_outliers": mostly,  # pose -> [corners rejected, corners given]
        "rms_px": float(np.sqrt(np.mean(e[ok] ** 2))) if ok.any() else float("nan"),
        "worst_px": float(np.max(e[ok])) if ok.any() else float("nan"),
        "board_rms_px": {(paths[b] if len(paths) == obs.shape[0] else str(b)): float(np.sqrt(np.mean(e[b][ok[b]] ** 2)))
                         for b in range(obs.shape[0]) if ok[b].any()},
        "sigma_px": float(np.std(mrcal.measurements_board(oi))),
        "focal_px": [float(v) for v in intr[:2]],
        "centre_px": [float(v) for v in intr[2:4]],
    }
    if ok.any():
        b, i, j = np.unravel_index(np.nanargmax(np.where(ok, e, -1)), e.shape)
        stats["worst_at"] = {"pose": paths[b] if len(paths) == obs.shape[0] else int(b), "corner": [int(j), int(i)],
                             "pixel": [round(float(v), 1) for v in obs[b, i, j, :2]]}
    q = np.array([[(W - 1) / 2, (H - 1) / 2], [0, 0], [W - 1, 0], [0, H - 1], [W - 1, H - 1]], float)
    try:
        u = projection_uncertainty(model, q)
        stats["uncertainty_px"] = {"centre": float(u[0]), "corners_max": float(np.max(u[1:])),
                                   "corners": [float(v) for v in u[1:]]}
    except Exception as ex:  # noqa: BLE001 mrcal raises plain Exceptions
        stats["uncertainty_px"] = {"error": str(ex).splitlines()[0] if str(ex) else type(ex).__name__}
    vir = model.valid_intrinsics_region()
    if vir is None:
        stats["valid_region_fraction"] = None
    else:
        import cv2

        stats["valid_region_fraction"] = (float(cv2.contourArea(np.asarray(vir, np.float32)) / (W * H))
                                          if len(vir) >= 3 else 0.0)
    return stats


def stats_line(s: dict) -> str:
    """One line of model_stats for people"""
    where = ", ".join(f"{k} {v}" for k, v in s["outliers_where"].items())
    u = s.get("uncertainty_px", {})
    unc = (f"uncertainty {u['centre']:.4f} px at the centre, up to {u['corners_max']:.4f} at the corners"
           if "centre" in u else f"uncertainty unknown ({u.get('error')})")
    vr = s.get("valid_region_fraction")
    at = s.get("worst_at", {})
    return (f"{s['lensmodel']}: {s['boards']} boards, {s['corners']} corners, {s['outliers']} outliers"
            + (f" ({where})" if where else "")
            + f"; fit RMS {s['rms_px']:.5f} px (2-D), worst {s['worst_px']:.4f} px"
            + (f" ({at.get('pose')} corner {at.get('corner')} at {at.get('pixel')})" if at else "")
            + f"; {unc}; valid-intrinsics region "
            + ("not computed" if vr is None else f"{100 * vr:.0f}% of the imager"))


def mostly_line(mostly: dict) -> str:
    """'pose022 (37 of 42)' for model_stats' boards_mostly_outliers

    >>> mostly_line({"pose022": [37, 42], "pose025": [30, 40]})
    'pose022 (37 of 42), pose025 (30 of 40)'
    """
    return ", ".join(f"{k} ({a} of {b})" for k, (a, b) in mostly.items())


def reseeded_argv(argv, seed_model: str, outdir: str) -> list[str]:
    """A calibrate_argv command seeded from a model (--seed, which excludes --focal), writing into outdir

    >>> reseeded_argv(["mrcal-calibrate-cameras", "--focal", "640", "--outdir", "a", "x"], "a/m.cameramodel", "b")
    ['mrcal-calibrate-cameras', '--seed', 'a/m.cameramodel', '--outdir', 'b', 'x']
    """
    argv = [str(a) for a in argv]
    out = []
    i = 0
    while i < len(argv):
        if argv[i] == "--focal":
            out += ["--seed", seed_model]
            i += 2
        elif argv[i] == "--outdir":
            out += ["--outdir", outdir]
            i += 2
        else:
            out.append(argv[i])
            i += 1
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


@dataclasses.dataclass
class Candidate:
    """One model fitted by mrcal-calibrate-cameras"""

    name: str  # 'lean' or 'splined'
    lensmodel: str
    command: str
    path: str  # the model file mrcal wrote (under outdir/candidates/)
    stats: dict | None = None
    error: str | None = None  # mrcal failed
    note: str = ""  # e.g. why it was solved again, seeded from its first solve

    def to_json(self) -> dict:
        return dataclasses.asdict(self)


@dataclasses.dataclass
class Calibration:
    """The result of calibrate(): the model written (or not) and why; owns its JSON form"""

    model_path: str | None  # outdir/camera-0.cameramodel when written
    chosen: str | None  # name of the candidate written or proposed
    reason: str  # why that one
    failures: list[str]  # checks that failed (empty: ok)
    kept: bool  # written despite failures (keep=True)
    candidates: list[Candidate]
    comparison: dict | None  # cross_validate(lean, splined).summary()
    focal_seed: float
    corners: str  # the corners.vnl
    dropped: dict = dataclasses.field(default_factory=dict)  # pose -> why its board was left out


    FORMAT = "rotstar-calibrate/1"

    @property
    def ok(self) -> bool:
        return not self.failures

    @property
    def stats(self) -> dict | None:
        c = self.candidate(self.chosen)
        return c.stats if c else None

    def candidate(self, name):
        return next((c for c in self.candidates if c.name == name), None)

    def to_json(self) -> dict:
        return {"format": self.FORMAT, "ok": self.ok, "model": self.model_path, "chosen": self.chosen,
                "reason": self.reason, "failures": self.failures, "kept": self.kept,
                "focal_seed_px": self.focal_seed, "corners": self.corners, "comparison": self.comparison,
                "dropped": self.dropped,
                "candidates": [c.to_json() for c in self.candidates]}

    def summary_lines(self) -> list[str]:
        out = [f"dropped {k}: {v}" for k, v in self.dropped.items()]
        for c in self.candidates:
            mark = "written" if c.name == self.chosen and self.model_path else (
                "chosen" if c.name == self.chosen else "not written")
            out.append(f"{c.name} ({mark}): " + (stats_line(c.stats) if c.stats else f"failed: {c.error}")
                       + (f" [{c.note}]" if c.note else ""))
        if self.comparison:
            k = self.comparison
            out.append(f"lean vs splined: projection diff {k['diff_median_px']:.4f} px median (p95 "
                       f"{k['diff_p95_px']:.3f}), uncertainty uA+uB {k['unc_median_px']:.4f} px, ratio "
                       f"{k['ratio_median']:.2f} ({k['verdict']})")
        out.append(f"model: {self.reason}")
        return out


def _atomic_copy(src: str, dst: str) -> None:
    with atomic_path(dst) as tmp:
        shutil.copyfile(src, tmp)


def _reseed(c: Candidate, argv, cs, in_process: bool, log) -> None:
    """Solve c again seeded from its first solve (module doc: a board mrcal seeds badly); keep the better one"""
    mostly = c.stats["boards_mostly_outliers"]
    first = ("most corners of " + mostly_line(mostly)) if mostly else f"{c.stats['outliers']} corner(s) as outliers"
    seeded = os.path.join(os.path.dirname(os.path.dirname(c.path)), os.path.basename(os.path.dirname(c.path))
                          + "-seeded")
    argv2 = reseeded_argv(argv, c.path, seeded)
    log(f"mrcal rejected {first}: solving again seeded from that model")
    log("$ " + command_line(argv2))
    stale = os.path.join(seeded, "camera-0.cameramodel")
    if os.path.exists(stale):
        os.remove(stale)
    try:
        model = run_calibration(argv2, in_process=in_process)
    except CalibrationError as e:
        c.note = f"mrcal rejected {first}; the seeded solve failed: {str(e).splitlines()[0]}"
        return
    s2 = model_stats(model, cs)
    if s2["outliers"] < c.stats["outliers"]:
        c.note = (f"solved again seeded from its first solve, in which mrcal rejected {first} "
                  f"({c.stats['outliers']} outliers then, {s2['outliers']} now)")
        c.path, c.command, c.stats = stale, command_line(argv2), s2
    else:
        c.note = f"mrcal rejected {first}, also when seeded from its first solve"


def calibrate(cs, outdir: str, spec: str = "auto", focal: float | None = None, knots_x: int = DEFAULT_KNOTS_X,
              keep: bool = False, force: bool = False, in_process: bool = False, log=None) -> Calibration:
    """Calibrate a corner set; write outdir/camera-0.cameramodel if its checks pass (or keep)

    spec: 'auto' (lean, then splined when supported; module doc), or one
    lens model (resolve_lensmodel). Raises InputError (before mrcal runs)
    for inputs that cannot give a model, CalibrationError when mrcal fails
    on the model that would be written. Every mrcal command goes to log (a
    function of one line) before it runs. The candidates' models stay in
    outdir/candidates/<name>/; outdir/camera-0.cameramodel is removed first
    and written (atomically) only for a result. Boards out of grid order
    (misordered_boards) are dropped before mrcal runs, a board that explains
    an implausible fit (fit_failures) after it; each is named in log and in
    Calibration.dropped. A fit that stays implausible is not written, even
    with keep.
    """
    log = log or (lambda s: None)
    final = os.path.join(outdir, "camera-0.cameramodel")
    for stale in [final] + [os.path.join(outdir, "candidates", n, "camera-0.cameramodel")
                                            for n in ("lean", "splined", "model", "lean-seeded", "splined-seeded",
                                                      "model-seeded")]:
        if os.path.exists(stale):
            os.remove(stale)
    dropped = {}
    bad = misordered_boards(cs.corners, cs.files, cs.layout)
    if bad and 2 * len(bad) > len(cs.files):
        f0, why = next(iter(bad.items()))
        raise InputError(f"{cs.vnl}: {len(bad)} of its {len(cs.files)} boards are not the pattern's grid, e.g. "
                         f"{f0}: {why}")
    if bad:
        cs = _drop(cs, bad, dropped, log)
    check_inputs(cs)  # the boards and the image sizes first: they decide whether anything can be done
    f = focal_seed(cs, check=not force) if focal is None else float(focal)
    lensmodel = resolve_lensmodel(spec, cs.imagersize, f, knots_x)
    check_inputs(cs, lensmodel, force)
    plan = [("lean" if spec.strip().lower() in ("auto", "lean") else "model", lensmodel)]
    why = None
    if spec.strip().lower() == "auto":
        ok, why = splined_supported(cs, knots_x)
        if ok:
            plan.append(("splined", recommended_lensmodel(cs.imagersize, f, knots_x)))
            log(f"splined model supported ({why}): fitting it after the lean one")
        else:
            log(f"lean model only: {why}")
    vnl = mrcal_corners(cs.vnl, os.path.join(outdir, "candidates"), drop=set(dropped))
    if vnl != cs.vnl and not dropped:
        log(f"{cs.vnl} is not plain ASCII text with LF line ends: mrcal reads the text we read, copied to {vnl}")
    while True:
        chosen, reason, failures, cands, comparison = _fit(cs, outdir, plan, f, vnl, why, in_process, log)
        f_boards = focal_seed(cs, check=False)  # what the boards say, whatever --focal was
        implausible = fit_failures(chosen.stats, f_boards)
        if not implausible:
            break
        culprits = _culprits(cs, chosen, f_boards, outdir, dropped, log)
        if not culprits or len(cs.files) - len(culprits) < MIN_BOARDS:
            failures = implausible + failures
            break
        cs = _drop(cs, culprits, dropped, log)
        vnl = mrcal_corners(cs.vnl, os.path.join(outdir, "candidates"), drop=set(dropped))
    written = None
    if not failures or (keep and not implausible):
        os.makedirs(outdir, exist_ok=True)
        _atomic_copy(chosen.path, final)
        written = final
    return Calibration(written, chosen.name, reason, failures, bool(failures) and bool(written), cands, comparison,
                       f, cs.vnl, {_pose_of_path(k): v for k, v in dropped.items()})


def _drop(cs, bad: dict, dropped: dict, log):
    """cs without the boards (files) in bad; each named in log and added to dropped (file -> why)"""
    for fn, why in bad.items():
        log(f"dropping {fn}: {why}")
        dropped[fn] = why
    keep = [i for i, fn in enumerate(cs.files) if fn not in bad]
    return dataclasses.replace(cs, files=[cs.files[i] for i in keep], corners=cs.corners[keep])


def _fit(cs, outdir, plan, f, vnl, why, in_process, log):
    """The candidates of plan fitted and the one to write chosen: (chosen, reason, failures, cands, comparison)"""
    from rotstar_mrcal.evaluate.crossval import cross_validate

    cands = []
    for name, lm in plan:
        argv = calibration_argv(cs, os.path.join(outdir, "candidates", name), lm, f, vnl)
        c = Candidate(name, lm, command_line(argv), os.path.join(outdir, "candidates", name, "camera-0.cameramodel"))
        log("$ " + c.command)
        try:
            if os.path.exists(c.path):
                os.remove(c.path)
            model = run_calibration(argv, in_process=in_process)
            c.stats = model_stats(model, cs)
            if c.stats["outliers"]:
                _reseed(c, argv, cs, in_process, log)
        except CalibrationError as e:
            if not cands:
                raise
            c.error = str(e).splitlines()[0]
        cands.append(c)
    chosen, comparison = cands[0], None
    if plan[0][0] != "lean":
        reason = f"{chosen.lensmodel} (as asked)"
    elif len(cands) == 1:
        reason = f"{chosen.lensmodel} (the lean model" + (f"; {why}" if why else "") + ")"
    else:
        reason = f"{chosen.lensmodel} (the lean model; the splined fit failed: {cands[1].error})"
    failures = list(model_failures(chosen.stats))
    if len(cands) == 2 and cands[1].stats:
        lean, spl = cands
        ml, ms = mrcal.cameramodel(lean.path), mrcal.cameramodel(spl.path)
        comparison = cross_validate(ml, ms).summary()
        ratio, better = comparison["ratio_median"], spl.stats["rms_px"] < SPLINED_BETTER_RMS * lean.stats["rms_px"]
        spl_fail = model_failures(spl.stats)
        if better and ratio > 2 and not spl_fail:
            chosen, failures = spl, []
            reason = (f"{spl.lensmodel}: it fits the corners better than {lean.lensmodel} (RMS "
                      f"{spl.stats['rms_px']:.5f} vs {lean.stats['rms_px']:.5f} px) and the two differ by "
                      f"{comparison['diff_median_px']:.4f} px, {ratio:.1f}x their uncertainty: the lean model "
                      "does not fit this lens")
        elif better and ratio > 2:
            failures = [f"{lean.lensmodel} does not fit (the splined model fits better and differs by "
                        f"{comparison['diff_median_px']:.4f} px, {ratio:.1f}x the uncertainty) and the splined "
                        "model fails its checks: " + "; ".join(spl_fail)]
        elif ratio > 2 and spl.stats["rms_px"] <= lean.stats["rms_px"]:
            failures.append(f"the lean and splined models disagree by {comparison['diff_median_px']:.4f} px "
                            f"({ratio:.1f}x their uncertainty) and fit equally well: the boards cannot tell "
                            "which is right")
        elif ratio <= 2:
            reason = (f"{lean.lensmodel}: the splined model agrees with it within {ratio:.1f}x their uncertainty "
                      f"(RMS {spl.stats['rms_px']:.5f} vs {lean.stats['rms_px']:.5f} px): the lean model is enough")
        else:
            reason = (f"{lean.lensmodel}: the splined model fits the corners worse (RMS "
                      f"{spl.stats['rms_px']:.5f} vs {lean.stats['rms_px']:.5f} px); its "
                      f"{comparison['diff_median_px']:.4f} px difference is freedom the boards do not constrain")
    return chosen, reason, failures, cands, comparison


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


def _culprits(cs, chosen, f, outdir, dropped, log) -> dict:
    """{file: why} of the boards that explain an implausible fit, or {} when none does

    Boards far off the rest (far_boards) when the fit is otherwise
    plausible; else the first board whose leaving out gives a plausible lean
    fit, searched by solving without each, the worst-fitting first (up to
    MAX_DROP_SEARCH boards).
    """
    s = chosen.stats
    byname = dict(zip(cs.names, cs.files))
    far = far_boards(s["board_rms_px"])
    if far and len(fit_failures(s, f)) == 1:
        med = float(np.median(list(s["board_rms_px"].values())))
        return {byname[k]: f"its fit RMS {v:.3g} px is {v / med:.0f}x the median board's ({med:.3g} px)"
                for k, v in far.items() if k in byname}
    if len(cs.files) > MAX_DROP_SEARCH:
        return {}
    log(f"the fit is implausible ({'; '.join(fit_failures(s, f))}): solving without each board in turn")
    best = None
    rms = s["board_rms_px"]
    for fn in sorted(cs.files, key=lambda fn: -rms.get(_pose_of_path(fn), 0.0)):  # the worst boards first
        folder = os.path.join(outdir, "candidates", "without")
        sub = dataclasses.replace(cs, files=[x for x in cs.files if x != fn],
                                  corners=cs.corners[[x != fn for x in cs.files]])
        argv = calibration_argv(sub, folder, LEAN_LENSMODEL, f,
                                mrcal_corners(cs.vnl, folder, drop={fn} | set(dropped)))
        with contextlib.suppress(FileNotFoundError):
            os.remove(os.path.join(folder, "camera-0.cameramodel"))
        try:
            st = model_stats(run_calibration(argv, in_process=True), sub)
        except CalibrationError:
            continue
        if not fit_failures(st, f):
            best = (fn, st["rms_px"])
            break
    if best is None:
        return {}
    why = fit_failures(s, f)
    return {best[0]: (f"the fit without it is plausible (RMS {best[1]:.3g} px), with it not: {why[0]}"
                      + (f" (and {len(why) - 1} more)" if len(why) > 1 else ""))}

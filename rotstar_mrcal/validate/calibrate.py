"""The mrcal-calibrate-cameras command for a corners.vnl, and running it

SYNOPSIS

    >>> from rotstar_mrcal.pattern.layout import make_layout
    >>> from rotstar_mrcal.validate.calibrate import recommended_lensmodel, calibrate_argv, image_glob
    >>> recommended_lensmodel((1280, 800), focal=640)
    'LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx=16_Ny=10_fov_x_deg=117'
    >>> image_glob(["seq/pose000/rotstar_00.png", "seq/pose010/rotstar_00.png"])
    '*/rotstar_00.png'
    >>> argv = calibrate_argv("corners.vnl", make_layout(), (1280, 800), 640,
    ...                       "LENSMODEL_OPENCV8", "cal", "*/rotstar_00.png")
    >>> print(command_line(argv))
    mrcal-calibrate-cameras --corners-cache corners.vnl --lensmodel LENSMODEL_OPENCV8 --focal 640 --imagersize 1280 800 --object-spacing 0.0144318182 --object-width-n 14 --object-height-n 9 --outdir cal '*/rotstar_00.png'

The lens model: mrcal's recommendation (doc/how-to-calibrate.org, "Model
choice") is LENSMODEL_SPLINED_STEREOGRAPHIC of order 3 with dense knots whose
Ny/Nx matches the imager's aspect ratio and a field of view that covers the
imager. The field of view comes from the focal seed: a stereographic lens of
focal length f sees the half-width W/2 at 2 atan(W / 4f), so fov_x = 4 atan(W /
4f); 10% is added so that the imager's edges are inside the spline. A splined
model fits anything, and needs boards over the whole imager to do it: with a
few poses (the demo's pose groups, or any dance of fewer than ~40 boards) use
LENSMODEL_OPENCV8 (measured in doc/validation.md).

mrcal-calibrate-cameras matches the file names of the corners.vnl against the
image globs (fnmatch, '*' also matches '/'); one glob per camera. The images
need not exist: the imager size is given. With a weight column (header
`# filename x y weight`, rotstar-detect --weights) the command gets
--corners-cache-has-weights.
"""

from __future__ import annotations

import contextlib
import math
import os
import runpy
import shlex
import shutil
import subprocess
import sys
import tempfile

import mrcal
import numpy as np

SPLINED_MIN_BOARDS = 40
"""Below this many boards a splined model is poorly constrained (doc/validation.md)"""

DEFAULT_KNOTS_X = 16

MIN_BOARDS = 3
"""Fewer boards than this are not calibrated by rotstar-crossval (mrcal would, and badly)"""


class CalibrationError(RuntimeError):
    """mrcal-calibrate-cameras failed; the message ends with its last output lines"""


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
    with open(path, encoding="ascii", errors="replace") as f:
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
        r = subprocess.run([exe] + argv[1:], capture_output=True, text=True)
        code, text = r.returncode, r.stdout + r.stderr
    if code != 0:
        tail = "\n".join(text.strip().splitlines()[-6:])
        raise CalibrationError(f"mrcal-calibrate-cameras exited with {code}:\n{tail}")
    fn = os.path.join(outdir, "camera-0.cameramodel")
    if not os.path.exists(fn):
        raise CalibrationError(f"mrcal-calibrate-cameras wrote no {fn}")
    return mrcal.cameramodel(fn)


def _run_script(script: str, args) -> tuple[int, str]:
    """runpy a Python script as __main__ with sys.argv = [script, *args]; (exit code, its output)

    Its output, Python's and the C library's (file descriptors 1 and 2), is
    captured and returned. Global state the script changes and we know of
    (sys.argv, numpy's print options: mrcal-calibrate-cameras sets
    linewidth=300) is put back.
    """
    saved_argv, saved_print = sys.argv, np.get_printoptions()
    sys.argv = [script, *args]
    code = 0
    sys.stdout.flush()
    sys.stderr.flush()
    saved_fds = os.dup(1), os.dup(2)
    with tempfile.TemporaryFile(mode="w+") as tmp:
        os.dup2(tmp.fileno(), 1)
        os.dup2(tmp.fileno(), 2)
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
            os.close(saved_fds[0])
            os.close(saved_fds[1])
            sys.argv = saved_argv
            np.set_printoptions(**saved_print)
        tmp.seek(0)
        return code, tmp.read()


def board_residuals(model: mrcal.cameramodel):
    """Unweighted reprojection errors of a calibration's own boards

    Returns (N, ny, nx) pixel distances between the observed corners and the
    solved model's projection of the (warped) board, NaN where a corner was
    missing or rejected as an outlier. mrcal's printed RMS is per axis, of
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
    q = mrcal.project(p, oi["lensmodel"], oi["intrinsics"][0])
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

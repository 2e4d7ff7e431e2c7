"""The mrcal-calibrate-cameras command: its argv for a corners.vnl, the lens model asked for, the hint

SYNOPSIS

    >>> from rotstar_mrcal.pattern.layout import make_layout
    >>> from rotstar_mrcal.calibrate.command import recommended_lensmodel, calibrate_argv, image_glob
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

The command rotstar-detect prints (hint_command) and the ones
rotstar-calibrate runs (calibrate_argv; calibrate.solve for a corner set)
come from the same builder. The lens model by name: resolve_lensmodel
('auto' and 'lean' are the lean LEAN_LENSMODEL, 'splined' mrcal's
recommended splined model, recommended_lensmodel; calibrate.solve's module
doc says when rotstar-calibrate's 'auto' adds the splined one). A rig's
command (rig_argv, rig_globs: one glob per camera) is described in
calibrate.rig's module doc.

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

import math
import os
import shlex

from rotstar_mrcal import dataset
from rotstar_mrcal.atomic import atomic_path
from rotstar_mrcal.vnl import corners_text

LEAN_LENSMODEL = "LENSMODEL_OPENCV8"
"""The lean model: rotstar-detect's printed command, rotstar-crossval, the first fit of rotstar-calibrate"""

DEFAULT_KNOTS_X = 16

VALID_REGION_PARAMETERS = (5, 0.05, 2, 3, 0)
"""mrcal-calibrate-cameras --valid-intrinsics-region-parameters for sub-0.05 px corners (module doc)"""


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


def resolve_image(name: str, vnl: str) -> str:
    """An image name from a vnl as mrcal resolves it (as written, else next to the vnl)"""
    if os.path.isabs(name) or os.path.exists(name):
        return name
    return os.path.join(os.path.dirname(os.path.abspath(vnl)), name)


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


def hint_command(layout, imagersize, focal: float, vnl_name: str, glob: str, weights: bool = False) -> str:
    """The command rotstar-detect prints: the lean model, the same builder as rotstar-calibrate's

    SYNOPSIS

        >>> from rotstar_mrcal.pattern.layout import make_layout
        >>> print(hint_command(make_layout(), (1280, 800), 640, "corners.vnl", "seq/*/rotstar_00.png"))
        mrcal-calibrate-cameras --corners-cache corners.vnl --lensmodel LENSMODEL_OPENCV8 --focal 640 --imagersize 1280 800 --object-spacing 0.0144318182 --object-width-n 14 --object-height-n 9 --valid-intrinsics-region-parameters 5 0.05 2 3 0 --outdir . 'seq/*/rotstar_00.png'
    """
    return command_line(calibrate_argv(vnl_name, layout, imagersize, focal, LEAN_LENSMODEL, ".", glob,
                                       weights=weights))


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


def rig_globs(seq: str, cameras, first_frame: str) -> list[str]:
    """One glob per camera, camera 0 first: seq/*/camera-K/<first frame>

    >>> rig_globs("seq", [0, 1], "rotstar_00.png")
    ['seq/*/camera-0/rotstar_00.png', 'seq/*/camera-1/rotstar_00.png']
    """
    return [os.path.join(seq, "*", dataset.camera_folder(k), first_frame) for k in cameras]


def rig_argv(vnl: str, layout, imagersizes: dict, focals: dict, lensmodel: str, outdir: str, globs,
             weights: bool = False, extra=()) -> list[str]:
    """The mrcal-calibrate-cameras command of a rig (a list, program first); see calibrate.rig's module doc"""
    cams = sorted(imagersizes)
    sizes = {tuple(int(v) for v in imagersizes[k]) for k in cams}
    argv = ["mrcal-calibrate-cameras"] + (["--corners-cache-has-weights"] if weights else [])
    argv += ["--corners-cache", vnl, "--lensmodel", lensmodel,
             "--focal", ",".join(f"{focals[k]:.0f}" for k in cams)]
    if len(sizes) == 1:
        W, H = sizes.pop()
        argv += ["--imagersize", str(W), str(H)]
    argv += [*layout.mrcal_object_args(),
             "--valid-intrinsics-region-parameters", *(f"{v:g}" for v in VALID_REGION_PARAMETERS),
             "--outdir", outdir, *extra, *globs]
    return argv

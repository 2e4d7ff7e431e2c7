"""mrcal's own visualisations (mrcal-show-*) of a calibration, with scales that suit sub-0.05 px corners

SYNOPSIS

    from rotstar_mrcal.report.mrcalshow import show_commands, draw
    figs = show_commands("cal/camera-0.cameramodel", "figs", other="B/camera-0.cameramodel")
    for f in figs:
        print(f.command)          # what to run to redraw it (by hand: without --hardcopy for a window)
    draw(figs)                    # runs them; every f.png written (non-empty) or a RuntimeError

Each figure is one mrcal-show-* program run with --hardcopy on a model that
mrcal-calibrate-cameras wrote (it holds its optimization_inputs):

    uncertainty        mrcal-show-projection-uncertainty --observations: the
                       1-sigma projection uncertainty at infinity, with the corners
    residuals-worst    mrcal-show-residuals-board-observation --from-worst 0:
                       the worst board over its image, residual vectors scaled
    residuals-directions  mrcal-show-residuals --directions: the residuals'
                       directions over the imager (colour = angle)
    residuals-histogram   mrcal-show-residuals --histogram
    distortion         mrcal-show-distortion-off-pinhole: the lens's distortion
    valid-region       mrcal-show-valid-intrinsics-region --points: the region
                       and the corners the calibration used (fed on its
                       standard input from <prefix>valid-region-points.txt)
    diff               (with other) mrcal-show-projection-diff of two
                       calibrations, e.g. the two halves of rotstar-crossval SEQ
    splined-correction (splined models only) mrcal-show-splined-model-correction

mrcal's default colour scales (0-3 px for the uncertainty, 0-4 px for the
diff) are made for ~0.3 px corners: ours (0.005-0.05 px) come out uniformly
black. scales() derives them from the model: the uncertainty's --cbmax 3x
its median over the imager (rounded up to 1, 2, 5 x 10^k; the corners the
boards did not reach saturate), the
residual vectors' --vectorscale so that the RMS residual draws as ~20
pixels, the histogram's --binwidth a tenth of the RMS, the diff's --cbmax 5x
the sum of the two models' uncertainty at the centre.

gnuplot: the residuals-on-image plot needs a gnuplot that reads PNG; the one
mrcal's wheel installs in the venv's bin does not ("This copy of gnuplot
cannot read png/gif/jpeg images"), Debian's (gnuplot-nox, +GD_PNG) does.
gnuplot_env() returns an environment whose PATH finds such a gnuplot first
(a folder with a link to it), for draw() and for people: `make setup` makes
.tools/gnuplot/gnuplot, and README.md's PATH puts it first.
"""

from __future__ import annotations

import dataclasses
import os
import shlex
import shutil
import subprocess
import sys
import tempfile

import mrcal
import numpy as np

from rotstar_mrcal.programs import run_tool
from rotstar_mrcal.report.plots import nice_max
from rotstar_mrcal.evaluate.uncertainty import projection_uncertainty
from rotstar_mrcal.calibrate.solve import board_residuals, model_stats, stats_line

TERMINAL = 'pngcairo size 1024,640 noenhanced font ",11" background "white"'
"""An opaque white background: mrcal's default PNG terminal (--hardcopy alone) is transparent"""


@dataclasses.dataclass
class Figure:
    name: str
    argv: list[str]
    png: str
    caption: str
    cwd: str | None = None  # where the model's image paths resolve (residuals on the image)
    log: str = ""  # what the program said (draw)
    stdin: str | None = None  # a file the program reads on its standard input (else /dev/null)

    @property
    def command(self) -> str:
        return with_stdin(shlex.join(self.argv), self.stdin)


def missing_image(model: mrcal.cameramodel, image_root: str | None = None) -> str | None:
    """The first board image of a calibration that is not on disk (paths relative to image_root, default the
    working directory), None if all are: mrcal-show-residuals-board-observation draws a board over its image
    only when it can read it"""
    paths = model.optimization_inputs().get("imagepaths")
    for p in [] if paths is None else paths:
        if not os.path.isfile(os.path.join(image_root or os.getcwd(), str(p))):
            return str(p)
    return None


def with_stdin(command: str, stdin: str | None) -> str:
    """A shell command line reading the file stdin, if any

    SYNOPSIS

        >>> with_stdin("mrcal-show-valid-intrinsics-region --points m.cameramodel", "my points.txt")
        "mrcal-show-valid-intrinsics-region --points m.cameramodel < 'my points.txt'"
    """
    return command + (f" < {shlex.quote(stdin)}" if stdin else "")


def write_corners_xy(model: mrcal.cameramodel, path: str) -> str:
    """The corners the calibration used (pixel x y, one a line, outliers left out) into path; path"""
    obs = model.optimization_inputs()["observations_board"]
    xy = obs[..., :2][obs[..., 2] > 0]
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    np.savetxt(path, xy, fmt="%.3f")
    return path


def reads_png(gnuplot: str) -> bool:
    """Can this gnuplot read PNG images (built with libgd)?"""
    try:
        r = run_tool([gnuplot, "-e", "show version long"], capture_output=True, text=True, timeout=20)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return "+GD_PNG" in (r.stdout + r.stderr)


def png_gnuplot() -> str | None:
    """The first gnuplot that reads PNG: on PATH, then /usr/bin/gnuplot"""
    seen = []
    for d in os.environ.get("PATH", "").split(os.pathsep) + ["/usr/bin"]:
        g = os.path.join(d, "gnuplot")
        if os.path.exists(g) and os.path.realpath(g) not in seen:
            seen.append(os.path.realpath(g))
            if reads_png(g):
                return g
    return None


def gnuplot_env(env=None) -> dict:
    """os.environ (or env) with a gnuplot that reads PNG first on PATH and the venv's bin after it"""
    env = dict(os.environ if env is None else env)
    venv_bin = os.path.dirname(sys.executable)
    path = env.get("PATH", "")
    if venv_bin not in path.split(os.pathsep):
        path = venv_bin + os.pathsep + path
    g = png_gnuplot()
    if g is not None and not reads_png(shutil.which("gnuplot", path=path) or "gnuplot"):
        d = os.path.join(tempfile.gettempdir(), f"rotstar-gnuplot-{os.getuid()}")
        os.makedirs(d, exist_ok=True)
        link = os.path.join(d, "gnuplot")
        if os.path.realpath(link) != os.path.realpath(g):
            if os.path.lexists(link):
                os.remove(link)
            os.symlink(os.path.realpath(g), link)
        path = d + os.pathsep + path
    env["PATH"] = path
    return env


def scales(model: mrcal.cameramodel, other: mrcal.cameramodel | None = None) -> dict:
    """Colour scales and vector scales for our small errors (module doc)"""
    W, H = (int(v) for v in model.imagersize())
    q = np.array([[(W - 1) / 2, (H - 1) / 2], [0, 0], [W - 1, 0], [0, H - 1], [W - 1, H - 1]], float)
    u = projection_uncertainty(model, q)
    grid = projection_uncertainty(model, mrcal.sample_imager(16, 10, W, H))
    e = board_residuals(model)
    rms = float(np.sqrt(np.nanmean(e**2)))
    out = {"uncertainty_cbmax": nice_max(3 * float(np.median(grid))),
           "vectorscale": float(nice_max(20.0 / max(rms, 1e-6)) / 2),
           "binwidth": float(f"{rms / 10:.1g}"),
           "residual_cbmax": nice_max(3 * rms)}
    if other is not None:
        u1 = projection_uncertainty(other, q[:1])
        out["diff_cbmax"] = nice_max(5 * float(u[0] + u1[0]))
    return out


def show_commands(model_path: str, outdir: str, other: str | None = None, image_root: str | None = None,
                  terminal: str = TERMINAL, prefix: str = "") -> list[Figure]:
    """The mrcal-show-* commands (module doc) writing outdir/<prefix><name>.png

    image_root: the folder the model's image paths are relative to (where
    the calibration ran), for the residuals drawn over the board's image.
    """
    model = mrcal.cameramodel(model_path)
    m1 = mrcal.cameramodel(other) if other else None
    missing = missing_image(model, image_root)
    s = scales(model, m1)
    lens = model.intrinsics()[0]
    png = lambda name: os.path.join(outdir, f"{prefix}{name}.png")  # noqa: E731
    common = lambda name: ["--terminal", terminal, "--hardcopy", png(name)]  # noqa: E731
    figs = [
        Figure("uncertainty", ["mrcal-show-projection-uncertainty", "--observations", "--cbmax",
                               f"{s['uncertainty_cbmax']:g}", "--unset", "key", *common("uncertainty"), model_path],
               png("uncertainty"), "projection uncertainty (1-sigma, worst direction, at infinity) and the "
               "corners the calibration saw"),
        Figure("residuals-worst", ["mrcal-show-residuals-board-observation", "--from-worst", "--vectorscale",
                                   f"{s['vectorscale']:g}", "--cbmax", f"{s['residual_cbmax']:g}",
                                   *common("residuals-worst"), os.path.abspath(model_path), "0"],
               png("residuals-worst"), ("the worst board's residuals over its image" if missing is None else
                                        f"the worst board's residuals (without its image: {missing} is not on "
                                        "disk)") + f" (vectors scaled {s['vectorscale']:g}x, colour: residual in px)",
               cwd=image_root),
        Figure("residuals-directions", ["mrcal-show-residuals", "--directions", "--unset", "key",
                                        *common("residuals-directions"), model_path],
               png("residuals-directions"), "directions of the residuals over the imager (colour: angle): "
               "patterns mean the model or the corners are biased"),
        Figure("residuals-histogram", ["mrcal-show-residuals", "--histogram", "--binwidth", f"{s['binwidth']:g}",
                                       *common("residuals-histogram"), model_path],
               png("residuals-histogram"), "histogram of the residuals (x and y) against mrcal's Gaussian"),
        Figure("distortion", ["mrcal-show-distortion-off-pinhole", "--unset", "key", *common("distortion"),
                              model_path],
               png("distortion"), "the lens's distortion: projection off a pinhole model, px"),
        Figure("valid-region", ["mrcal-show-valid-intrinsics-region", "--points", *common("valid-region"),
                                model_path],
               png("valid-region"), "the valid-intrinsics region (rotstar-calibrate's parameters) and the corners "
               "the calibration used",
               stdin=write_corners_xy(model, os.path.join(outdir, f"{prefix}valid-region-points.txt"))),
    ]
    if other:
        figs.append(Figure("diff", ["mrcal-show-projection-diff", "--cbmax", f"{s['diff_cbmax']:g}", "--unset", "key",
                                    *common("diff"), model_path, other],
                           png("diff"), "projection difference of two calibrations (mrcal's cross-validation)"))
    if lens.startswith("LENSMODEL_SPLINED"):
        figs.append(Figure("splined-correction", ["mrcal-show-splined-model-correction", "--unset", "key",
                                                  *common("splined-correction"), model_path],
                           png("splined-correction"), "the splined model's correction over its stereographic core"))
    return figs


def draw(figs, env=None, timeout: float = 120) -> list[Figure]:
    """Run the commands; RuntimeError (with mrcal's last line) when one writes no PNG"""
    env = gnuplot_env(env)
    for f in figs:
        os.makedirs(os.path.dirname(os.path.abspath(f.png)), exist_ok=True)
        argv = [os.path.abspath(a) if f.cwd is not None and a == f.png else a for a in f.argv]
        if f.stdin is None:
            r = run_tool(argv, env=env, cwd=f.cwd, capture_output=True, text=True, timeout=timeout)
        else:
            with open(f.stdin) as points:
                r = run_tool(argv, env=env, cwd=f.cwd, stdin=points, capture_output=True, text=True, timeout=timeout)
        f.log = r.stdout + r.stderr
        if r.returncode != 0 or not os.path.exists(f.png) or os.path.getsize(f.png) == 0:
            tail = (r.stderr.strip() or r.stdout.strip() or "no output").splitlines()[-1]
            raise RuntimeError(f"{f.command}: {tail}")
    return figs


def redraw_command(f: Figure) -> str:
    """The command without --hardcopy/--terminal: mrcal draws it in a window (`< file` if it reads one)"""
    argv, skip = [], 0
    for a in f.argv:
        if skip:
            skip -= 1
        elif a in ("--hardcopy", "--terminal"):
            skip = 1
        else:
            argv.append(a)
    return with_stdin(shlex.join(argv), f.stdin)


def calibration_figures(model_path: str, outdir: str, other: str | None = None, image_root: str | None = None,
                        prefix: str = "") -> tuple[list[tuple[str, str, str]], dict]:
    """Draw a calibration's mrcal-show-* figures; ([(caption, png, redraw command)], model_stats)

    The first caption carries the numbers (calibrate.stats_line): outliers,
    fit RMS, worst residual, uncertainty, valid region.
    """
    stats = model_stats(mrcal.cameramodel(model_path))
    figs = draw(show_commands(model_path, outdir, other=other, image_root=image_root, prefix=prefix))
    out = [(f.caption + (f" ({stats_line(stats)})" if i == 0 else ""), f.png, redraw_command(f))
           for i, f in enumerate(figs)]
    return out, stats

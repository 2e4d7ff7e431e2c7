"""rotstar-synth: the paper's synthetic experiment (4.1) with wavefront PSFs and the Cramer-Rao bound

SYNOPSIS

    rotstar-synth experiment --quick --out synth-quick/          # < 1 minute
    rotstar-synth experiment --out doc/synth-results/ --jobs 2   # the full protocol
    rotstar-synth experiment --scheduler tcp://host:8786 --repeats 200 --aberrations none defocus spherical coma astigmatism
    rotstar-synth psf --aberrations spherical coma               # PSF statistics
    rotstar-synth bound --sigmas 0.5 1 2 3                       # CRLB per pattern vs Gaussian blur

`experiment` writes into --out: table.md and table.json (every
configuration, pattern and refiner, and the means over the tilts),
summary.md (the means, the three findings' verdicts computed from them, our
observation on phase shifting, the pattern x refiner grid, the wall time), range_noise<N>.png (pairwise-distance range against the tilt,
one per noise level), psf.png, views.png, protocol.json, and cache/ (one
file per configuration: rerunning resumes). Progress goes to stderr; stdout
gets only the output folder.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

from rotstar_mrcal.optics.crlb import closed_form_corner_bound
from rotstar_mrcal.optics.psf import Optics, asymmetry, centroid_px, gaussian_psf, second_moment_px
from rotstar_mrcal.synth import table, verdicts
from rotstar_mrcal.synth.bound import pattern_bounds
from rotstar_mrcal.synth.experiment import ABERRATIONS, Protocol, psf_kernel, quick_protocol
from rotstar_mrcal.synth.patterns import PATTERNS
from rotstar_mrcal.synth.refiners import REFINERS, applies
from rotstar_mrcal.synth.sweep import pending_tasks, run_sweep
from rotstar_mrcal.cli.common import (
    HelpFormatter, exit_status_help, atomic_path, atomic_write, check_output_path, fail, number_arg, run,
    say,
)


def _floats(xs):
    return tuple(float(x) for x in xs)


def _amplitudes(items):
    out = []
    for it in items or ():
        name, _, val = it.partition("=")
        try:
            out.append((name, float(val)))
        except ValueError:
            fail(f"--amplitude wants NAME=WAVES, not {it!r}")
    return tuple(out)


def parse_args(argv=None) -> argparse.Namespace:
    d = Protocol()
    p = argparse.ArgumentParser(prog="rotstar-synth", description=__doc__.split("\n\n")[0].split(": ", 1)[1],
                                epilog=exit_status_help("done"), formatter_class=HelpFormatter)
    sub = p.add_subparsers(dest="command", required=True)
    _experiment_parser(sub, d)
    s = sub.add_parser("psf", help="statistics of each aberration's PSF",
                       formatter_class=HelpFormatter)
    _protocol_arguments(s, d, full=False)
    _bound_parser(sub)
    return p.parse_args(argv)


def _protocol_arguments(q, d: Protocol, full: bool = True) -> None:
    """The protocol's options (defaults: d); full: also the sweep's (noise, tilts, patterns, refiners, ...)"""
    q.add_argument("--aberrations", nargs="+", choices=tuple(ABERRATIONS), default=list(d.aberrations),
                   help="PSFs: none = Gaussian, the others Seidel wavefronts")
    q.add_argument("--amplitude", action="append", metavar="NAME=WAVES",
                   help="override an aberration's amplitude in waves (defaults: "
                   + ", ".join(f"{k} {v[1]:g}" for k, v in ABERRATIONS.items() if v[0]) + ")")
    q.add_argument("--gaussian-sigma", type=float, default=d.gaussian_sigma, help="sigma (px) of 'none'")
    q.add_argument("--coma-angle", type=float, default=d.coma_angle_deg,
                   help="direction of the comet's tail in the image, degrees from +x toward +y")
    q.add_argument("--fnumber", type=float, default=d.optics.fnumber)
    q.add_argument("--pixel-um", type=float, default=d.optics.pixel_um)
    q.add_argument("--wavelength-um", type=float, default=d.optics.wavelength_um)
    q.add_argument("--supersample", type=number_arg(int, 1, 64), default=d.supersample, help="s x s sub-pixels per pixel")
    q.add_argument("--window", type=number_arg(int, 2, 200), default=d.window,
                   help="half-window of every refiner and the bound")
    if not full:
        return
    q.add_argument("--noise", nargs="+", type=float, default=list(d.noises), metavar="SIGMA",
                   help="noise levels sigma_n in DN (contrast 200 DN)")
    q.add_argument("--phi", nargs="+", type=float, default=list(d.phis_deg), help="tilts, degrees")
    q.add_argument("--alpha", nargs="+", type=float, default=list(d.alphas_deg), help="tilt-axis directions")
    q.add_argument("--repeats", type=number_arg(int, 1), default=d.repeats)
    q.add_argument("--patterns", nargs="+", choices=PATTERNS, default=list(d.patterns),
                   help="phase: 4-step fringes along x and y (period --phase-period)")
    q.add_argument("--refiners", nargs="+", choices=sorted(REFINERS), default=list(d.refiners),
                   help="each runs on the patterns it applies to: phase on the phase pattern, "
                   "the others on the stars (the other cells are n/a)")
    q.add_argument("--phase-period", type=float, default=d.phase_period,
                   help="fringe period of the phase pattern, px at the head-on view")
    q.add_argument("--perturb", type=float, default=d.perturb, help="start = truth + U(-p, p) in x and y, px")
    q.add_argument("--seed", type=int, default=d.seed)


def _experiment_parser(sub, d: Protocol) -> None:
    """rotstar-synth experiment: the protocol, --quick, where the results go and where the work runs"""
    e = sub.add_parser("experiment", help="run the experiment, write table, plots and summary",
                       formatter_class=HelpFormatter)
    _protocol_arguments(e, d)
    e.add_argument("--quick", action="store_true",
                   help="2 tilts (20, 50), 6 directions, 4 repeats, noise 0 and 4: under a minute "
                   "(explicit --phi/--alpha/--repeats/--noise still apply)")
    e.add_argument("--out", default="synth-out", help="output folder")
    e.add_argument("--cache", metavar="DIR", help="cache folder (default: OUT/cache); rerunning resumes from it")
    e.add_argument("--jobs", type=number_arg(int, 1), default=os.cpu_count() or 1, help="local worker processes")
    e.add_argument("--scheduler", metavar="ADDRESS", help="run on this Dask scheduler (dask.distributed)")
    e.add_argument("--no-plots", action="store_true", help="skip the PNG figures")


def _bound_parser(sub) -> None:
    """rotstar-synth bound: the Cramer-Rao bound against a Gaussian blur"""
    b = sub.add_parser("bound", help="Cramer-Rao bound per pattern against a Gaussian blur (head-on)",
                       formatter_class=HelpFormatter)
    b.add_argument("--sigmas", nargs="+", type=float, default=[0.5, 1.0, 2.0, 3.0], help="Gaussian sigma_b, px")
    b.add_argument("--noise", type=float, default=2.0, help="sigma_n, DN")
    b.add_argument("--window", type=int, default=10)
    b.add_argument("--supersample", type=int, default=8)


def protocol_from(args, given: set):
    base = quick_protocol() if getattr(args, "quick", False) else Protocol()
    kw = dict(aberrations=tuple(args.aberrations), amplitudes=_amplitudes(args.amplitude),
              gaussian_sigma=args.gaussian_sigma, coma_angle_deg=args.coma_angle,
              optics=Optics(args.wavelength_um, args.fnumber, args.pixel_um),
              supersample=args.supersample, window=args.window)
    if hasattr(args, "repeats"):
        if not args.phase_period > 0:
            fail(f"--phase-period must be positive, not {args.phase_period:g}")
        kw.update(patterns=tuple(args.patterns), refiners=tuple(args.refiners), perturb=args.perturb, seed=args.seed,
                  phase_period=args.phase_period)
        # with --quick only the options given explicitly override the quick settings
        for opt, field, conv in (("noise", "noises", _floats), ("phi", "phis_deg", _ints_or_floats),
                                 ("alpha", "alphas_deg", _ints_or_floats), ("repeats", "repeats", int)):
            if not args.quick or opt in given:
                kw[field] = conv(getattr(args, opt))
    return base.replace(**kw)


def _ints_or_floats(xs):
    return tuple(int(x) if float(x).is_integer() else float(x) for x in xs)


def _given(argv) -> set:
    argv = sys.argv[1:] if argv is None else argv
    return {a[2:].split("=")[0].replace("-", "_") for a in argv if a.startswith("--")}


class Bar:
    """A progress bar on stderr (a line per step when stderr is not a terminal)"""

    def __init__(self, width: int = 28):
        self.width, self.t0, self.tty = width, time.monotonic(), sys.stderr.isatty()

    def __call__(self, done: int, total: int, label: str) -> None:
        el = time.monotonic() - self.t0
        left = el / done * (total - done)
        n = int(self.width * done / max(total, 1))
        msg = f"[{'#' * n}{'.' * (self.width - n)}] {done}/{total} {label}  {el:.0f} s, ~{left:.0f} s left"
        if self.tty:
            sys.stderr.write("\r" + msg + ("\n" if done == total else ""))
            sys.stderr.flush()
        else:
            say(msg)


def cmd_experiment(args, given) -> int:
    # (here, not at the top: the figures' module brings matplotlib, 2.7-4.2 s of start-up measured with
    # python -X importtime, which psf, bound and --help do not need)
    import matplotlib

    matplotlib.use("Agg")
    from rotstar_mrcal.synth import plots

    protocol = protocol_from(args, given)
    pairs = sum(applies(a, r) for a in protocol.patterns for r in protocol.refiners)
    if not pairs:
        fail(f"no refiner of --refiners ({', '.join(protocol.refiners)}) applies to a pattern of --patterns "
             f"({', '.join(protocol.patterns)}): phase refines only the phase pattern, the others only the stars")
    _say_not_applying(protocol)
    out = args.out
    check_output_path(out, folder=True)
    cache = args.cache or os.path.join(out, "cache")
    check_output_path(cache, folder=True)
    os.makedirs(out, exist_ok=True)
    t0 = time.monotonic()
    todo = pending_tasks(protocol, cache) if os.path.isdir(cache) else None
    n_conf = len(protocol.aberrations) * len(protocol.noises) * len(protocol.phis_deg)
    where = f"Dask scheduler {args.scheduler}" if args.scheduler else f"{args.jobs} local process(es)"
    say(f"rotstar-synth: {n_conf} configurations ({len(protocol.alphas_deg)} views x {protocol.repeats} repeats "
        f"x {pairs} pattern-refiner pairs that apply each); "
        f"{'all' if todo is None else sum(len(t[2]) for t in todo)} to compute on {where}; cache {cache}")
    results = run_sweep(protocol, cache, jobs=args.jobs, scheduler=args.scheduler, progress=Bar())
    wall = time.monotonic() - t0
    rows = table.tabulate(protocol, results)
    mean_rows = table.over_tilts(rows)
    vs = verdicts.verdicts(mean_rows)

    _write_tables(out, protocol, rows, mean_rows)
    figures = [] if args.no_plots else _figures(plots, protocol, rows, out)
    with atomic_write(os.path.join(out, "summary.md")) as f:
        f.write(summary_markdown(protocol, mean_rows, vs, wall, args, figures))
    say(f"rotstar-synth: {wall:.1f} s wall; " + "; ".join(f"finding {v.finding}: {v.status}" for v in vs))
    print(out)
    return 0


def _say_not_applying(protocol) -> None:
    alone = [a for a in protocol.patterns if not any(applies(a, r) for r in protocol.refiners)]
    if alone:
        say(f"rotstar-synth: no refiner of --refiners applies to {', '.join(alone)}: n/a")


def _write_tables(out: str, protocol, rows, mean_rows) -> None:
    """OUT/protocol.json, table.json, table.md"""
    with atomic_write(os.path.join(out, "protocol.json")) as f:
        json.dump(protocol.to_dict(), f, indent=1, default=list)
    with atomic_write(os.path.join(out, "table.json")) as f:
        f.write(table.to_json(protocol, rows, mean_rows))
    with atomic_write(os.path.join(out, "table.md")) as f:
        f.write("# rotstar-synth: every configuration\n\nColumns: see summary.md.\n\n"
                + table.markdown(rows, with_phi=True))


def _figures(plots, protocol, rows, out: str) -> list[str]:
    """The range against the tilt per noise level, the PSFs, the views: their file names in OUT"""
    figures = []
    for n in protocol.noises:
        name = f"range_noise{n:g}.png"
        with atomic_path(os.path.join(out, name)) as tmp:
            plots.range_figure(protocol, rows, n).savefig(tmp, dpi=90)
        figures.append(name)
    with atomic_path(os.path.join(out, "psf.png")) as tmp:
        plots.psf_figure(protocol).savefig(tmp, dpi=90)
    with atomic_path(os.path.join(out, "views.png")) as tmp:
        plots.views_figure(protocol).savefig(tmp, dpi=90)
    return figures + ["psf.png", "views.png"]


def summary_markdown(protocol, mean_rows, vs, wall, args, figures) -> str:
    p = protocol
    lines = _summary_head(p, wall, args) + [
        "## The three findings",
        "",
        "Verdicts computed from the table below by rotstar_mrcal.synth.verdicts (thresholds in its docstring).",
        "",
        verdicts.markdown(vs),
        verdicts.observation_markdown(verdicts.phase_observation(mean_rows)),
        "## Pattern x refiner: mean range over the tilts (px)",
        "",
        "Each refiner runs on the patterns it applies to: the phase refiner (detect.phase, planes in the paper's "
        "7 x 7 px, started from the rotating star's symmetric corner as in the paper "
        + ("" if "rotstar" in p.patterns and "symmetric" in p.refiners else
           "where the run has it; this run has not, so from the common start")
        + ") on the phase pattern only, "
        "the wedge refiners on the stars only; n/a: does not apply. fails: more than half of the detections failed.",
        "",
    ] + [f"sigma_n = {n:g} DN:\n\n" + table.grid(mean_rows, n) for n in p.noises] + [
        "## Means over the tilts",
        "",
        "range = mean pairwise-distance range (the paper's metric); rms = 2-D RMS error against the truth; "
        "bias = its view-dependent systematic part, scatter = its noise part; bound = Cramer-Rao bound on the 2-D "
        "RMS error (0 without noise); fail = failed detections. Pixels. Every row: table.md, table.json.",
        "",
        table.markdown(mean_rows),
    ]
    if figures:
        lines += ["## Figures", ""] + [f"![{f}]({f})" for f in figures] + [""]
    return "\n".join(lines)


def _summary_head(p, wall, args) -> list[str]:
    """summary.md's title, the command and its wall time, the protocol"""
    cmd = "rotstar-synth " + " ".join(sys.argv[1:]) if sys.argv and "synth" in sys.argv[0] else "rotstar-synth experiment"
    return [
        "# rotstar-synth: reproduction of the synthetic experiment (paper 4.1)",
        "",
        f"Command: `{cmd}`. Wall time {wall:.1f} s on "
        + (f"the Dask scheduler {args.scheduler}" if args.scheduler else f"{args.jobs} local process(es)")
        + f" ({os.cpu_count()} cores seen; cached configurations are not recomputed, so a resumed run is faster).",
        "",
        f"Protocol: aberrations {', '.join(p.aberrations)}; noise sigma_n {', '.join(f'{n:g}' for n in p.noises)} DN "
        f"(contrast {p.contrast:g} DN); tilts phi {', '.join(f'{x:g}' for x in p.phis_deg)} deg; "
        f"{len(p.alphas_deg)} axis directions alpha; {p.repeats} repeats; half-window {p.window} px for every refiner "
        f"but phase (3 px, the paper's) and for the bound; starts = truth + U(-{p.perturb:g}, {p.perturb:g}) px "
        f"(phase: the rotating star's symmetric corner); {p.captures} exposures per pattern; "
        f"{p.supersample}x{p.supersample} sub-pixels; phase fringe period {p.phase_period:g} px head-on; "
        f"optics F/{p.optics.fnumber:g}, "
        f"{p.optics.pixel_um:g} um pixels, {p.optics.wavelength_um:g} um. PSFs: "
        + "; ".join(f"{a}: {_psf_text(p.psf_spec(a))}" for a in p.aberrations) + ".",
        "",
    ]


def _psf_text(spec) -> str:
    if spec["kind"] == "gaussian":
        return f"Gaussian sigma {spec['sigma_px']:g} px"
    return ", ".join(f"W_{t} = {v:g} waves" for t, v in spec["seidel"].items() if v and not t.endswith("angle"))


def cmd_psf(args, given) -> int:
    p = protocol_from(args, given)
    s = p.supersample
    print("# aberration  kernel_px  centroid_x  centroid_y  rms_radius  ee80_radius  asymmetry")
    for a in p.aberrations:
        k = psf_kernel(p, a)
        c = centroid_px(k, s)
        h = k.shape[0] // 2
        y, x = np.mgrid[-h : h + 1, -h : h + 1] / s
        r = np.hypot(x - c[0], y - c[1]).ravel()
        i = np.argsort(r)
        ee80 = r[i][np.searchsorted(np.cumsum(k.ravel()[i]), 0.8)]
        print(f"{a:12s} {k.shape[0] / s:9.2f} {c[0]:11.3f} {c[1]:11.3f} "
              f"{np.sqrt(np.trace(second_moment_px(k, s))):11.3f} {ee80:12.3f} {asymmetry(k):10.4f}")
    return 0


def cmd_bound(args, given) -> int:
    print(f"# per-axis CRLB std (px), contrast 200 DN, sigma_n {args.noise:g} DN, half-window {args.window}, head-on")
    print("# sigma_b  checkerboard  closed_form  rotstar_8_frames  star16  phase_8_frames")
    for sb in args.sigmas:
        b = pattern_bounds(gaussian_psf(sb, args.supersample), args.supersample, args.window, 200.0, args.noise)
        cf = closed_form_corner_bound(args.noise, 200.0, sb, args.window)
        print(f"{sb:8g} {b['checkerboard']:13.4f} {cf:12.4f} {b['rotstar']:17.4f} {b['star16']:7.4f} "
              f"{b['phase']:15.4f}")
    return 0


def main(argv=None) -> int:
    return run("rotstar-synth", _main, argv)


def _main(argv=None) -> int:
    args = parse_args(argv)
    given = _given(argv)
    return {"experiment": cmd_experiment, "psf": cmd_psf, "bound": cmd_bound}[args.command](args, given)


if __name__ == "__main__":
    sys.exit(main())

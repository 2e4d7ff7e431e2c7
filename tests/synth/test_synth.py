"""Tests of rotstar_mrcal.synth (the paper's synthetic experiment) and the rotstar-synth CLI"""

from __future__ import annotations

import json
import math
import os
import re

import mrcal
import numpy as np
import pytest

from rotstar_mrcal.cli.synth import main
from rotstar_mrcal.optics import Seidel, gaussian_psf, wavefront_psf
from rotstar_mrcal.synth import table, verdicts
from rotstar_mrcal.optics import Optics
from rotstar_mrcal.synth.experiment import (
    ABERRATIONS, SYMMETRIC, Protocol, psf_kernel, quick_protocol, render_views, run_task,
)
from rotstar_mrcal.synth.metrics import pairwise_range
from rotstar_mrcal.peers.phase import wrapped_phase
from rotstar_mrcal.synth.patterns import Star, pattern_frames
from rotstar_mrcal.synth.refiners import applies, refine
from rotstar_mrcal.synth.imaging import ViewRenderer, star_coverage, star_edge_measure
from rotstar_mrcal.synth.sweep import cache_path, pending_tasks, run_sweep
from rotstar_mrcal.synth.views import tilt_rotation, view_jacobian

RNG = np.random.default_rng(7)
VIEWS = [(0.0, 0.0), (math.radians(50), math.radians(30)), (math.radians(60), math.radians(135))]


def _brute_coverage(star, dx, dy, h, n=400):
    t = ((np.arange(n) + 0.5) / n - 0.5) * h
    return star.colour_at(np.arctan2(dy[:, None, None] + t[None, :, None], dx[:, None, None] + t[None, None, :])).mean(
        axis=(1, 2))


# ---- patterns and views ---------------------------------------------------
def test_patterns():
    (c,) = pattern_frames("checkerboard")
    assert np.allclose(np.degrees(c.edges), [0, 90, 180, 270]) and c.colours.tolist() == [0, 1, 0, 1]
    r = pattern_frames("rotstar")
    assert len(r) == 8 and np.allclose(np.degrees([f.edges[0] for f in r]), np.arange(8) * 11.25)
    (s,) = pattern_frames("star16")
    assert len(s.edges) == 16 and np.allclose(np.diff(s.edges), math.pi / 8)
    with pytest.raises(ValueError):
        pattern_frames("deltille")


def test_tilt_rotation():
    for phi, alpha in VIEWS + [(0.3, 2.0)]:
        R = tilt_rotation(phi, alpha)
        assert np.allclose(R @ R.T, np.eye(3)) and np.linalg.det(R) == pytest.approx(1)
        axis = np.array((math.cos(alpha), math.sin(alpha), 0))
        assert np.allclose(R @ axis, axis)  # the tilt axis lies in the board and stays
        assert math.degrees(math.acos(R[2, 2])) == pytest.approx(math.degrees(phi))  # the normal tilts by phi


@pytest.mark.parametrize("field", [(0.0, 0.0), (0.4, -0.25)])
@pytest.mark.parametrize("phi,alpha", VIEWS)
def test_star_mapped_is_the_exact_perspective_image(phi, alpha, field):
    """Board rays through the corner, projected by a pinhole camera, leave the corner's image at J u"""
    Z = 0.5
    R = tilt_rotation(phi, alpha)
    t = np.array((field[0] * Z, field[1] * Z, Z))
    intr = ("LENSMODEL_PINHOLE", np.array((800.0, 800.0, 400.0, 300.0)))
    star = Star.regular(16, 0.1)
    mapped = star.mapped(view_jacobian(phi, alpha, field))
    q0 = mrcal.project(t, *intr)
    for L in (0.002, 0.2):  # near and far along each edge: lines stay lines
        u = np.stack((np.cos(star.edges), np.sin(star.edges), np.zeros(16)), axis=-1) * L
        q = mrcal.project(u @ R.T + t, *intr) - q0
        assert np.allclose(np.arctan2(q[:, 1], q[:, 0]) % (2 * np.pi), mapped.edges % (2 * np.pi), atol=1e-9)


# ---- exact rendering ------------------------------------------------------
@pytest.mark.parametrize("name", ["checkerboard", "star16"])
def test_coverage_is_exact_area(name):
    star = pattern_frames(name)[0].mapped(view_jacobian(math.radians(55), math.radians(20)))
    h = 0.25
    dx, dy = RNG.uniform(-1.5, 1.5, 150), RNG.uniform(-1.5, 1.5, 150)
    dx[:3], dy[:3] = (0.0, 0.05, -0.1), (0.0, 0.1, 0.02)  # squares that hold the apex
    exact = star_coverage(star, dx, dy, h)
    assert np.allclose(exact, _brute_coverage(star, dx, dy, h), atol=3e-3)  # 400 x 400 point samples
    assert np.mean((exact > 0.01) & (exact < 0.99)) > 0.1  # enough squares cut by edges


@pytest.mark.parametrize("name", ["checkerboard", "star16"])
def test_edge_measure_is_the_derivative_of_coverage(name):
    """The gradient used by the bound is the exact derivative of the exact area (no finite differences inside)"""
    star = pattern_frames(name)[0].mapped(view_jacobian(math.radians(40), math.radians(70)))
    h, e = 0.25, 1e-6
    dx, dy = RNG.uniform(-2, 2, 500), RNG.uniform(-2, 2, 500)
    m = star_edge_measure(star, dx, dy, h)
    # moving the pattern by +e moves every square by -e relative to the apex
    fx = (star_coverage(star, dx + e, dy, h) - star_coverage(star, dx - e, dy, h)) / (2 * e) * h * h
    fy = (star_coverage(star, dx, dy + e, h) - star_coverage(star, dx, dy - e, h)) / (2 * e) * h * h
    far = np.maximum(abs(dx), abs(dy)) > 0.6 * h  # the apex square: coverage has a kink there
    assert np.allclose(m[far, 0], fx[far], atol=1e-6) and np.allclose(m[far, 1], fy[far], atol=1e-6)
    assert np.abs(m).max() > 0.1


@pytest.mark.parametrize("name", ["checkerboard", "rotstar", "star16"])
def test_block_summation(name):
    """s x s sub-pixels averaged into a pixel = the pixel's own exact coverage (and edge measure)"""
    stars = [st.mapped(view_jacobian(math.radians(35), math.radians(100))) for st in pattern_frames(name)]
    T, apex = 15, np.array((7.3, 6.6))
    c = np.arange(T, dtype=float)
    dx, dy = c[None, :] - apex[0], c[:, None] - apex[1]
    exact = np.stack([star_coverage(st, dx, dy, 1.0) for st in stars])
    meas = np.stack([star_edge_measure(st, dx, dy, 1.0) for st in stars])
    for s in (1, 3, 4):
        img, grad = ViewRenderer(np.ones((1, 1)), s, T)(stars, apex)  # a delta PSF: only the summation
        assert np.allclose(img, exact, atol=1e-6)
        assert np.allclose(grad, meas, atol=1e-5)
    assert exact.min() >= 0 and exact.max() <= 1 and np.mean((exact > 0.01) & (exact < 0.99)) > 0.1


def test_render_gradient_matches_finite_differences_of_the_render():
    stars = [st.mapped(view_jacobian(0.6, 0.4)) for st in pattern_frames("rotstar")[:3]]
    r = ViewRenderer(wavefront_psf(Seidel(coma=4.0), supersample=4), 4, 24)
    apex, e = np.array((12.3, 11.6)), 1e-3
    _, g = r(stars, apex)
    for i in range(2):
        d = np.eye(2)[i] * e
        fd = (r(stars, apex + d, False)[0] - r(stars, apex - d, False)[0]) / (2 * e)
        assert np.allclose(-fd, g[..., i], atol=5e-4)  # float32 FFT
    assert np.abs(g).max() > 0.1


def test_render_symmetric_psf_gives_point_symmetric_tile():
    apex = np.array((10.0, 10.0))  # on a pixel centre: the tile itself is point-symmetric
    stars = [st.mapped(view_jacobian(0.8, 0.3)) for st in pattern_frames("rotstar")]
    for k in (gaussian_psf(1.5, 4), wavefront_psf(Seidel(spherical=1.5), supersample=4)):
        img, _ = ViewRenderer(k, 4, 21)(stars, apex)
        assert np.allclose(img, img[:, ::-1, ::-1], atol=1e-5)
    img, _ = ViewRenderer(wavefront_psf(Seidel(coma=4.0), supersample=4), 4, 21)(stars, apex)
    assert not np.allclose(img, img[:, ::-1, ::-1], atol=1e-2)


# ---- refiners on the experiment's renders ---------------------------------
@pytest.mark.parametrize("aberration", [a for a in ABERRATIONS if SYMMETRIC[a]])
def test_refiners_unbiased_on_noise_free_symmetric_psf(aberration):
    """No noise, point-symmetric PSF: the symmetric refinement finds the true corner at every tilt

    Astigmatism focuses to a line: edges along it stay diffraction-sharp (0.4 px),
    and the refiner's bilinear interpolation of a sharp edge costs ~0.02 px (the
    PSF is still symmetric; the sampling is not), so it gets a looser bound.
    """
    tol = 0.04 if aberration == "astigmatism" else 0.01
    p = Protocol(alphas_deg=(0, 45, 120), patterns=("checkerboard", "rotstar"), repeats=3)
    for phi in (20, 60):
        frames, _ = render_views(p, aberration, phi)
        for name, f in frames.items():
            for v in range(len(p.alphas_deg)):
                starts = p.truth + RNG.uniform(-1, 1, (3, 2))
                q = refine("symmetric", f[v], starts, p.window)
                assert np.abs(q - p.truth).max() < tol, (aberration, phi, name, v)


def test_coma_biases_the_same_refiner():
    """...and under coma the same refiner moves with the view: the test above can fail"""
    p = Protocol(alphas_deg=(0, 45, 90, 135), patterns=("checkerboard",))
    frames, _ = render_views(p, "coma", 50)
    q = np.stack([refine("symmetric", f, p.truth[None], p.window)[0] for f in frames["checkerboard"]])
    assert pairwise_range(q) > 0.05
    assert np.linalg.norm(q.mean(axis=0) - p.truth) > 1.0  # the comet's light is off the paraxial point


# ---- the phase-shift pattern and its refiner --------------------------------
@pytest.mark.parametrize("phi,alpha", VIEWS)
def test_phase_pattern_has_phase_zero_at_the_corner_without_blur(phi, alpha):
    """Delta PSF: the 4-step phase of every pixel is k . (centre - corner), the plane fit's zero is the corner"""
    J = view_jacobian(phi, alpha)
    fr = [f.mapped(J) for f in pattern_frames("phase")]
    apex = np.array((10.3, 9.6))
    img, grad = ViewRenderer(np.ones((1, 1)), 4, 21)(fr, apex)
    assert img.shape == (8, 21, 21) and img.min() >= 0 and img.max() <= 1
    y, x = np.mgrid[0:21, 0:21].astype(float)
    for axis in range(2):
        phi_img, mod = wrapped_phase(img[4 * axis : 4 * axis + 4])
        k = fr[4 * axis].k
        want = k[0] * (x - apex[0]) + k[1] * (y - apex[1])
        assert np.abs(np.angle(np.exp(1j * (phi_img - want)))).max() < 1e-6  # pixel averaging keeps the phase
        assert mod.min() > 0.4  # 0.5 times the pixel's sinc attenuation
    starts = apex + np.array([[0.8, -0.7], [-0.4, 0.9]])
    assert np.abs(refine("phase", 28 + 200 * img, starts) - apex).max() < 1e-6


def test_fringe_gradient_matches_finite_differences_of_the_render():
    """The bound's d pixel / d corner for fringes, through a coma PSF"""
    k = wavefront_psf(Seidel(coma=2.0), Optics(), 4)
    r = ViewRenderer(k, 4, 21)
    fr = [f.mapped(view_jacobian(0.6, 0.4)) for f in pattern_frames("phase")]
    apex, e = np.array((10.3, 9.6)), 1e-2  # smooth: the truncation error is ~(k e)^2 / 6, float32 noise ~1e-7 / e
    _, g = r(fr, apex)
    for i in range(2):
        d = np.zeros(2)
        d[i] = e
        fd = (r(fr, apex + d, False)[0] - r(fr, apex - d, False)[0]) / (2 * e)
        assert np.abs(fd + g[..., i]).max() < 1e-3 * np.abs(g).max()


@pytest.mark.parametrize("aberration", ["none", "spherical"])
def test_phase_refiner_subpixel_under_a_symmetric_blur(aberration):
    """Point-symmetric PSF, tilted view, no noise: the phase corner is within 0.01 px of the truth"""
    p = Protocol(aberrations=(aberration,))
    r = ViewRenderer(psf_kernel(p, aberration), 4, 30)
    fr = [f.mapped(view_jacobian(math.radians(50), math.radians(30))) for f in pattern_frames("phase")]
    for apex in (np.array((15.3, 15.7)), np.array((14.55, 15.1))):
        img, _ = r(fr, apex, False)
        q = refine("phase", 28 + 200 * img, apex + np.array([[0.9, -0.8]]))
        assert np.linalg.norm(q - apex) < 0.01, (aberration, apex, q)


def test_cli_refuses_a_run_where_no_refiner_applies(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["experiment", "--quick", "--patterns", "checkerboard", "--refiners", "phase", "--out", str(out)]) == 2
    assert "no refiner of --refiners (phase) applies" in capsys.readouterr().err and not out.exists()


def test_phase_refiner_rejects_wedges_and_table_shows_na():
    with pytest.raises(ValueError, match="8 frames"):
        refine("phase", np.zeros((1, 30, 30)), np.array([[15.0, 15.0]]))
    assert not applies("checkerboard", "phase") and not applies("phase", "opencv") and applies("phase", "phase")
    p = quick_protocol(aberrations=("spherical", "coma"), noises=(0.0,), phis_deg=(30,), alphas_deg=(0, 90),
                       repeats=2, patterns=("checkerboard", "rotstar", "phase"), refiners=("phase", "symmetric"))

    def det(shift):  # view 1 is off by `shift` px in x: the stars with symmetric, phase with phase; the rest NaN
        d = np.full((2, 2, 3, 2, 2), np.nan, np.float32)
        off = np.array([[0.0, 0.0], [shift, 0.0]])[None]
        d[:, :, :2, 1] = (p.truth + off)[:, :, None]
        d[:, :, 2, 0] = p.truth + 5 * off
        return d

    res = {(a, 0.0, 30): {"detections": det(v), "truth": p.truth, "fisher": np.tile(np.eye(2), (2, 3, 1, 1))}
           for a, v in (("spherical", 0.01), ("coma", 0.1))}
    rows = table.tabulate(p, res)
    assert {(r["pattern"], r["refiner"]) for r in rows} == {("checkerboard", "symmetric"), ("rotstar", "symmetric"),
                                                            ("phase", "phase")}
    means = table.over_tilts(rows)
    g = table.grid(means, 0.0).splitlines()
    assert g[0] == "| aberration | pattern | symmetric | phase |"
    assert "| coma | checkerboard | 0.1000 | n/a |" in g and "| coma | phase | n/a | 0.5000 |" in g
    vs = verdicts.verdicts(means)  # the n/a cells are skipped, nothing crashes
    assert [v.status for v in vs][:2] == ["reproduced", "partly reproduced"]
    obs = verdicts.phase_observation(means)
    assert obs.lines[0] == "symmetric PSF, sigma_n = 0: phase 0.0500 px, rotstar (symmetric) 0.0100 px: phase x5.00"
    assert "noise-free, the phase-shift corner is less stable than the rotating star (x5.00" in obs.conclusion
    assert verdicts.phase_observation([r for r in means if r["pattern"] != "phase"]) is None
    assert verdicts.observation_markdown(None) == ""


# ---- the experiment, the cache, the executors ------------------------------
TINY = quick_protocol(aberrations=("spherical", "coma"), noises=(0.0, 3.0), phis_deg=(30,), alphas_deg=(0, 90),
                      repeats=2)


def test_run_task_deterministic_and_independent_of_grouping():
    a = run_task(TINY, "coma", 30, (0.0, 3.0))
    b = run_task(TINY, "coma", 30, (3.0,))
    assert a[3.0]["detections"].shape == (2, 2, 4, 4, 2)
    assert np.array_equal(a[3.0]["detections"], b[3.0]["detections"], equal_nan=True)
    assert not np.array_equal(a[0.0]["detections"], a[3.0]["detections"], equal_nan=True)
    F = a[0.0]["fisher"]
    assert F.shape == (2, 4, 2, 2) and np.all(np.linalg.eigvalsh(F) > 0)
    # only the pairs that apply ran: phase x phase and the stars x the wedge refiners
    det = a[3.0]["detections"]
    for j, pat in enumerate(TINY.patterns):
        for i, ref in enumerate(TINY.refiners):
            ran = np.isfinite(det[:, :, j, i]).any()  # (the saddle fit fails on the 16-star: no saddle)
            assert ran == applies(pat, ref) or (pat, ref) == ("star16", "saddle"), (pat, ref)


def test_cache_key():
    k = TINY.config_key("coma", 3.0, 30)
    assert k == TINY.replace(phis_deg=(10, 30), noises=(3.0,), aberrations=("coma",)).config_key("coma", 3.0, 30)
    assert k != TINY.replace(repeats=3).config_key("coma", 3.0, 30)
    assert k != TINY.replace(amplitudes=(("coma", 3.0),)).config_key("coma", 3.0, 30)
    assert TINY.config_key("spherical", 3.0, 30) == TINY.replace(
        amplitudes=(("coma", 3.0),)).config_key("spherical", 3.0, 30)


def test_sweep_caches_and_resumes(tmp_path):
    p = TINY.replace(aberrations=("spherical",), refiners=("symmetric",))
    first = run_sweep(p, str(tmp_path), jobs=1)
    assert len(first) == 2 and pending_tasks(p, str(tmp_path)) == []
    path = cache_path(p, str(tmp_path), "spherical", 3.0, 30)
    os.remove(path)
    assert pending_tasks(p, str(tmp_path)) == [("spherical", 30, (3.0,))]
    calls = []
    again = run_sweep(p, str(tmp_path), jobs=1, progress=lambda *a: calls.append(a))
    assert calls == [(1, 1, "spherical phi=30")] and os.path.exists(path)
    for key in first:
        assert np.array_equal(first[key]["detections"], again[key]["detections"], equal_nan=True)


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("quick")
    assert main(["experiment", "--quick", "--out", str(out)]) == 0
    return out


@pytest.mark.slow  # make test-slow: an end-to-end run, left out of make test
def test_quick_experiment_outputs(quick_run, capsys):
    names = set(os.listdir(quick_run))
    assert {"table.md", "table.json", "summary.md", "protocol.json", "psf.png", "views.png",
            "range_noise0.png", "range_noise4.png", "cache"} <= names
    doc = json.load(open(quick_run / "table.json"))
    # 3 star patterns x 3 wedge refiners + phase x phase, per aberration, noise (and tilt)
    assert len(doc["rows"]) == 2 * 2 * 2 * (3 * 3 + 1) and len(doc["over_tilts"]) == 2 * 2 * (3 * 3 + 1)
    summary = open(quick_run / "summary.md").read()
    assert "## Phase shifting: our observation" in summary
    assert re.search(r"\| spherical \| phase \| n/a \| n/a \| n/a \| [0-9.]+ \|", summary)  # opencv saddle symmetric phase
    # a rerun finds everything in the cache
    assert main(["experiment", "--quick", "--out", str(quick_run), "--no-plots"]) == 0
    assert "0 to compute" in capsys.readouterr().err


@pytest.mark.slow  # make test-slow: on the quick experiment's whole run (test_quick_experiment_outputs)
def test_quick_verdicts_are_computed_from_the_numbers(quick_run):
    """The summary's verdicts are what verdicts.verdicts() says about table.json's numbers"""
    summary = open(quick_run / "summary.md").read()
    stated = re.findall(r"### Finding (\d): ([a-z ]+) \(", summary)
    assert [int(n) for n, _ in stated] == [1, 2, 3]
    rows = [dict(r, range=np.nan if r["range"] is None else r["range"])
            for r in json.load(open(quick_run / "table.json"))["over_tilts"]]
    vs = verdicts.verdicts(rows)
    assert [s for _, s in stated] == [v.status for v in vs]
    assert all(v.status != "not testable" for v in vs)
    # change the numbers and the verdicts change: make coma as harmless as spherical aberration
    sph = {(r["noise"], r["pattern"], r["refiner"]): r["range"] for r in rows if r["aberration"] == "spherical"}
    for factor, status in ((1.0, "not reproduced"), (10.0, "reproduced")):
        fake = [dict(r, range=factor * sph[(r["noise"], r["pattern"], r["refiner"])] if r["aberration"] == "coma"
                     else r["range"]) for r in rows]
        assert verdicts.verdicts(fake)[0].status == status


@pytest.mark.slow  # make test-slow: on the quick experiment's whole run (test_quick_experiment_outputs)
def test_quick_table_sanity(quick_run):
    rows = json.load(open(quick_run / "table.json"))["over_tilts"]
    get = lambda **k: table.lookup(rows, **k)  # noqa: E731
    # noise-free symmetric PSF: the symmetric refinement is unbiased on checkerboard and rotstar
    for pat in ("checkerboard", "rotstar"):
        assert get(aberration="spherical", noise=0.0, pattern=pat, refiner="symmetric")["rms"] < 0.01
    # with noise the error is at least the bound (Cramer-Rao), for every method with a spread
    for r in rows:
        if r["noise"] > 0 and r["fail"] < 0.5:
            assert r["scatter_over_bound"] > 0.7, r
    # the saddle fit does not apply to the 16-segment star (no saddle): it fails
    assert get(aberration="spherical", noise=0.0, pattern="star16", refiner="saddle")["fail"] > 0.5
    # noise-free, a symmetric PSF does not shift the fringes' phase: the phase corner is the truth; coma shifts it
    assert get(aberration="spherical", noise=0.0, pattern="phase", refiner="phase")["rms"] < 1e-3
    assert get(aberration="coma", noise=0.0, pattern="phase", refiner="phase")["range"] > 0.01
    assert get(aberration="spherical", noise=0.0, pattern="phase", refiner="symmetric") is None  # n/a


def test_dask_scheduler_matches_local(tmp_path):
    """--scheduler: the same numbers from a Dask LocalCluster as from this process"""
    distributed = pytest.importorskip("dask.distributed")
    p = ["--aberrations", "coma", "--noise", "2", "--phi", "30", "--alpha", "0", "90", "--repeats", "2",
         "--refiners", "symmetric", "opencv", "--no-plots"]
    assert main(["experiment", "--out", str(tmp_path / "local"), "--jobs", "1", *p]) == 0
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp://",
                                  dashboard_address=None) as cluster:
        assert cluster.scheduler_address.startswith("tcp://")
        assert main(["experiment", "--out", str(tmp_path / "dask"), "--scheduler", cluster.scheduler_address, *p]) == 0
    a = json.load(open(tmp_path / "local" / "table.json"))["rows"]
    b = json.load(open(tmp_path / "dask" / "table.json"))["rows"]
    assert a == b and len(a) == 3 * 2

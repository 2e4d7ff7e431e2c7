"""Corner error against the centroid truth under coma: rotstar, rotstar-psf and the saddle fit (issue 24)

SYNOPSIS

    nice -n 10 .venv/bin/python -m rotstar_lab.benchmark.psfcheck --coma 2.5 --focus 0.3 --npose 4
    (PYTHONPATH=scripts; renders are cached in --cache, default /tmp/rotstar-psfcheck-centred: the lens's PSF
    blended between nodes, optics.SmoothPSF, each node's centroid on the chief ray exactly; the former
    /tmp/rotstar-psfcheck-smooth held renders whose kernels' centroids the crop had moved 0.01-0.02 px)

The scene of the failure tables (failures.py): the d435 preset, make demo's
lens (optics.LensPSF, coma and focus in waves at the image corners; the
light's centroid on the true model), the paper layout without identity
frames, random poses from failures.make_units' generator, read noise 1 %,
shot 1e-4, 16 bits. Per pose the 8 rotating-star frames are detected by
rotstar (detect_pose, the symmetric fit) and by rotstar-psf; the saddle fit
runs on the 8-capture averaged checkerboard from the true corners moved 0.5
px, in the true windows (as in the failure tables). --gaussian S replaces the
lens by a symmetric Gaussian PSF of S px.

--check-blur-map CSV instead compares a blur map (rotstar-detect --blur-map
of a d435 dataset simulated with --seidel coma=C,focus=F, e.g. make
blur-map-doc) with the lens's true PSFs (LensPSF's kernel at each corner, its
projections on 16 directions clipped to the row's reach): the width ratio,
and the coma direction error where the coma is above 0.5 waves, per corner
and pooled in 128-px cells.

Methods: the refiners' names (symmetric, psf, psf-sim: detect_pose with
REFINERS[name]), saddle, and the experiments of bias by simulation
(detect/psfbias.py) on the symmetric fit's corners with the truth's help:
simbias-true (the simulator's own kernel at each corner and the true element
geometry), simbias-nodes-S-N-D (the same at N corners, S sub-pixels per px,
a field of degree D between), simbias-moments-L (a Gram-Charlier kernel of
the true kernel's moments clipped to L px, 0: edgespread's reach),
simbias-est (psf-sim's estimate with the true geometry), simbias-truecoma
(psf-sim's model and scheme given the lens's own coma, the true geometry),
simbias-seidel (every corner simulated through the Seidel PSF at that point,
the lens's coma and focus: LensPSF without the blending between its
nodes). --noise 0 renders
noiseless frames, --no-display-maps leaves the per-frame display maps out;
--supersample S renders at S sub-pixels per px (make demo's 2; default 4)
and --pose K runs only pose K of the --npose.
The floor's suspects (doc/blur-map.md): --tiled PX renders through the
former piecewise-constant PSF (optics.TiledPSF, PX-px tiles from the rendered
region's corner; simbias-true then takes the Seidel kernel at the corner),
--tap-floor F and --star-fft change psfbias's own approximations (the
kernel taps left out; the FFT rendering of the local star instead of the
binned one); --no-phase runs psf-sim without psfbias.PHASE (only the 12
nodes' biases, carried by a smooth field; every corner's own sub-pixel
phase simulated on its node's star is the default).

Printed: per method the RMS of the corner error against the truth, and its
pose-dependent part: the error minus the mean error of its image cell
(CELL_PX squares, over all poses; cells with one corner left out), RMS, with
the n/(n-1) correction, and (in brackets) the error less a smooth field over
the image fitted to all poses at once (field_residual: what a lens model
cannot take up; the cells also count a static field's change across a
cell); and the detection time per pose.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time

import numpy as np

from rotstar_mrcal import simulate
from rotstar_mrcal.detect.blurmap import read_table
from rotstar_mrcal.detect.edgespread import projected_moments, psf_estimate
from rotstar_mrcal.detect.pipeline import detect_pose
from rotstar_mrcal.detect import psfbias
from rotstar_mrcal.detect.psfbias import bias_correct, coma_samples, simulated_bias, spread_nodes, star_normals
from rotstar_mrcal.optics.blur import TiledPSF, normalize_kernel
from rotstar_mrcal.optics.psf import LensPSF
from rotstar_mrcal.optics.wavefront import Seidel
from rotstar_mrcal.peers.checkerboard import refine_by_window, saddle_refine
from rotstar_mrcal.peers.registry import REFINERS
from rotstar_mrcal.simulate.captures import averaged_captures, lit_box
from rotstar_mrcal.simulate.visibility import in_view, true_windows
from rotstar_lab.benchmark.failures import paper_layout
from rotstar_lab.benchmark.scoring import MATCH_PX, perturbed_start

CELL_PX = 80.0


def render(model, layout, rt, psf, path, supersample=4):
    """(rotstar frames irradiance (8, H, W), checkerboard irradiance (H, W)), cached in path"""
    if os.path.exists(path):
        z = np.load(path)
        return z["rot"], z["cb"]
    fr = [f for f in layout.frames() if f["kind"] in ("rotstar", "checkerboard")]
    kinds = np.array([f["kind"] for f in fr])
    light = simulate.shown_light(simulate.exact_frames(layout, fr), 2.2, 2.2)
    screen = simulate.make_screen(light, layout)
    E = simulate.render_irradiance(screen, model, rt, supersample=supersample, psf=psf)
    rot, cb = E[kinds == "rotstar"], E[kinds == "checkerboard"][0]
    np.savez(path, rot=rot, cb=cb)
    return rot, cb


class TiledLens:
    """A LensPSF rendered as the simulator did before SmoothPSF: px-px tiles from the region's corner"""

    def __init__(self, lens: LensPSF, px: int):
        self.lens = lens
        self.tiled = TiledPSF(lens._built().kernel_at, px, lens.radius_px)
        self.radius_px = lens.radius_px

    def __call__(self, sub, origin, s):
        return self.tiled(sub, origin, s)

    def local_kernel(self, x, y, s):
        """The Seidel kernel at (x, y) (what a corner at its tile's centre is blurred by)"""
        return normalize_kernel(self.lens._built().kernel_at(x, y, s))


def pose_dependent(pos, err):
    """RMS of err (n, 2) minus its CELL_PX cell's mean over all poses (cells of >= 2 corners), n/(n-1) corrected

    >>> pos = np.array([[10.0, 10.0], [20.0, 20.0], [500.0, 500.0]])
    >>> round(pose_dependent(pos, np.array([[0.1, 0.0], [0.3, 0.0], [9.0, 9.0]])), 4)   # the lone corner: no cell
    0.1414

    (residuals +-0.1 px about the cell's mean, times sqrt(n / (n - 1)) for n = 2.)
    """
    cell = np.floor(pos / CELL_PX).astype(int)
    key = cell[:, 0] * 1000 + cell[:, 1]
    out, dof = 0.0, 0
    for k in np.unique(key):
        e = err[key == k]
        if len(e) < 2:
            continue
        out += ((e - e.mean(axis=0)) ** 2).sum()
        dof += (len(e) - 1) * 2
    return float(np.sqrt(out / max(dof, 1) * 2))


FIELD_DEGREE = 5


def field_residual(pos, err, degree: int = FIELD_DEGREE):
    """RMS of err (n, 2) less the smooth field over the image (a polynomial of `degree` in x, y fitted to every
    pose's corners at once): the part of the error a lens model cannot take up, dof-corrected

    The cell means of pose_dependent also count the static field's change
    across a cell (under coma the symmetric fit's offset grows by 0.004 px
    across 80 px near the image corners), which a calibration absorbs.

    >>> pos = np.random.default_rng(0).uniform(0, 1280, (400, 2))
    >>> e = np.stack((1e-4 * pos[:, 0], -1e-4 * pos[:, 1]), -1)     # a static field: nothing left but the cells'
    >>> field_residual(pos, e) < 1e-12, pose_dependent(pos, e) > 0.002
    (True, True)
    """
    x, y = (pos[:, 0] - 640.0) / 640.0, (pos[:, 1] - 400.0) / 640.0
    A = np.stack([x ** i * y ** j for i in range(degree + 1) for j in range(degree + 1 - i)], 1)
    c, *_ = np.linalg.lstsq(A, err, rcond=None)
    r = err - A @ c
    return float(np.sqrt((r ** 2).sum(1).mean() * len(err) / max(len(err) - A.shape[1], 1)))


# the Gram-Charlier kernel of a PSF's second and third moments (the experiment simbias-moments-L: with the
# moments clipped to edgespread's reach the bias is not reproduced, 0.0342 px against 0.0105 unclipped)
def moment_tensors(es) -> tuple[np.ndarray, np.ndarray]:
    """(cov (N, 2, 2), kappa (N, 4)) of the PSF from its projections' moments (edgespread.EdgeSpread)

    var(phi) = s0 + s2c cos 2phi + s2s sin 2phi gives the covariance;
    third(phi) = A cos phi + B sin phi + C cos 3phi + D sin 3phi the third
    cumulant tensor kappa = (k_xxx, k_xxy, k_xyy, k_yyy), from
    third(phi) = k_xxx c^3 + 3 k_xxy c^2 s + 3 k_xyy c s^2 + k_yyy s^3.
    NaN rows where too few edges were measured.

    >>> from rotstar_mrcal.detect.edgespread import projected_moments
    >>> from rotstar_mrcal.optics.psf import gaussian_psf
    >>> cov, kappa = moment_tensors(projected_moments(gaussian_psf(1.0, 4), 4, np.arange(16) * np.pi / 16, 6.0))
    >>> np.round(cov, 2).tolist(), bool(np.abs(kappa).max() < 1e-6)
    ([[[1.0, 0.0], [0.0, 1.0]]], True)
    """
    phi = es.normal
    c1, s1 = np.cos(phi), np.sin(phi)
    v = _harmonic(es.var, np.stack((np.ones_like(phi), np.cos(2 * phi), np.sin(2 * phi)), -1))
    t = _harmonic(es.third, np.stack((c1, s1, np.cos(3 * phi), np.sin(3 * phi)), -1))
    cov = np.stack((np.stack((v[:, 0] + v[:, 1], v[:, 2]), -1), np.stack((v[:, 2], v[:, 0] - v[:, 1]), -1)), -2)
    A, B, C, D = t.T
    kappa = np.stack((A + C, B / 3 + D, A / 3 - C, B - D), -1)
    return cov, kappa


def _harmonic(y, cols):
    """Least-squares coefficients per row of y (N, E) on cols (N, E, p), NaNs left out (NaN: too few)"""
    ok = np.isfinite(y) & np.isfinite(cols).all(-1)
    A = np.where(ok[..., None], cols, 0.0)
    AtA = np.einsum("nep,neq->npq", A, A)
    enough = ok.sum(-1) > cols.shape[-1] + 1
    AtA[~enough] = np.eye(cols.shape[-1])
    coef = np.linalg.solve(AtA, np.einsum("nep,ne->np", A, np.where(ok, y, 0.0))[..., None])[..., 0]
    coef[~enough] = np.nan
    return coef


def moment_kernel(cov: np.ndarray, kappa: np.ndarray, s: int, radius: float | None = None) -> np.ndarray:
    """(N, k, k) kernels at s taps per px with covariance cov (N, 2, 2) and third cumulants kappa (N, 4)

    A Gaussian times 1 + kappa . H3 / 6 (the Gram-Charlier series to third
    order: mean 0, the covariance and third cumulants given; it may dip
    below 0 where the skew is strong), sum 1. radius: px (default 5 sigma
    of the widest).

    >>> k = moment_kernel(np.eye(2)[None] * 1.0, np.array([[0.5, 0.0, 0.0, 0.0]]), 4)
    >>> x = (np.arange(k.shape[2]) - k.shape[2] // 2) / 4
    >>> round(float((k[0].sum(0) * x).sum()), 3) + 0.0, round(float((k[0].sum(0) * x ** 3).sum()), 2)
    (0.0, 0.5)
    """
    cov = np.asarray(cov, float)
    kappa = np.asarray(kappa, float)
    if radius is None:
        radius = 5 * float(np.sqrt(np.linalg.eigvalsh(cov)[:, -1].max()))
    m = int(np.ceil(radius * s))
    t = np.arange(-m, m + 1) / s
    x = np.stack(np.broadcast_arrays(t[None, :], t[:, None]), -1)  # (k, k, 2) (x, y)
    P = np.linalg.inv(cov)  # (N, 2, 2)
    y = np.einsum("nij,abj->nabi", P, x)  # Sigma^-1 x
    g = np.exp(-0.5 * np.einsum("nabi,abi->nab", y, x))
    kxxx, kxxy, kxyy, kyyy = (kappa[:, i, None, None] for i in range(4))
    y0, y1 = y[..., 0], y[..., 1]
    p00, p01, p11 = (P[:, i, j, None, None] for i, j in ((0, 0), (0, 1), (1, 1)))
    h = (kxxx * (y0 ** 3 - 3 * y0 * p00) + 3 * kxxy * (y0 * y0 * y1 - y1 * p00 - 2 * y0 * p01)
         + 3 * kxyy * (y0 * y1 * y1 - y0 * p11 - 2 * y1 * p01) + kyyy * (y1 ** 3 - 3 * y1 * p11))
    k = g * (1 + h / 6)
    return k / k.sum(axis=(1, 2), keepdims=True)


def grid_jacobian(corners: np.ndarray, pitch: float) -> np.ndarray:
    """(ny, nx, 2, 2) camera px per display px from a corner grid (ny, nx, 2), by central differences"""
    gx = np.gradient(corners, axis=1) / pitch
    gy = np.gradient(corners, axis=0) / pitch
    return np.stack((gx, gy), axis=-1)


def true_kernels(psf, xy: np.ndarray, s: int = 4, quantum: float = 1.0) -> np.ndarray:
    """(N, k, k) the lens's PSFs of the light at points xy (N, 2) (LensPSF.local_kernel; positions rounded to
    `quantum` px), padded to one size; a number: that Gaussian's"""
    if len(xy) == 0:
        return np.zeros((0, 1, 1))
    if not hasattr(psf, "local_kernel"):
        from rotstar_mrcal.optics.psf import gaussian_psf
        return np.broadcast_to(gaussian_psf(float(psf), s), (len(xy),) + gaussian_psf(float(psf), s).shape).copy()
    ks = [psf.local_kernel(*(np.round(p / quantum) * quantum), s) for p in xy]
    m = max(k.shape[0] for k in ks)
    out = np.zeros((len(ks), m, m))
    for i, k in enumerate(ks):
        a = (m - k.shape[0]) // 2
        out[i, a:a + k.shape[0], a:a + k.shape[1]] = k / k.sum()
    return out


def simbias_nodes(pc, truth, psf, layout, s=2, nodes=9, degree=1) -> np.ndarray:
    """simbias_true at `nodes` corners spread over the pose (s sub-pixels per px), a smooth field between"""
    from rotstar_mrcal.detect.edgespread import smooth_field
    q = pc.corners.copy()
    j, i = np.nonzero(np.isfinite(q[..., 0]))
    pick = spread_nodes(q[j, i], nodes)
    J = grid_jacobian(truth, float(layout.pitch))[j, i][pick]
    n = star_normals(J, np.array([layout.angle(k) for k in range(layout.nframes)]))
    b = simulated_bias(true_kernels(psf, q[j, i][pick], s), s, n, q[j, i][pick], pc.window[j, i][pick], pc.prefilter_px)
    ok = np.isfinite(b).all(axis=1)
    q[j, i] -= smooth_field(q[j, i][pick][ok], b[ok], degree, at=q[j, i])
    return q


def simbias_true(pc, truth, psf, layout, reach=None) -> np.ndarray:
    """(ny, nx, 2) the symmetric corners pc less the bias simulated with the TRUE local PSF and geometry

    reach: instead of the true kernels, Gram-Charlier kernels of their moments clipped to +-reach
    (px; 0: edgespread's reach for the corner's window)
    """
    q = pc.corners.copy()
    j, i = np.nonzero(np.isfinite(q[..., 0]))
    J = grid_jacobian(truth, float(layout.pitch))[j, i]
    n = star_normals(J, np.array([layout.angle(k) for k in range(layout.nframes)]))
    w = pc.window[j, i]
    k = true_kernels(psf, q[j, i])
    if reach is not None:
        L = np.clip(0.45 * w, 2, 5) if reach == 0 else np.full(len(w), float(reach))
        es = [projected_moments(kk, 4, np.arange(16) * np.pi / 16, r) for kk, r in zip(k, L)]
        cov, kappa = (np.concatenate(v) for v in zip(*[moment_tensors(e) for e in es]))
        k = moment_kernel(cov, kappa, 4)
    b = simulated_bias(k, 4, n, q[j, i], w, pc.prefilter_px)
    q[j, i] -= b
    return q


def true_coma(a, xy: np.ndarray, imagersize) -> np.ndarray:
    """(N, 2) the lens's coma at image points xy (waves along the tail: LensPSF's coma x field radius, outward)"""
    c = (np.array(imagersize, float) - 1) / 2
    return a.coma * (xy - c) / np.hypot(*c)


def simbias_seidel(pc, truth, a, layout, imagersize) -> np.ndarray:
    """simbias_true with, at every corner, the Seidel PSF at that point (coma and focus of LensPSF's field, no
    blending between the simulator's nodes): what psf-sim's model of the PSF leaves with the true parameters"""
    from rotstar_mrcal.optics.psf import wavefront_psf
    q = pc.corners.copy()
    j, i = np.nonzero(np.isfinite(q[..., 0]))
    J = grid_jacobian(truth, float(layout.pitch))[j, i]
    n = star_normals(J, np.array([layout.angle(k) for k in range(layout.nframes)]))
    c = (np.array(imagersize, float) - 1) / 2
    ks = []
    for p in q[j, i]:
        h = np.hypot(*(p - c)) / np.hypot(*c)
        ang = math.atan2(p[1] - c[1], p[0] - c[0])
        ks.append(wavefront_psf(Seidel(tilt=-a.coma * h, coma=a.coma * h, focus=a.focus * h * h, tilt_angle=ang,
                                       coma_angle=ang)))
    q[j, i] -= simulated_bias(psfbias._padded(ks), 4, n, q[j, i], pc.window[j, i], pc.prefilter_px)
    return q


def samples_from(model, layout, psf, a, dist, fs, mc):
    """coma_samples of the poses at distances dist (near, far), the same lens, npose and seed (renders cached)"""
    tag = f"g{a.gaussian:g}" if a.gaussian > 0 else f"c{a.coma:g}f{a.focus:g}" + (f"-tiled{a.tiled}" if a.tiled else "")
    tag += f"-d{dist[0]:g},{dist[1]:g}"
    xy, vec = [], []
    for i, rt in enumerate(simulate.random_poses(model, layout, a.npose, np.random.default_rng([3, a.seed]),
                                                 distance=dist)):
        rot, _ = render(model, layout, rt, psf, os.path.join(a.cache, f"{tag}-n{a.npose}-s{a.seed}-p{i}.npz"))
        rng = np.random.default_rng([5, a.seed, i])
        frames = simulate.expose(rot, gain=0.9, noise=0.01 * a.noise, shot=1e-4 * a.noise, bits=16,
                                 rng=rng).astype(np.float32)
        pc = detect_pose(frames, layout, full_scale=fs, check_motion=mc)
        jj, ii = np.nonzero(np.isfinite(pc.corners[..., 0]))
        x, v = coma_samples(frames, pc.corners[jj, ii], pc.window[jj, ii])
        xy.append(x)
        vec.append(v)
    return np.concatenate(xy), np.concatenate(vec)


def dataset_correction(poses, acc, extra=None):
    """psf-sim with the coma pooled over all poses (coma_samples of each, or extra (xy, vec)), appended to acc"""
    xy = np.concatenate([p[5][0] for p in poses] + ([] if extra is None else [extra[0]]))
    vec = np.concatenate([p[5][1] for p in poses] + ([] if extra is None else [extra[1]]))
    print(f"psf-sim-dataset: {len(xy)} corners show the coma", file=sys.stderr)
    for frames, pc, truth, view, tw, _ in poses:
        t0 = time.perf_counter()
        q = pc.corners.copy()
        jj, ii = np.nonzero(np.isfinite(q[..., 0]))
        q[jj, ii] = bias_correct(frames, q[jj, ii], pc.window[jj, ii], samples=(xy, vec))
        e = q - truth
        ok = view & np.isfinite(e).all(axis=-1) & (np.linalg.norm(e, axis=-1) <= MATCH_PX)
        for k, v in enumerate((truth[ok], e[ok], time.perf_counter() - t0, tw[ok])):
            acc[k].append(v)


def cpu_time(frames, layout, fs, refine: str, repeats: int = 3) -> float:
    """The least CPU time (s) of `repeats` detect_pose runs with REFINERS[refine]"""
    best = math.inf
    for _ in range(repeats):
        t0 = time.process_time()
        detect_pose(frames, layout, full_scale=fs, refine=REFINERS[refine])
        best = min(best, time.process_time() - t0)
    return best


def check_blur_map(path, coma, focus, imagersize=(1280, 800)):
    """Print the blur map's width and coma direction against the lens's true PSFs (module doc)"""
    t = read_table(path)
    lens = LensPSF(Seidel(coma=coma, focus=focus), imagersize)
    c = (np.array(imagersize) - 1) / 2
    normals = np.arange(16) * np.pi / 16
    truth = {}
    tw, ta = np.empty(len(t)), np.empty(len(t))
    for n, (x, y, *_, reach) in enumerate(t):
        key = (int(x // 8), int(y // 8), reach)  # (the lens's PSF changes little over 8 px)
        if key not in truth:
            e = psf_estimate(projected_moments(lens.local_kernel(x // 8 * 8 + 4, y // 8 * 8 + 4, 4), 4, normals,
                                               reach))
            truth[key] = (e.width[0], e.coma_angle[0])
        tw[n], ta[n] = truth[key]
    ratio = t[:, 2] / tw
    waves = coma * np.linalg.norm(t[:, :2] - c, axis=1) / np.hypot(*c)
    strong = waves > 0.5
    da = np.abs(np.degrees(np.angle(np.exp(1j * (np.radians(t[:, 8]) - ta)))))
    print(f"{len(t)} corners: width estimate / truth median {np.median(ratio):.3f} (5-95 % "
          f"{np.percentile(ratio, 5):.3f}-{np.percentile(ratio, 95):.3f}), within 10 %: {np.mean(abs(ratio - 1) < 0.1):.0%}")
    print(f"coma > 0.5 waves: {strong.sum()} corners, direction error median {np.median(da[strong]):.1f} deg, "
          f"within 15 deg: {np.mean(da[strong] < 15):.0%}")
    for lo, hi in ((0.5, 1.0), (1.0, 1.5), (1.5, 9)):
        m = (waves >= lo) & (waves < hi)
        if m.any():
            print(f"  {lo}-{hi} waves: {m.sum()} corners, median {np.median(da[m]):.1f} deg, within 15: {np.mean(da[m] < 15):.0%}")
    cell = (t[:, 0] // 128).astype(int) * 1000 + (t[:, 1] // 128).astype(int)
    errs = [abs(np.degrees(np.angle((t[m, 6] * np.exp(1j * (np.radians(t[m, 8]) - ta[m]))).mean())))
            for m in (strong & (cell == k) for k in np.unique(cell[strong]))]
    print(f"pooled in 128-px cells ({len(errs)}): direction error median {np.median(errs):.1f} deg, "
          f"max {np.max(errs):.1f}, within 15 deg: {np.mean(np.array(errs) < 15):.0%}")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--coma", type=float, default=1.5)
    p.add_argument("--focus", type=float, default=0.3)
    p.add_argument("--gaussian", type=float, default=0.0)
    p.add_argument("--npose", type=int, default=4)
    p.add_argument("--pose", type=int, default=None, help="only pose K of the --npose (e.g. for --supersample)")
    p.add_argument("--supersample", type=int, default=4,
                   help="sub-pixels per px of the renders (default 4; make demo renders at 2)")
    p.add_argument("--noise", type=float, default=1.0,
                   help="scale of the read noise (1 %%) and shot noise (1e-4); 0: noiseless frames, whose "
                        "pose-dependent error is the methods' own")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--cache", default="/tmp/rotstar-psfcheck-centred")
    p.add_argument("--tiled", type=int, default=0, metavar="PX",
                   help="render through the former piecewise-constant PSF (TiledPSF, PX-px tiles)")
    p.add_argument("--tap-floor", type=float, help="psfbias.TAP_FLOOR (0: every kernel tap)")
    p.add_argument("--star-fft", action="store_true", help="psfbias renders the local star by FFT (render_star_fft)")
    p.add_argument("--no-phase", action="store_true",
                   help="psf-sim simulates only the 12 nodes' biases, carried to the other corners by a smooth "
                        "field, not every corner's own sub-pixel phase and window on its node's star (psfbias.PHASE "
                        "False, the default before)")
    p.add_argument("--methods", default="symmetric,psf,saddle")
    p.add_argument("--distance", default="", help="near,far metres (default: random_poses' range)")
    p.add_argument("--coma-from", metavar="NEAR,FAR",
                   help="psf-sim-dataset: the coma pooled from the same lens's poses at this distance range "
                        "(as --distance) instead of these poses")
    p.add_argument("--no-display-maps", action="store_true",
                   help="detect_pose(check_motion=False): no per-frame display maps in the joint refinement")
    p.add_argument("--check-blur-map", metavar="CSV", help="compare a blur map with the lens's true PSFs")
    p.add_argument("--timing", action="store_true",
                   help="also the CPU time of detect_pose per pose, symmetric, psf and psf-sim "
                        "(the least of 3 runs each: psf-sim's kernels and tables are cached by then; "
                        "time a whole rotstar-detect run for what a user waits)")
    a = p.parse_args(argv)
    if a.check_blur_map:
        return check_blur_map(a.check_blur_map, a.coma, a.focus)
    os.makedirs(a.cache, exist_ok=True)
    model = simulate.preset_model("d435")
    layout = paper_layout()
    psf = a.gaussian if a.gaussian > 0 else LensPSF(Seidel(coma=a.coma, focus=a.focus), model.imagersize())
    tag = f"g{a.gaussian:g}" if a.gaussian > 0 else f"c{a.coma:g}f{a.focus:g}"
    if a.tiled and a.gaussian <= 0:
        psf, tag = TiledLens(psf, a.tiled), tag + f"-tiled{a.tiled}"
    if a.tap_floor is not None:
        psfbias.TAP_FLOOR = a.tap_floor
    if a.star_fft:
        psfbias.STAR_FFT = True
    if a.no_phase:
        psfbias.PHASE = False
    dist = tuple(float(v) for v in a.distance.split(",")) if a.distance else None
    rts = simulate.random_poses(model, layout, a.npose, np.random.default_rng([3, a.seed]), distance=dist)
    if dist:
        tag += f"-d{a.distance}"
    tag += f"-n{a.npose}"  # random_poses' poses depend on how many
    fs = float(simulate.full_scale_code(16))
    methods = a.methods.split(",")
    mc = not a.no_display_maps
    acc = {m: ([], [], [], []) for m in methods}  # positions, errors, seconds, true windows
    later = []  # psf-sim-dataset's poses
    if a.supersample != 4:
        tag += f"-ss{a.supersample}"
    for i, rt in enumerate(rts):
        if a.pose is not None and i != a.pose:
            continue
        t0 = time.perf_counter()
        rot, cb = render(model, layout, rt, psf, os.path.join(a.cache, f"{tag}-s{a.seed}-p{i}.npz"), a.supersample)
        print(f"pose {i}: rendered ({time.perf_counter() - t0:.0f} s)", file=sys.stderr)
        truth = simulate.true_corners(model, layout, rt)
        view = in_view(model, layout, rt)
        rng = np.random.default_rng([5, a.seed, i])

        def expose(img):
            return simulate.expose(img, gain=0.9, noise=0.01 * a.noise, shot=1e-4 * a.noise, bits=16, rng=rng)

        frames = expose(rot).astype(np.float32)
        if a.timing:
            print(f"pose {i}: CPU s per detection " + ", ".join(
                f"{m} {cpu_time(frames, layout, fs, m):.2f}" for m in ("symmetric", "psf", "psf-sim")))
        for m in methods:
            t0 = time.perf_counter()
            if m == "saddle":
                avg = averaged_captures(cb, expose, 8, lit_box(cb, 0.02))
                q = refine_by_window(lambda im, x, w: saddle_refine(im, x, win=w), avg,
                                     perturbed_start(truth, a.seed, i), true_windows(model, layout, rt))
            elif m.startswith("simbias-nodes"):  # simbias-nodes-S-N-D
                S, NN, D = (int(v) for v in m.split("-")[2:5])
                q = simbias_nodes(detect_pose(frames, layout, full_scale=fs, check_motion=mc), truth, psf, layout,
                                  S, NN, D)
            elif m in ("simbias-est", "simbias-truecoma"):  # psf-sim's model and scheme with the true geometry,
                # the coma estimated from the raw frames or the lens's own
                pc = detect_pose(frames, layout, full_scale=fs, check_motion=mc)
                q = pc.corners.copy()
                jj, ii = np.nonzero(np.isfinite(q[..., 0]))
                coma = {"samples": (q[jj, ii], true_coma(a, q[jj, ii], model.imagersize()))} \
                    if m == "simbias-truecoma" else {}
                q[jj, ii] = bias_correct(frames, q[jj, ii], pc.window[jj, ii],
                                         jac=grid_jacobian(truth, float(layout.pitch))[jj, ii],
                                         angles=np.array([layout.angle(k) for k in range(layout.nframes)]),
                                         lowpass_sigma=pc.prefilter_px, **coma)
            elif m == "simbias-seidel":
                q = simbias_seidel(detect_pose(frames, layout, full_scale=fs, check_motion=mc), truth, a, layout,
                                   model.imagersize())
            elif m == "simbias-true":
                q = simbias_true(detect_pose(frames, layout, full_scale=fs, check_motion=mc), truth, psf, layout)
            elif m.startswith("simbias-moments"):  # simbias-moments-L: clipped to L px (0: edgespread's reach)
                q = simbias_true(detect_pose(frames, layout, full_scale=fs, check_motion=mc), truth, psf, layout,
                                 float(m.split("-")[2]))
            elif m == "psf-sim-dataset":  # the symmetric fit now, the correction once every pose's coma is in
                pc = detect_pose(frames, layout, full_scale=fs, check_motion=mc)
                jj, ii = np.nonzero(np.isfinite(pc.corners[..., 0]))
                later.append((frames, pc, truth, view, true_windows(model, layout, rt),
                              coma_samples(frames, pc.corners[jj, ii], pc.window[jj, ii])))
                continue
            else:
                q = detect_pose(frames, layout, full_scale=fs, refine=REFINERS[m], check_motion=mc).corners
            dt = time.perf_counter() - t0
            e = q - truth
            ok = view & np.isfinite(e).all(axis=-1) & (np.linalg.norm(e, axis=-1) <= MATCH_PX)
            acc[m][0].append(truth[ok])
            acc[m][1].append(e[ok])
            acc[m][2].append(dt)
            acc[m][3].append(true_windows(model, layout, rt)[ok])
        print(f"pose {i}: windows {np.nanpercentile(true_windows(model, layout, rt), [5, 50, 95]).round(1)}",
              file=sys.stderr)
    if later:
        extra = None
        if a.coma_from:
            extra = samples_from(model, layout, psf, a, tuple(float(v) for v in a.coma_from.split(",")), fs, mc)
        dataset_correction(later, acc["psf-sim-dataset"], extra)
    print(f"{tag}, {a.npose} poses (seed {a.seed})" + (f", noise x {a.noise:g}" if a.noise != 1 else ""))
    for m in methods:
        pos, err = np.concatenate(acc[m][0]), np.concatenate(acc[m][1])
        rms = float(np.sqrt((err ** 2).sum(axis=1).mean()))
        print(f"  {m:10s} corners {len(err):5d}  RMS {rms:.4f} px  pose-dependent {pose_dependent(pos, err):.4f} px"
              f" (less a smooth field: {field_residual(pos, err):.4f})"
              f"  mean error ({err[:, 0].mean():+.4f}, {err[:, 1].mean():+.4f})  {np.mean(acc[m][2]):.2f} s/pose")
        w, e = np.concatenate(acc[m][3]), np.linalg.norm(err, axis=1)
        print("             by true window: " + "; ".join(
            f"{lo:g}-{hi:g} px: {(sel := (w >= lo) & (w < hi)).sum()} RMS {np.sqrt(np.mean(e[sel] ** 2)):.4f}"
            for lo, hi in ((0, 4), (4, 6), (6, 99)) if ((w >= lo) & (w < hi)).any()))


if __name__ == "__main__":
    main()

"""The paper's synthetic experiment (4.1): one configuration = one aberration at one tilt

SYNOPSIS

    >>> from rotstar_mrcal.synth.experiment import Protocol, quick_protocol, run_task
    >>> p = quick_protocol()
    >>> p.aberrations, p.noises, p.phis_deg
    (('spherical', 'coma'), (0.0, 4.0), (20, 50))
    >>> tiny = p.replace(alphas_deg=(0, 90), repeats=2, refiners=("symmetric",), patterns=("checkerboard",))
    >>> out = run_task(tiny, "spherical", 20, (0.0,))
    >>> out[0.0]["detections"].shape          # repeats, views, patterns, refiners, xy
    (2, 2, 1, 1, 2)

For one aberration and one tilt phi the board is shown at the 12 alpha
directions (views.py). For each view and pattern (patterns.py) the
noise-free frames are rendered once (imaging.py) through the aberration's
PSF, together with the gradients that give the Fisher information. Then,
for each noise level and each of `repeats` repetitions, every frame is
exposed with independent Gaussian noise and every refiner (refiners.py)
refines the corner from the truth perturbed by a uniform offset of up to
`perturb` pixels in x and y (the same start for every pattern and refiner
of one repeat and view, so the comparisons are paired), except the phase
refiner, which starts from the rotating star's symmetric corner of the same
repeat and view, as in the paper's real experiment (_phase_starts).

Fairness (the paper's rule): every pattern gets `captures` = 8 exposures.
The rotating star and the phase shifts show 8 frames, one exposure each;
the checkerboard and the 16-segment star show one frame, exposed 8 times
with independent noise and averaged (detect.baselines.average_frames).

Each refiner runs only on the patterns it applies to (refiners.applies: the
phase refiner on the phase pattern, the others on the stars); the other
cells of the detections stay NaN and the table leaves them out ("n/a").

Image values: dark + contrast * (blurred pattern) + N(0, sigma_n^2), in DN
(default 28 + 200 x, i.e. black 28, white 228), float, no quantisation or
saturation: the experiment isolates the PSF. What limits the phase shifts
besides the PSF and the noise is therefore left out: the display's gamma
(a mismatch makes the fringes non-sinusoidal, and the 4-step phase then
has a periodic error), saturation of the bright fringes, ambient light and
the 8-bit quantisation of the screen and the camera (rotstar-simulate and
the benchmark model those).

The repetitions of all views are tiled side by side into one mosaic per
pattern (tile T x T, T = 2 window + 10), so each refiner runs once on all
V x R corners (the refiners are vectorised over corners).

Aberrations (ABERRATIONS; amplitudes in waves, overridable): "none" is a
Gaussian PSF of sigma `gaussian_sigma` px (what prior work simulates), the
others Seidel wavefront PSFs (optics.psf) with default amplitudes chosen so
that every PSF puts 80% of its energy within ~2.8 px of its centroid, as the
paper's coma of 4 waves does at the default optics (F/2, 3 um pixels,
550 nm): the PSFs differ in shape, not in size.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import zlib

import numpy as np

from rotstar_mrcal.peers.checkerboard import average_frames
from rotstar_mrcal.optics.crlb import fisher_information
from rotstar_mrcal.optics.psf import Optics, gaussian_psf, wavefront_psf
from rotstar_mrcal.optics.wavefront import Seidel
from rotstar_mrcal.synth.patterns import PATTERNS, PHASE_PERIOD, pattern_frames
from rotstar_mrcal.synth.refiners import REFINERS, applies, refine
from rotstar_mrcal.synth.imaging import ViewRenderer
from rotstar_mrcal.synth.views import ALPHAS_DEG, PHIS_DEG, view_jacobian

ABERRATIONS = {
    # name: (Seidel term, default amplitude in waves); "none" is the Gaussian
    "none": (None, 0.0),
    "defocus": ("focus", 2.0),
    "spherical": ("spherical", 1.5),
    "coma": ("coma", 4.0),
    "astigmatism": ("astigmatism", 3.0),
}
SYMMETRIC = {"none": True, "defocus": True, "spherical": True, "coma": False, "astigmatism": True}


@dataclasses.dataclass(frozen=True)
class Protocol:
    """Every setting of a run of the experiment"""

    aberrations: tuple = ("spherical", "coma")
    noises: tuple = (0.0, 2.0, 6.0)  # sigma_n, DN
    phis_deg: tuple = PHIS_DEG
    alphas_deg: tuple = ALPHAS_DEG
    repeats: int = 50
    patterns: tuple = PATTERNS
    refiners: tuple = tuple(sorted(REFINERS))  # every refiner; alphabetical, the published tables' order
    window: int = 10  # half-window of every refiner but phase (detect.phase.HALF_WINDOW) and of the bound
    supersample: int = 4
    captures: int = 8
    perturb: float = 1.0
    dark: float = 28.0
    contrast: float = 200.0
    truth_offset: tuple = (0.3, 0.7)  # sub-pixel position of the corner in its tile
    field: tuple = (0.0, 0.0)  # normalised image point of the corner (0: optical axis)
    gaussian_sigma: float = 1.5
    amplitudes: tuple = ()  # ((name, waves), ...) overriding ABERRATIONS
    coma_angle_deg: float = 0.0  # direction of the comet's tail in the image
    phase_period: float = PHASE_PERIOD  # the phase pattern's fringe period, board units (= px head-on)
    optics: Optics = Optics()
    seed: int = 0

    def replace(self, **kw) -> "Protocol":
        return dataclasses.replace(self, **kw)

    @property
    def tile(self) -> int:
        return 2 * int(self.window) + 10

    @property
    def truth(self) -> np.ndarray:
        """The corner's position in its tile (pixel coordinates)"""
        return np.array((self.tile // 2 + self.truth_offset[0], self.tile // 2 + self.truth_offset[1]))

    def amplitude(self, aberration: str) -> float:
        return float(dict(self.amplitudes).get(aberration, ABERRATIONS[aberration][1]))

    def seidel(self, aberration: str) -> Seidel | None:
        term, _ = ABERRATIONS[aberration]
        if term is None:
            return None
        return Seidel(**{term: self.amplitude(aberration)}, coma_angle=math.radians(self.coma_angle_deg))

    def psf_spec(self, aberration: str) -> dict:
        s = self.seidel(aberration)
        if s is None:
            return {"kind": "gaussian", "sigma_px": self.gaussian_sigma}
        return {"kind": "seidel", "seidel": s.to_dict(), "optics": self.optics.to_dict()}

    def config_key(self, aberration: str, noise: float, phi_deg: float) -> str:
        """Cache key of one configuration: every setting its numbers depend on"""
        shared = {k: v for k, v in dataclasses.asdict(self).items()
                  if k not in ("aberrations", "noises", "phis_deg", "amplitudes", "optics",
                               "gaussian_sigma", "coma_angle_deg")}
        blob = json.dumps({"shared": shared, "psf": self.psf_spec(aberration), "noise": float(noise),
                           "phi": float(phi_deg), "version": 1}, sort_keys=True, default=list)
        h = hashlib.sha1(blob.encode()).hexdigest()[:12]
        return f"{aberration}-n{float(noise):g}-phi{float(phi_deg):g}-{h}"

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["optics"] = self.optics.to_dict()
        d["psf"] = {a: self.psf_spec(a) for a in self.aberrations}
        return d


def quick_protocol(**kw) -> Protocol:
    """The --quick run: 2 tilts, 6 directions, 4 repeats, spherical and coma, noise 0 and 4 DN"""
    p = Protocol(noises=(0.0, 4.0), phis_deg=(20, 50), alphas_deg=tuple(range(0, 180, 30)), repeats=4)
    return p.replace(**kw)


def psf_kernel(protocol: Protocol, aberration: str) -> np.ndarray:
    """The PSF of an aberration at the protocol's supersampling (odd, centred, unit sum)"""
    s = protocol.seidel(aberration)
    if s is None:
        return gaussian_psf(protocol.gaussian_sigma, protocol.supersample)
    return wavefront_psf(s, protocol.optics, protocol.supersample)


def _rng(*key) -> np.random.Generator:
    return np.random.default_rng([int(k) for k in key])


def _name_id(name: str) -> int:
    return zlib.crc32(name.encode())


def render_views(protocol: Protocol, aberration: str, phi_deg: float):
    """Noise-free frames and Fisher information of every view and pattern at one tilt

    Returns (frames, fisher): frames[pattern] (V, K, T, T) in DN, fisher
    (V, P, 2, 2) per unit noise sigma (the information of all the pattern's
    exposures within the window; scale by 1 / sigma_n^2).
    """
    p = protocol
    renderer = ViewRenderer(psf_kernel(p, aberration), p.supersample, p.tile)
    truth = p.truth
    c = np.arange(p.tile)
    win = (np.abs(c[None, :] - truth[0]) <= p.window) & (np.abs(c[:, None] - truth[1]) <= p.window)
    frames = {name: [] for name in p.patterns}
    fisher = np.zeros((len(p.alphas_deg), len(p.patterns), 2, 2))
    for v, alpha in enumerate(p.alphas_deg):
        J = view_jacobian(math.radians(phi_deg), math.radians(alpha), p.field)
        for j, name in enumerate(p.patterns):
            stars = [st.mapped(J) for st in pattern_frames(name, p.phase_period)]
            img, grad = renderer(stars, truth)
            frames[name].append(p.dark + p.contrast * img)
            per_frame = p.captures / len(stars)  # exposures averaged into each frame
            g = p.contrast * grad[:, win]  # (K, M, 2)
            fisher[v, j] = per_frame * fisher_information(g.reshape(-1, 2), 1.0)
    return {k: np.stack(v) for k, v in frames.items()}, fisher


def _pattern_order(patterns) -> list[int]:
    """Indices of the patterns, the phase pattern last (it starts from the rotating star's corners)"""
    return [j for j, n in enumerate(patterns) if n != "phase"] + [j for j, n in enumerate(patterns) if n == "phase"]


def _phase_starts(p: Protocol, det: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Starts of the phase refiner (V, R, 2) in mosaic coordinates: the rotating star's symmetric corners

    As in the paper's real experiment ("the initial feature positions are
    provided by our method"): the phase refiner starts from the corner the
    symmetric refinement found on the rotating star in the same repeat and
    view, so a PSF that moves every detection (coma moves it 2-3 px from the
    paraxial point) does not push the phase-plane solution out of its 7 x 7
    px window. Where that corner failed, or the protocol lacks the rotating
    star or the symmetric refinement, the common start (truth + perturbation).
    """
    V, R = starts.shape[:2]
    offs = np.stack((np.arange(V * R) * p.tile, np.zeros(V * R)), axis=-1).reshape(V, R, 2)
    s = starts
    if "rotstar" in p.patterns and "symmetric" in p.refiners:
        q = np.moveaxis(det[:, :, p.patterns.index("rotstar"), p.refiners.index("symmetric")], 0, 1)  # (V, R, 2)
        s = np.where(np.isfinite(q).all(axis=-1, keepdims=True), q, starts)
    return s + offs


def run_task(protocol: Protocol, aberration: str, phi_deg: float, noises) -> dict:
    """Detections of every repeat, view, pattern and refiner, for each noise level

    Returns {noise: {"detections": (R, V, P, F, 2) float32 image coordinates
    of the tile, "truth": (2,), "fisher": (V, P, 2, 2) per unit sigma}}.
    """
    p = protocol
    frames, fisher = render_views(p, aberration, phi_deg)
    V, R, T = len(p.alphas_deg), int(p.repeats), p.tile
    truth = p.truth
    # tile (v, r) of the mosaic is column block v * R + r
    offs = np.stack((np.arange(V * R) * T, np.zeros(V * R)), axis=-1).reshape(V, R, 2)
    starts = truth + _rng(p.seed, 1, int(round(phi_deg * 1000))).uniform(-p.perturb, p.perturb, (V, R, 2))
    out = {}
    for noise in noises:
        rng = _rng(p.seed, 2, _name_id(aberration), int(round(noise * 1000)), int(round(phi_deg * 1000)))
        det = np.full((R, V, len(p.patterns), len(p.refiners), 2), np.nan, np.float32)
        for j in _pattern_order(p.patterns):
            name = p.patterns[j]
            f = frames[name]  # (V, K, T, T)
            K = f.shape[1]
            mosaic = np.repeat(f[:, None], R, axis=1)  # (V, R, K, T, T)
            mosaic = np.moveaxis(mosaic, 2, 0).transpose(0, 3, 1, 2, 4).reshape(K, T, V * R * T)
            per_frame = max(1, p.captures // K)
            if noise > 0:
                noisy = np.stack([average_frames(mosaic[k] + rng.normal(0.0, noise, (per_frame,) + mosaic.shape[1:]))
                                  for k in range(K)])
            else:
                noisy = mosaic.astype(np.float32)
            s0 = (_phase_starts(p, det, starts) if name == "phase" else starts + offs).reshape(-1, 2)
            for i, r in enumerate(p.refiners):
                if not applies(name, r):
                    continue  # n/a: stays NaN
                q = refine(r, noisy, s0, p.window).reshape(V, R, 2) - offs
                det[:, :, j, i] = np.moveaxis(q, 1, 0)
        out[float(noise)] = {"detections": det, "truth": truth, "fisher": fisher}
    return out

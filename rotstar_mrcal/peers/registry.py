"""Every corner method and every corner refiner, listed once

SYNOPSIS

    >>> from rotstar_mrcal.peers.registry import METHODS, REFINERS, method_names
    >>> list(METHODS)[:3]
    ['rotstar', 'rotstar-weighted', 'opencv-sb']
    >>> METHODS["saddle"].needs, METHODS["saddle"].start
    ('checkerboard', 'rotstar')
    >>> method_names(needs=("rotstar", "checkerboard"), start="own")
    ['rotstar', 'rotstar-weighted', 'opencv-sb', 'opencv-classic', 'rotstar-psf', 'rotstar-psf-sim']
    >>> list(REFINERS)
    ['symmetric', 'psf', 'psf-sim', 'opencv', 'saddle']

A *method* turns the images of one pose into labelled corners (ny, nx, 2)
(mrcal order, NaN = missing) or no board. Its entry says:

    needs   'rotstar'       the rotating-star frames
            'checkerboard'  the checkerboard frame (the benchmark and the demo
                            give it the mean of 8 captures, the paper's
                            fairness rule)
            'square'        a square N x N checkerboard as an image file
                            (mrgingham finds only square boards)
            'phase'         the phase-shift frames (rotstar-pattern --paper-sequence)
            'star'          the star frame of Schops et al. (the same)
    start   'own'           it finds the board itself
            'rotstar'       it refines rotstar's labelled corners, each in
                            rotstar's per-corner window (PoseImages.start /
                            start_window, or rotstar's own detection)
    relabel it numbers its board from whichever corner it likes (no
            orientation marker): a caller relabels it to a reference
    variant_of  the same corners as another method (rotstar-weighted: rotstar's
            corners with per-corner weights)
    demo    part of `make demo`'s comparison (the benchmark runs them all)

    method(PoseImages(...)) -> Found(corners, weights, why)

A *refiner* moves given start corners (N, 2) on given frames (K, H, W) to
the corner: rotstar-detect --refine and rotstar-synth's experiment.

    REFINERS[name].refine(frames, starts, window) -> (N, 2), NaN = failed

Adding a method is one entry in METHODS plus its function; rotstar-detect,
rotstar-crossval, rotstar-synth, the benchmark and the demo read these two
tables.
"""

from __future__ import annotations

import dataclasses
from typing import Callable

import numpy as np

from rotstar_mrcal.pattern.layout import Layout
from rotstar_mrcal.detect.pipeline import correct_with_dataset, detect_pose
from rotstar_mrcal.detect.edgespread import psf_correct
from rotstar_mrcal.detect.psfbias import bias_correct, coma_samples
from rotstar_mrcal.detect.refine import (PREFILTER_SIGMA, SYMMETRIC, Refiner, lowpass_for, prefilter,
                                         refine_symmetric)
from rotstar_mrcal.peers import checkerboard as baselines
from rotstar_mrcal.peers.checkerboard import (
    mrgingham_detect, opencv_find_chessboard, opencv_subpix, refine_by_window, saddle_refine,
)
from rotstar_mrcal.peers.phase import phase_corners


# ---------------------------------------------------------------------------
# refiners: start corners on frames -> corners
# ---------------------------------------------------------------------------
def _per_frame_mean(fn, frames, starts, window) -> np.ndarray:
    """fn(image, starts, win) on every frame from the same starts; the mean (NaN in any frame -> NaN)"""
    frames = np.asarray(frames, np.float32)
    frames = frames[None] if frames.ndim == 2 else frames
    starts = np.asarray(starts, float).reshape(-1, 2)
    return np.stack([fn(f, starts, win=int(window)) for f in frames]).mean(axis=0)


def refine_opencv(frames, starts, window=5) -> np.ndarray:
    """cv2.cornerSubPix (detect.baselines.opencv_subpix) on each frame, half window int(window); the mean"""
    return _per_frame_mean(opencv_subpix, frames, starts, window)


def refine_saddle(frames, starts, window=5) -> np.ndarray:
    """The Lucchese-Mitra saddle fit (detect.baselines.saddle_refine) on each frame; the mean"""
    return _per_frame_mean(saddle_refine, frames, starts, window)


def _symmetric_then(correct, frames, starts, window, lowpass=None) -> np.ndarray:
    """The symmetric fit on the frames low-passed by `lowpass` px (None: refine.lowpass_for the windows, as
    detect_pose), then correct(frames, corners, windows)"""
    frames = np.asarray(frames, np.float32)
    frames = frames[None] if frames.ndim == 2 else frames
    w = np.broadcast_to(np.asarray(window, float), (len(np.asarray(starts).reshape(-1, 2)),))
    q = refine_symmetric(prefilter(frames, lowpass_for(w) if lowpass is None else lowpass), starts, w)
    return correct(frames, q, w)


def refine_psf(frames, starts, window=10.0) -> np.ndarray:
    """The symmetric fit on the low-passed frames, then each corner moved to the light's centroid (psf_correct)"""
    return _symmetric_then(psf_correct, frames, starts, window, PREFILTER_SIGMA)


PSF = Refiner("psf", "rotstar", "the symmetric fit, then each corner moved to where its 16 edges, each at its "
              "line-spread function's mean, meet: the light's centroid (detect.edgespread)", refine_psf,
              correct=psf_correct)


def refine_psf_sim(frames, starts, window=10.0) -> np.ndarray:
    """The symmetric fit on the low-passed frames less its bias simulated through the local PSF (bias_correct)"""
    return _symmetric_then(bias_correct, frames, starts, window)


PSF_SIM = Refiner("psf-sim", "rotstar", "the symmetric fit less its bias under the local PSF: the same fit run on "
                  "the local star rendered through the Seidel coma that the edges' third moments show "
                  "(detect.psfbias)", refine_psf_sim, correct=bias_correct, samples=coma_samples)


REFINERS = {r.name: r for r in (
    SYMMETRIC,
    PSF,
    PSF_SIM,
    Refiner("opencv", "checkerboard", "cv2.cornerSubPix (Forstner); on several frames, the mean of each frame's",
            refine_opencv),
    Refiner("saddle", "checkerboard", "Lucchese-Mitra quadratic saddle fit; on several frames, the mean",
            refine_saddle),
)}


def refiner(name: str) -> Refiner:
    """REFINERS[name], or a ValueError that lists the known ones"""
    try:
        return REFINERS[name]
    except KeyError:
        raise ValueError(f"unknown refiner {name!r}; known: {', '.join(REFINERS)}") from None


# ---------------------------------------------------------------------------
# methods: the images of one pose -> labelled corners
# ---------------------------------------------------------------------------
@dataclasses.dataclass
class PoseImages:
    """What a method may look at for one pose (fields a method does not need may be None)"""

    layout: Layout  # the board the method looks for (the square one for needs='square')
    full_scale: float  # the images' full-scale value (255, 65535, ...)
    frames: np.ndarray | None = None  # (nframes, H, W) rotating-star frames
    identity: np.ndarray | None = None  # (nidentity, H, W) identity frames, when the pattern has them
    checkerboard: np.ndarray | None = None  # (H, W) the checkerboard frame (float: an average)
    phase: np.ndarray | None = None  # (2, 4, H, W) the phase shifts along x then y, steps 0..3
    star: np.ndarray | None = None  # (H, W) the star frame
    png: str | None = None  # the board as an image file, for methods that are programs (mrgingham)
    start: np.ndarray | None = None  # (ny, nx, 2) start of start='rotstar' methods (default: rotstar's corners)
    start_window: np.ndarray | None = None  # (ny, nx) their half-windows, px (default: rotstar's windows)
    window: float = 10.0  # rotstar's refinement half-window cap, px
    detection: object = None  # rotstar's PoseCorners, computed on first use (rotstar_detection)


@dataclasses.dataclass
class Found:
    """One method's corners of one pose"""

    corners: np.ndarray | None  # (ny, nx, 2) or None: no board
    weights: np.ndarray | None = None  # (ny, nx) or None
    why: str = ""  # why there is no board
    shifts: object = None  # rotstar's detect.display.FrameShifts of the pose (the dataset's motion check)
    reasons: np.ndarray | None = None  # (ny, nx) str: why a corner is NaN ('' where found), when the method says
    pose: object = None  # rotstar's detect.pipeline.PoseCorners, for a method whose refiner pools a dataset (pooled)


def rotstar_detection(p: PoseImages):
    """detect_pose on p.frames (default options), computed once per PoseImages"""
    if p.detection is None:
        p.detection = detect_pose(np.asarray(p.frames, np.float32), p.layout, full_scale=p.full_scale,
                                  window=p.window, identity=p.identity)
    return p.detection


def _rotstar(p: PoseImages) -> Found:
    r = rotstar_detection(p)
    return Found(r.corners if r.found else None, None, r.error, r.shifts)


def _rotstar_refined(refine: Refiner):
    """The method: detect_pose with this refiner in place of the symmetric fit"""
    def run(p: PoseImages) -> Found:
        r = detect_pose(np.asarray(p.frames, np.float32), p.layout, full_scale=p.full_scale, window=p.window,
                        identity=p.identity, refine=refine)
        pooled = refine.pools and r.found
        return Found(r.corners if r.found else None, None, r.error, r.shifts, pose=r if pooled else None)
    return run


def _rotstar_weighted(p: PoseImages) -> Found:
    r = rotstar_detection(p)
    return Found(r.corners if r.found else None, r.weights() if r.found else None, r.error, r.shifts)


def _finder(how: str, what: str):
    def run(p: PoseImages) -> Found:
        if p.checkerboard is None:
            return Found(None, None, "no checkerboard frame")
        c = opencv_find_chessboard(np.asarray(p.checkerboard, np.float32), p.layout.nx, p.layout.ny,
                                   p.full_scale, method=how)
        return Found(c, None, "" if c is not None else f"{what} found no board")

    return run


def _start(p: PoseImages):
    """(start corners, their half-windows) of a start='rotstar' method, or a Found saying why there are none"""
    if p.start is not None:
        return p.start, p.start_window
    if p.frames is None:
        return Found(None, None, "no start (rotstar found no board)")
    r = rotstar_detection(p)
    if not r.found:
        return Found(None, None, f"no start (rotstar: {r.error})")
    return r.corners, r.window


def _from_rotstar(fn_name: str):
    def run(p: PoseImages) -> Found:
        if p.checkerboard is None:
            return Found(None, None, "no checkerboard frame")
        start = _start(p)
        if isinstance(start, Found):
            return start
        fn = getattr(baselines, fn_name)
        return Found(baselines.refine_by_window(lambda im, x, w: fn(im, x, win=w),
                                                np.asarray(p.checkerboard, np.float32), *start))

    return run


def _phase(p: PoseImages, saturation: str = "reject") -> Found:
    """detect.phase.phase_corners from rotstar's corners (the paper's phase-shift baseline)

    saturation: 'reject' drops a corner whose phase window holds a clipped
    value; 'keep' fits the clipped values as they are (the paper's pipeline).
    """
    if p.phase is None:
        return Found(None, None, "no phase-shift frames")
    if not p.layout.phase:
        return Found(None, None, "the pattern has no phase-shift frames")
    start = _start(p)
    if isinstance(start, Found):
        return start
    r = phase_corners(p.phase, start[0], p.layout.corner_phase(), p.full_scale, saturation=saturation)
    if not np.isfinite(r.corners).all(axis=-1).any():
        return Found(None, None, "no corner: " + reason_counts(r.reason), reasons=r.reason)
    return Found(r.corners, None, reasons=r.reason)


def _star(p: PoseImages) -> Found:
    """The symmetric refinement (Eq. 1) on the one star frame, from rotstar's corners in rotstar's windows"""
    if p.star is None:
        return Found(None, None, "no star frame")
    start = _start(p)
    if isinstance(start, Found):
        return start
    return Found(refine_by_window(lambda im, x, w: refine_symmetric(im[None], x, w),
                                 np.asarray(p.star, np.float32), *start))


def reason_counts(reason) -> str:
    """'3 saturated: ..., 1 window leaves the image' from per-corner reasons ('' = found)

    >>> reason_counts(np.array(["", "low", "low", "far"], dtype=object))
    '2 low, 1 far'
    """
    r = [x for x in np.asarray(reason, dtype=object).ravel() if x]
    names, counts = np.unique(np.array(r, dtype=str), return_counts=True) if r else ([], [])
    order = np.argsort(-np.asarray(counts), kind="stable")
    return ", ".join(f"{counts[i]} {names[i]}" for i in order)


def _mrgingham(p: PoseImages, *args) -> Found:
    if p.png is None:
        return Found(None, None, "no square checkerboard image")
    c = mrgingham_detect([p.png], p.layout.nx, jobs=1, extra_args=args)[p.png]
    return Found(c, None, "" if c is not None else "mrgingham found no board")


@dataclasses.dataclass(frozen=True)
class Method:
    name: str
    title: str  # the name in the benchmark's tables
    needs: str  # 'rotstar' | 'checkerboard' | 'square' | 'phase' | 'star'
    start: str  # 'own' | 'rotstar'
    description: str  # one line
    run: Callable  # run(PoseImages, *args) -> Found
    args: tuple = ()  # more arguments of run (a program's options)
    relabel: bool = False  # numbers its board up to the grid's symmetries only
    variant_of: str = ""  # gives the corners of that method (with weights)
    detail: str = ""  # settings worth a word in a table
    demo: bool = True  # part of make demo's comparison
    refiner: Refiner | None = None  # rotstar's refiner in place of the symmetric fit (its run: _rotstar_refined)

    @property
    def peer(self) -> bool:
        """A peer's method (another pattern's frames), not one of rotstar's own (the rotating-star frames)

        >>> METHODS["saddle"].peer, METHODS["rotstar-psf-sim"].peer
        (True, False)
        """
        return self.needs != "rotstar"

    def __call__(self, p: PoseImages) -> Found:
        return self.run(p, *self.args)


METHODS = {m.name: m for m in (
    Method("rotstar", "rotstar (symmetric)", "rotstar", "own",
           "rotating-star frames, symmetric refinement (rotstar-detect)", _rotstar),
    Method("rotstar-weighted", "rotstar, weighted (--weights)", "rotstar", "own",
           "the same, with per-corner weights 1/sigma (rotstar-detect --weights)", _rotstar_weighted,
           variant_of="rotstar"),
    Method("opencv-sb", "OpenCV findChessboardCornersSB (ACCURACY)", "checkerboard", "own",
           "checkerboard frame, cv2.findChessboardCornersSB + CALIB_CB_ACCURACY",
           _finder("sb", "findChessboardCornersSB"), relabel=True),
    Method("opencv-classic", "OpenCV findChessboardCorners + cornerSubPix", "checkerboard", "own",
           "checkerboard frame, cv2.findChessboardCorners, then cv2.cornerSubPix (win 5)",
           _finder("classic", "findChessboardCorners"), relabel=True, detail="win 5", demo=False),
    Method("cornersubpix", "cornerSubPix from rotstar's corners", "checkerboard", "rotstar",
           "checkerboard frame, cv2.cornerSubPix from rotstar's corners", _from_rotstar("opencv_subpix")),
    Method("saddle", "saddle fit (Lucchese-Mitra)", "checkerboard", "rotstar",
           "checkerboard frame, Lucchese-Mitra saddle fit from rotstar's corners", _from_rotstar("saddle_refine")),
    Method("phase", "phase shifting (4-step, phase planes)", "phase", "rotstar",
           "phase-shift frames along x and y: where both phases take the corner's, planes fitted in 7x7 px about "
           "rotstar's corners; a corner with a clipped value in its window is rejected", _phase,
           detail="half-window 3"),
    Method("phase-keep", "phase shifting, clipped values kept", "phase", "rotstar",
           "the same, fitting clipped values as they are (the paper's pipeline: saturation hurts, not removes)",
           _phase, ("keep",), detail="half-window 3"),
    Method("star", "star (Schops et al.), symmetric refinement", "star", "rotstar",
           "star frame, the symmetric refinement (Eq. 1) on the one frame from rotstar's corners, rotstar's window",
           _star),
    Method("mrgingham", "mrgingham", "square", "own", "square checkerboard, mrgingham", _mrgingham, relabel=True),
    Method("mrgingham-noclahe", "mrgingham --noclahe", "square", "own",
           "square checkerboard, mrgingham --noclahe (no CLAHE equalisation)", _mrgingham, ("--noclahe",),
           relabel=True, demo=False),
    Method("rotstar-psf", "rotstar, PSF-aware (centroid of the light)", "rotstar", "own",
           "rotating-star frames, the symmetric fit moved to where the edges' line-spread means meet "
           "(rotstar-detect --refine psf)", _rotstar_refined(PSF), demo=False, refiner=PSF),
    Method("rotstar-psf-sim", "rotstar, less the bias simulated through the local PSF", "rotstar", "own",
           "rotating-star frames, the symmetric fit less its offset from the light's centroid, simulated on the "
           "local star through the coma the edges show, pooled over a dataset's poses (rotstar-detect --refine psf-sim)",
           _rotstar_refined(PSF_SIM), refiner=PSF_SIM),
)}


def method_names(needs=None, start=None, demo=None, variants: bool = True) -> list[str]:
    """The names of the methods that match, in the registry's order

    needs: one value or a collection of them; variants=False leaves out the
    methods that give another method's corners.
    """
    needs = (needs,) if isinstance(needs, str) else needs
    return [n for n, m in METHODS.items()
            if (needs is None or m.needs in needs) and (start is None or m.start == start)
            and (demo is None or m.demo == demo) and (variants or not m.variant_of)]


def pooled(name: str, layout: Layout, found: list[Found]) -> list[Found]:
    """One method's Found on every pose of a dataset, as rotstar-detect gives them on that dataset

    A method whose refiner pools its measurements over the poses (psf-sim:
    the lens's coma) corrects every pose again with the pool
    (pipeline.correct_with_dataset); any other method's are returned as they
    are. The benchmark's and the demo's per-pose runs of such a method are
    its single-pose form; a caller with a dataset's poses passes them here.

    >>> pooled("saddle", None, [Found(None)])[0].why
    ''
    """
    refine = METHODS[name].refiner if name in METHODS else None
    if refine is None or not refine.pools:
        return found
    poses = [f.pose for f in found if f.pose is not None and f.corners is not None]
    correct_with_dataset(layout, poses, refine)  # in place: each Found's pose holds its corners
    return [dataclasses.replace(f, corners=f.pose.corners) if f.pose is not None and f.corners is not None else f
            for f in found]


def method(name: str) -> Method:
    """METHODS[name], or a ValueError that lists the known ones"""
    try:
        return METHODS[name]
    except KeyError:
        raise ValueError(f"unknown method {name!r}; known: {', '.join(METHODS)}") from None


def description(name: str) -> str:
    """The one-line description of a method, '' for a name that is not one (a user's --set)"""
    return METHODS[name].description if name in METHODS else ""

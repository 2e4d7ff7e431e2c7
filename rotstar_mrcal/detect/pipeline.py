"""One pose: recorded frames in, labelled sub-pixel corners out

SYNOPSIS

    from rotstar_mrcal.dataset import open_dataset
    from rotstar_mrcal.detect.pipeline import detect_pose
    ds = open_dataset("seq")
    pose = ds.load("pose000")
    result = detect_pose(pose.rotstar, ds.layout, full_scale=pose.full_scale,
                         checkerboard=pose.checkerboard)
    # another refiner, as a value: detect_pose(..., refine=REFINERS["opencv"]) (peers.registry)
    result.corners      # (ny, nx, 2), NaN where a corner was rejected
    result.error        # '' or the one-line reason the board was skipped

The stages (paper 3.2-3.3): response map -> element boundaries -> rough
corners -> grid indexing and orientation -> refinement; with identity frames
(issue 13) the elements are found and named by their identity codes instead
of the response map and the element graph (elements.py: by_identity,
by_graph), so that boards partly out of view give the corners in view; with the checks that
name what went wrong: exposure, the border bands' colour frame by frame
(sequence.py: frames out of order), the element count (too small, hidden,
out of view), the stars' angles (indexing.frame_angles: order, mirror), and
the per-frame display maps and motion (display_offsets.py). Each stage is a pure
function in its own module; this one strings them together and turns their
failures into a reason. A board whose labelling is not certain is never
returned: it is skipped with the reason.

Where the refinement starts: the paper's rough corner (the point nearest to
the fitted checker lines of all frames) for elements whose inscribed square
has a half-size of LARGE_ELEMENT px or more, where perspective biases the
element's centroid; the centroid of the element boundary for smaller ones,
where it is the better start (measured on simulated D435 views with 10-14 px
elements: centroid 0.1 px median error, curve intersection 0.3 px, both well
inside the refinement's reach and giving identical refined corners).

The refinement window is capped per corner at 0.65 x the half-side of the
largest square inside the element's boundary (projected by the labelled
grid's local homography, elements.grid_windows), so that the symmetric window
never reaches the border band or the neighbouring elements (whose crossings
are centres of symmetry too, and would attract the corner).

The symmetric refinement runs on the frames low-passed by a Gaussian of
PREFILTER_SIGMA px (prefilter). A star blurred by an asymmetric PSF (coma)
is symmetric about no point; the symmetric fit weighs every spatial
frequency of the edges, and the high ones, whose phase the PSF's skew moves
most, pull it toward the PSF's peak, away from the light's centroid (where
the true model puts the corner: the phase of the low frequencies follows the
centroid). Low-passing weighs the low frequencies more. Measured on
simulated D435 views (make demo's lens: coma 1.5 and focus 0.3 waves at the
image corners; the corner error against the truth, RMS over two views):
0.036 px without, 0.021 px with sigma 1, 0.0175 px with sigma 1.5; with a
Gaussian PSF of 1 px, 0.0044 / 0.0042 / 0.0047 px, and of 0.5 px (edges
close to aliasing) 0.0059 / 0.0036 / 0.0039 px; at three times the read
noise the same order. Sigma 1 is never worse in these cases. A symmetric
filter keeps the centre of a symmetric image where it is, so an ideal view
gives the same corner. Small elements are the exception: their windows end
a pixel or two from the border band, and a wider blur brings the band's
perspective-distorted (not point-symmetric) edge into the window (half-size
D435 views, half-windows of 2 px: largest error 0.032 px without, 0.078 px
with sigma 1, 0.038 px with 0.5); so sigma is at most PREFILTER_PER_WINDOW
of the pose's median half-window.
"""

from __future__ import annotations

import dataclasses
import re

import cv2
import numpy as np

from rotstar_mrcal.pattern.layout import Layout
from rotstar_mrcal.detect.consistency import refined_consistency
from rotstar_mrcal.detect.display_offsets import (
    MAX_MOTION, FrameShifts, frame_shifts, grid_homography, homography_jacobian, image_displacement,
)
from rotstar_mrcal.detect.edgespread import BLUR_FIELDS, blur_columns
from rotstar_mrcal.detect.elements import by_graph, by_identity
from rotstar_mrcal.detect.refine import (PREFILTER_SIGMA, SYMMETRIC, Refiner, lowpass_for, prefilter,
                                         refine_each_frame, symmetric_refine)
from rotstar_mrcal.detect.response import pixel_noise
from rotstar_mrcal.detect.sequence import check_band_parity


@dataclasses.dataclass
class PoseCorners:
    corners: np.ndarray  # (ny, nx, 2) mrcal image coordinates, NaN = missing
    error: str = ""  # why the whole board was skipped, or ''
    reasons: np.ndarray | None = None  # (ny, nx) why single corners are missing
    sigma: np.ndarray | None = None  # (ny, nx) rms residual of the refinement
    cov: np.ndarray | None = None  # (ny, nx, 2, 2) corner covariance estimate, px^2
    window: np.ndarray | None = None  # (ny, nx) refinement half-window used
    motion_px: float = 0.0  # frame-to-frame disagreement that the display maps do not explain, px
    shifts: FrameShifts | None = None  # per-frame display maps of this pose (symmetric refinement)
    unplaced: list | None = None  # why, for each element seen whose identity was not read
    blur: np.ndarray | None = None  # (ny, nx, len(BLUR_FIELDS)) the local PSF per corner (detect_pose(blur_map=True))
    prefilter_px: float = 0.0  # the Gaussian low-pass (px) the symmetric refinement ran on
    samples: tuple | None = None  # what refine.samples measured on the pose (image coordinates), or None
    correction: np.ndarray | None = None  # (ny, nx, 2) what refine.correct added to the symmetric fit's corners

    @property
    def found(self) -> bool:
        return not self.error

    @property
    def n_valid(self) -> int:
        return int(np.isfinite(self.corners[..., 0]).sum())

    def missing_summary(self) -> str:
        """Why corners are missing, in a few words

        >>> r = PoseCorners(np.full((1, 5, 2), np.nan), reasons=np.array([["", "", "", "a (3 px)", "a (5 px)"]], object),
        ...                 unplaced=["identity unreadable: 5 white frames"])
        >>> r.corners[0, :1] = 1.0
        >>> r.missing_summary()
        '1 not in view or hidden, 2 dropped (2 a), 1 identity not read'
        """
        missing = ~np.isfinite(self.corners[..., 0])
        why = self.reasons[missing] if self.reasons is not None else np.zeros(0, object)
        named = [re.sub(r" \(.*\)$", "", str(w)) for w in why if w]
        out = []
        unnamed = int(missing.sum()) - len(named) - len(self.unplaced or [])
        if unnamed > 0:
            out.append(f"{unnamed} not in view or hidden")
        if named:
            kinds, counts = np.unique(named, return_counts=True)
            top = ", ".join(f"{c} {k}" for k, c in sorted(zip(kinds, counts), key=lambda kc: -kc[1])[:2])
            out.append(f"{len(named)} dropped ({top})")
        if self.unplaced:
            out.append(f"{len(self.unplaced)} identity not read")
        return ", ".join(out)

    def weights(self) -> np.ndarray:
        """(ny, nx) 1/sigma per corner from the refinement covariance, median 1

        sigma is the RMS of the covariance's two principal standard
        deviations. This is mrcal's weight column (rotstar-detect --weights):
        relative only, the covariance underestimates the real error (see
        doc/detector.md). Without a covariance all weights are 1.
        """
        if self.cov is None:
            return np.ones(self.corners.shape[:2])
        w = 1 / np.sqrt(np.trace(self.cov, axis1=-2, axis2=-1) / 2)
        med = np.nanmedian(w) if np.isfinite(w).any() else np.nan
        return w / med if np.isfinite(med) and med > 0 else np.ones_like(w)


def _fail(layout: Layout, why: str) -> PoseCorners:
    return PoseCorners(np.full((layout.ny, layout.nx, 2), np.nan), error=why)


MIN_CONTRAST_NOISE = 10.0  # darkness: the frames' contrast against their own noise (pure noise: ~5)
MIN_LEVELS = 8.0  # ... and against the quantisation: grey levels between dark and bright


def check_exposure(frames: np.ndarray, full_scale: float) -> str:
    """'' or why the frames cannot hold a board (dark, saturated, static)

    Darkness is judged on the data, not on the container's full scale (10-bit
    values stored unscaled in a 16-bit PNG are fine): the contrast between the
    0.5th and 99.5th percentiles must be MIN_CONTRAST_NOISE times the noise
    (robust sigma of neighbouring-pixel differences) and MIN_LEVELS grey levels.
    """
    sub = frames[:, ::4, ::4]
    sat = float(np.mean(sub >= full_scale))
    if sat > 0.5:
        return f"saturated ({sat:.0%} of the pixels at full scale)"
    lo, hi = (float(v) for v in np.percentile(sub, [0.5, 99.5]))
    noise = pixel_noise(frames)
    if hi - lo < max(MIN_CONTRAST_NOISE * noise, MIN_LEVELS):
        what = "all dark" if hi < 0.25 * full_scale else "too noisy"
        return (f"{what} (no contrast above the noise: 0.5-99.5th percentiles {lo:.0f}-{hi:.0f} of "
                f"{full_scale:.0f}, noise {noise:.1f})")
    return ""


def per_frame_corners(frames: np.ndarray, corners: np.ndarray, window: np.ndarray, ok: np.ndarray,
                      n_corners: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """(indices (n,), corners (nframes, n, 2)): each frame refined alone for n corners spread over the board

    Each frame alone is point-symmetric about its own copy of the corner; the
    copies agree when neither the camera nor the display moved the frames.
    """
    idx = np.flatnonzero(ok)
    idx = idx[np.unique(np.linspace(0, len(idx) - 1, min(n_corners, len(idx))).astype(int))] if len(idx) else idx
    per = refine_each_frame(frames, corners[idx], window[idx], max_iter=15, tol=1e-3).corners  # (nf, n, 2)
    return idx, per


MAX_SIGMA_RATIO = 3.0  # a corner's refinement residual over the board's median (whole views: <= 1.3)


SHIFT_MIN_PX = 0.02  # display maps that move no corner by this much (camera px) are not modelled in the refinement


def board_centre(layout: Layout) -> np.ndarray:
    """(2,) display px, relative to corner (0, 0): the centre of the grid of corners, where display maps apply

        >>> from rotstar_mrcal.pattern.layout import make_layout
        >>> board_centre(make_layout(screen=(800, 600), pitch=100, band=24)).tolist()
        [250.0, 150.0]
    """
    return np.array([(layout.nx - 1) / 2, (layout.ny - 1) / 2]) * float(layout.pitch)


def refine_with_display_offsets(frames, res, rough, labels, w, pitch, centre=None) -> tuple:
    """(Refined, FrameShifts): each frame's display map measured (display_offsets.py), then refined with it modelled

    res: the joint refinement of the corners (labels (N, 2), rough starts
    (N, 2), windows w (N,)); pitch: display pixels per grid step; centre:
    the board's centre, display px. The second refinement runs only when the
    maps move a corner by SHIFT_MIN_PX or more.
    """
    idx, per = per_frame_corners(frames, res.corners, w, res.ok)
    uv = labels * float(pitch)
    jac = label_jacobian(res.corners[res.ok], labels[res.ok], labels, pitch)
    shifts = frame_shifts(per, res.corners[idx], labels[idx], pitch, jac[idx], centre)
    img = shifts.image_shifts(jac, uv)
    if np.abs(img).max() > SHIFT_MIN_PX:
        res = symmetric_refine(frames, np.where(res.ok[:, None], res.corners, rough), w, shifts=img)
        shifts.applied = True
    return res, shifts


def label_jacobian(corners: np.ndarray, labels: np.ndarray, at: np.ndarray, pitch: float) -> np.ndarray:
    """(M, 2, 2) camera px per display px at the grid labels `at` (M, 2), from the homography of corners (N, 2)
    at labels (N, 2); pitch: display px per grid step"""
    return homography_jacobian(grid_homography(corners, labels, pitch), at * float(pitch))


def image_shifts(shifts: FrameShifts | None, corners: np.ndarray, labels: np.ndarray, pitch: float):
    """(nframes, N, 2) the display offsets of each frame at each corner, px; None when there are none to model"""
    if shifts is None:
        return None
    ok = np.isfinite(corners).all(axis=1)
    if ok.sum() < 4:
        return None
    img = shifts.image_shifts(label_jacobian(corners[ok], labels[ok], labels, pitch), labels * float(pitch))
    return img if np.abs(img).max() > SHIFT_MIN_PX else None


def refine_with_maps(frames: np.ndarray, layout: Layout, r: PoseCorners, offsets, linear, centre) -> PoseCorners:
    """r's corners refined again on frames with given display maps (a dataset's) instead of the pose's own

    offsets (nframes, 2), linear (nframes, 2, 2), centre (2,): the maps, as
    display_offsets.FrameShifts (zeros: the plain joint refinement). Only
    corners r found are refined, in r's windows and on frames low-passed as
    before; a corner whose second refinement fails keeps its first.
    """
    j, i = np.nonzero(np.isfinite(r.corners[..., 0]))
    if len(i) < 4 or r.window is None:
        return r
    labels, q, w = np.column_stack((i, j)), r.corners[j, i], r.window[j, i]
    H, W = frames.shape[1:]
    m = int(np.ceil(np.max(w))) + 4
    x0, y0 = np.maximum(np.floor(q.min(axis=0)).astype(int) - m, 0)
    x1, y1 = np.minimum(np.ceil(q.max(axis=0)).astype(int) + m + 1, (W, H))
    off = np.array([x0, y0], float)
    lowpass = prefilter(np.asarray(frames, np.float32)[:, y0:y1, x0:x1], r.prefilter_px)
    img = image_displacement(label_jacobian(q, labels, labels, layout.pitch), offsets, linear, centre,
                             labels * float(layout.pitch))
    res = symmetric_refine(lowpass, q - off, w, shifts=img)
    corners, sigma, cov = r.corners.copy(), r.sigma.copy(), r.cov.copy()
    k = res.ok
    corners[j[k], i[k]] = res.corners[k] + off
    sigma[j[k], i[k]] = res.sigma[k]
    cov[j[k], i[k]] = res.cov[k]
    return dataclasses.replace(r, corners=corners, sigma=sigma, cov=cov)


def detect_pose(
    frames: np.ndarray,
    layout: Layout,
    full_scale: float = 255.0,
    checkerboard: np.ndarray | None = None,
    window: float = 10.0,
    refine: Refiner = SYMMETRIC,
    max_motion: float = MAX_MOTION,
    check_motion: bool = True,
    identity: np.ndarray | None = None,
    prefilter_sigma: float = PREFILTER_SIGMA,
    blur_map: bool = False,
) -> PoseCorners:
    """Detect and label the corners of one pose; see the module doc

    identity: (nidentity, H, W) the identity frames of a layout that has them;
    the elements are then labelled by their identities (boards partly out of
    view give the corners in view), else by the element graph (whole board).
    prefilter_sigma: the Gaussian low-pass (px) before the symmetric
    refinement (module doc); 0 for the paper's refinement on the raw frames.
    blur_map: also estimate the local PSF at every corner (PoseCorners.blur,
    edgespread.blur_columns; NaN where the window is too small).
    """
    frames = np.asarray(frames, np.float32)
    if len(frames) < 2:
        return _fail(layout, f"{len(frames)} rotating-star frame(s); need the whole sequence")
    why = check_exposure(frames, full_scale)
    if why:
        return _fail(layout, why)
    why = check_band_parity(frames)
    if why:
        return _fail(layout, why)
    if identity is not None and layout.identity:
        identity = np.asarray(identity, np.float32)
        if identity.shape[1:] != frames.shape[1:] or len(identity) != layout.identity_code.nframes:
            return _fail(layout, f"identity frames of shape {identity.shape}; expected "
                                 f"{(layout.identity_code.nframes,) + frames.shape[1:]}")
        found = by_identity(frames, identity, layout, window)
    else:
        found = by_graph(frames, layout, window)
    if found.error:
        return _fail(layout, found.error)
    labels, w = found.labels, found.window
    # work on the corners' bounding box from here on (all stages are local)
    H, W = frames.shape[1:]
    m = int(np.ceil(window)) + 4
    x0, y0 = np.maximum(np.floor(found.rough.min(axis=0)).astype(int) - m, 0)
    x1, y1 = np.minimum(np.ceil(found.rough.max(axis=0)).astype(int) + m + 1, (W, H))
    off = np.array([x0, y0], float)
    frames = frames[:, y0:y1, x0:x1]
    rough = found.rough - off

    grid_w = np.full((layout.ny, layout.nx), np.nan)
    grid_w[labels[:, 1], labels[:, 0]] = w
    reasons = np.full((layout.ny, layout.nx), "", dtype=object)
    for (i, j), r in found.rejected.items():
        reasons[j, i] = r
    sigma = np.full((layout.ny, layout.nx), np.nan)
    cov = np.full((layout.ny, layout.nx, 2, 2), np.nan)
    motion = 0.0
    shifts = None
    samples = None
    if refine.needs == "rotstar":  # the paper's symmetric refinement, display maps and motion check
        lowpass_sigma = lowpass_for(w, prefilter_sigma)
        lowpass = prefilter(frames, lowpass_sigma)
        res = symmetric_refine(lowpass, rough, w)
        if check_motion and res.ok.sum() >= 4:
            res, shifts = refine_with_display_offsets(lowpass, res, rough, labels, w, layout.pitch,
                                                      board_centre(layout))
            motion = shifts.residual_px
            if motion > max_motion:
                return _fail(layout, f"frames do not align: the camera moved during the sequence "
                                     f"(the frames bend against each other by {motion:.2f} px beyond what one "
                                     f"affine map per frame explains, limit {max_motion})")
        q, ok = res.corners, res.ok
        q_sym = q
        if refine.correct is not None:  # e.g. the PSF-aware refiner: from the symmetric corner to the light's
            sh = image_shifts(shifts, q, labels, layout.pitch)
            if refine.samples is None:
                q = refine.correct(frames, q, w, sh)
            else:
                measured = refine.samples(frames, q, w, sh)
                q = refine.correct(frames, q, w, sh, samples=measured)
                samples = (measured[0] + off, measured[1])
        reasons[labels[:, 1], labels[:, 0]] = res.reason
        sigma[labels[:, 1], labels[:, 0]] = res.sigma
        cov[labels[:, 1], labels[:, 0]] = res.cov
    elif refine.needs == "checkerboard":
        if checkerboard is None:
            return _fail(layout, f"--refine {refine.name} needs the checkerboard frame, which this pose lacks")
        cb = np.asarray(checkerboard, np.float32)[y0:y1, x0:x1]  # the same crop as the frames
        wi = max(int(np.floor(np.median(w))), 2)
        q = refine.refine(cb, rough, wi)
        ok = np.isfinite(q).all(axis=1) & (np.linalg.norm(q - rough, axis=1) <= w)
        q = np.where(ok[:, None], q, np.nan)
        reasons[labels[:, 1], labels[:, 0]] = np.where(ok, "", f"{refine.name} refinement failed")
    else:
        raise ValueError(f"refiner {refine.name!r} has no place in detect_pose")

    if found.by_identity:  # corners of partial views: checked against the others and against their neighbours
        q = q.copy()
        good = np.isfinite(q).all(axis=1)
        if refine.needs == "rotstar" and good.sum() >= 4:
            ratio = res.sigma / np.median(res.sigma[good])
            odd = good & ~(ratio <= MAX_SIGMA_RATIO)
            reasons[labels[odd, 1], labels[odd, 0]] = [
                f"refinement residual {v:.0f} x the board's median (partly hidden, or glare?)" for v in ratio[odd]]
            q[odd] = np.nan
            good &= ~odd
        ok2, why = refined_consistency(labels[good], q[good])
        drop = np.flatnonzero(good)[~ok2]
        reasons[labels[drop, 1], labels[drop, 0]] = why[~ok2]
        q[drop] = np.nan
    corners = np.full((layout.ny, layout.nx, 2), np.nan)
    corners[labels[:, 1], labels[:, 0]] = q + off
    blur = None
    if blur_map:
        blur = np.full((layout.ny, layout.nx, len(BLUR_FIELDS)), np.nan)
        blur[labels[:, 1], labels[:, 0]] = blur_columns(frames, q, w)
    correction = None
    if samples is not None:
        correction = np.full((layout.ny, layout.nx, 2), np.nan)
        correction[labels[:, 1], labels[:, 0]] = q - q_sym
    return PoseCorners(corners, "", reasons, sigma, cov, grid_w, motion, shifts, found.unplaced, blur,
                       lowpass_sigma if refine.needs == "rotstar" else 0.0, samples, correction)


def correct_with_dataset(layout: Layout, poses: list[PoseCorners], refine: Refiner) -> None:
    """Every pose's corners corrected again by refine.correct with what refine.samples measured on ALL poses

    (psf-sim: the coma is a property of the lens, measured where elements are
    large; poses whose windows are all small get it from the others.) In
    place; each pose's symmetric corners are its corners less its own
    correction, its element Jacobians those of its corners' homography.
    detect_camera's first pass leaves the corrections to this (corners_as_they_are).
    """
    have, pooled = _pooling(poses)
    if not have:
        return
    angles = np.array([layout.angle(k) for k in range(layout.nframes)])
    for p in have:
        j, i = np.nonzero(np.isfinite(p.corners[..., 0]) & np.isfinite(p.correction[..., 0]))
        if len(i) < 4:
            continue
        labels = np.column_stack((i, j))
        q = p.corners[j, i] - p.correction[j, i]
        jac = label_jacobian(q, labels, labels, layout.pitch)
        new = refine.correct(None, q, p.window[j, i], None, samples=pooled, jac=jac, angles=angles,
                             lowpass_sigma=p.prefilter_px)
        p.corners[j, i] = new
        p.correction[j, i] = new - q


def pooled_corrections(poses: list[PoseCorners]) -> tuple[tuple[np.ndarray, ...] | None, np.ndarray]:
    """(every pose's refine.samples pooled, or None; the lengths (M,) of the corrections correct_with_dataset made)

    >>> p = PoseCorners(np.zeros((1, 2, 2)), samples=(np.zeros((1, 2)), np.ones((1, 2))),
    ...                 correction=np.array([[[0.03, 0.04], [np.nan, np.nan]]]))
    >>> s, moved = pooled_corrections([p, PoseCorners(np.zeros((1, 2, 2)))])
    >>> len(s[0]), moved.round(3).tolist()
    (1, [0.05])
    """
    have, pooled = _pooling(poses)
    if not have:
        return None, np.zeros(0)
    moved = np.concatenate([np.linalg.norm(p.correction, axis=-1).ravel() for p in have])
    return pooled, moved[np.isfinite(moved)]


def _pooling(poses: list[PoseCorners]) -> tuple[list[PoseCorners], tuple[np.ndarray, ...] | None]:
    """(the poses a pooling refiner measured, their refine.samples concatenated or None)"""
    have = [p for p in poses if p.samples is not None and p.correction is not None]
    if not have:
        return have, None
    return have, tuple(np.concatenate([p.samples[i] for p in have]) for i in range(len(have[0].samples)))

"""One pose: recorded frames in, labelled sub-pixel corners out

SYNOPSIS

    from rotstar_mrcal import dataset
    from rotstar_mrcal.detect.pipeline import detect_pose
    _, layout = dataset.read_pattern("seq")
    pose = dataset.load_pose("seq", "pose000", layout)
    result = detect_pose(pose.rotstar, layout, full_scale=pose.full_scale,
                         checkerboard=pose.checkerboard)
    result.corners      # (ny, nx, 2), NaN where a corner was rejected
    result.error        # '' or the one-line reason the board was skipped

The stages (paper 3.2-3.3): response map -> element boundaries -> rough
corners -> grid indexing and orientation -> refinement. Each stage is a pure
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
largest square inside the element's boundary, so that the symmetric window
never reaches the border band or the neighbouring elements (whose crossings
are centres of symmetry too, and would attract the corner).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..pattern.layout import Layout
from .boundaries import element_boundaries
from .indexing import GridError, contact_graph, grid_labels, grid_labels_grown, orient, prune_triangles
from .refine import refine_each_frame, symmetric_refine
from .response import binarize, response_map
from .rough import rough_corners

REFINERS = ("symmetric", "opencv", "saddle")
LARGE_ELEMENT = 12.0  # px, inscribed half-size above which the curve intersection starts the refinement
WINDOW_FRACTION = 0.65
MIN_WINDOW = 2.0


@dataclasses.dataclass
class PoseCorners:
    corners: np.ndarray  # (ny, nx, 2) mrcal image coordinates, NaN = missing
    error: str = ""  # why the whole board was skipped, or ''
    reasons: np.ndarray | None = None  # (ny, nx) why single corners are missing
    sigma: np.ndarray | None = None  # (ny, nx) rms residual of the refinement
    cov: np.ndarray | None = None  # (ny, nx, 2, 2) corner covariance estimate, px^2
    window: np.ndarray | None = None  # (ny, nx) refinement half-window used
    motion_px: float = 0.0  # largest per-frame disagreement of the corners

    @property
    def found(self) -> bool:
        return not self.error

    @property
    def n_valid(self) -> int:
        return int(np.isfinite(self.corners[..., 0]).sum())

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


def check_exposure(frames: np.ndarray, full_scale: float) -> str:
    """'' or why the frames cannot hold a board (dark, saturated, static)"""
    sub = frames[:, ::4, ::4]
    hi = float(np.percentile(sub, 99.5))
    if hi < 0.03 * full_scale:
        return f"all dark (99.5th percentile {hi:.0f} of {full_scale:.0f})"
    sat = float(np.mean(sub >= full_scale))
    if sat > 0.5:
        return f"saturated ({sat:.0%} of the pixels at full scale)"
    return ""


def frame_motion(frames: np.ndarray, corners: np.ndarray, window: np.ndarray, ok: np.ndarray,
                 n_corners: int = 24) -> float:
    """Median over corners of the largest per-frame corner shift, px

    Each frame alone is point-symmetric about the same corner when the camera
    held still: refine each frame separately from the joint solution (for
    n_corners spread over the board) and measure how far the per-frame
    answers spread.
    """
    idx = np.flatnonzero(ok)
    if len(idx) < 3:
        return 0.0
    idx = idx[np.linspace(0, len(idx) - 1, min(n_corners, len(idx))).astype(int)]
    per = refine_each_frame(frames, corners[idx], window[idx], max_iter=15, tol=1e-3).corners  # (nf, n, 2)
    spread = np.nanmax(np.linalg.norm(per - np.nanmedian(per, axis=0), axis=-1), axis=0)
    return float(np.nanmedian(spread))


def detect_pose(
    frames: np.ndarray,
    layout: Layout,
    full_scale: float = 255.0,
    checkerboard: np.ndarray | None = None,
    window: float = 10.0,
    refine: str = "symmetric",
    max_motion: float = 0.15,
    check_motion: bool = True,
) -> PoseCorners:
    """Detect and label the corners of one pose; see the module doc"""
    frames = np.asarray(frames, np.float32)
    if len(frames) < 2:
        return _fail(layout, f"{len(frames)} rotating-star frame(s); need the whole sequence")
    why = check_exposure(frames, full_scale)
    if why:
        return _fail(layout, why)
    resp = response_map(frames)
    mask, _ = binarize(resp)
    el = element_boundaries(mask)
    n_expected = layout.nx * layout.ny
    if el.touches_edge and len(el.contours) <= 2 * n_expected:
        return _fail(layout, f"board partly out of view (the border lattice reaches the image edge; {len(el.contours)} of {n_expected} elements inside)")
    if len(el.contours) != n_expected:
        if not el.contours:
            hint = " (no rotating-star pattern found)"
        elif len(el.contours) > 2 * n_expected:
            hint = " (the response map is dominated by noise: too dark or too noisy?)"
        else:
            hint = " (camera moved during the sequence? wrong pattern.json?)"
        return _fail(layout, f"found {len(el.contours)} elements, expected {layout.nx}x{layout.ny} = {n_expected}{hint}")
    # work on the board's bounding box from here on (all stages are local)
    H, W = frames.shape[1:]
    m = int(np.ceil(window)) + 4
    x0, y0 = np.maximum(el.lattice.min(axis=0) - m, 0)
    x1, y1 = np.minimum(el.lattice.max(axis=0) + m + 1, (W, H))
    off = np.array([x0, y0], float)
    frames = frames[:, y0:y1, x0:x1]
    contours = [c - (x0, y0) for c in el.contours]
    centroids = el.centroids - off
    rough = centroids.copy()
    large = el.inscribed >= LARGE_ELEMENT
    if large.any():
        q, ok = rough_corners(frames, [c for c, l in zip(contours, large) if l], centroids[large])
        rough[np.flatnonzero(large)[ok]] = q[ok]
    A, contact = contact_graph(contours, frames.shape[1:], el.lattice - (x0, y0))
    try:
        try:
            labels = grid_labels(prune_triangles(A, contact), layout.nx, layout.ny)
        except GridError as e:  # small elements: diagonal neighbours touch like side ones
            try:
                labels = grid_labels_grown(A, centroids, layout.nx, layout.ny)
            except GridError:
                raise e from None
        labels = orient(labels, rough, frames[0], layout.nx, layout.ny, layout.marker)
    except GridError as e:
        return _fail(layout, str(e))

    w = np.clip(WINDOW_FRACTION * el.inscribed, MIN_WINDOW, window)
    grid_w = np.full((layout.ny, layout.nx), np.nan)
    grid_w[labels[:, 1], labels[:, 0]] = w
    reasons = np.full((layout.ny, layout.nx), "", dtype=object)
    sigma = np.full((layout.ny, layout.nx), np.nan)
    cov = np.full((layout.ny, layout.nx, 2, 2), np.nan)
    motion = 0.0
    if refine == "symmetric":
        res = symmetric_refine(frames, rough, w)
        q, ok = res.corners, res.ok
        reasons[labels[:, 1], labels[:, 0]] = res.reason
        sigma[labels[:, 1], labels[:, 0]] = res.sigma
        cov[labels[:, 1], labels[:, 0]] = res.cov
        if check_motion:
            motion = frame_motion(frames, q, w, ok)
            if motion > max_motion:
                return _fail(layout, f"frames do not align: the camera moved during the sequence "
                                     f"(per-frame corners disagree by {motion:.2f} px, limit {max_motion})")
    elif refine in ("opencv", "saddle"):
        if checkerboard is None:
            return _fail(layout, f"--refine {refine} needs the checkerboard frame, which this pose lacks")
        from . import baselines

        cb = np.asarray(checkerboard, np.float32)[y0:y1, x0:x1]  # the same crop as the frames
        wi = max(int(np.floor(np.median(w))), 2)
        if refine == "opencv":
            q = baselines.opencv_subpix(cb, rough, win=wi, full_scale=full_scale)
        else:
            q = baselines.saddle_refine(cb, rough, win=wi)
        ok = np.isfinite(q).all(axis=1) & (np.linalg.norm(q - rough, axis=1) <= w)
        q = np.where(ok[:, None], q, np.nan)
        reasons[labels[:, 1], labels[:, 0]] = np.where(ok, "", f"{refine} refinement failed")
    else:
        raise ValueError(f"unknown refiner {refine!r}; choose one of {REFINERS}")

    corners = np.full((layout.ny, layout.nx, 2), np.nan)
    corners[labels[:, 1], labels[:, 0]] = q + off
    return PoseCorners(corners, "", reasons, sigma, cov, grid_w, motion)

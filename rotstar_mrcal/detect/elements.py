"""Labelled elements: rough corners with their grid labels and refinement windows

SYNOPSIS

    from rotstar_mrcal.detect.elements import by_identity
    found = by_identity(frames, identity, layout, window=10.0)
    found.error                              # '' or why the pose has no board (then no element)
    found.labels, found.rough, found.window  # (N, 2) (i, j), (N, 2) px, (N,) px
    found.rejected                           # {(i, j): why} for elements seen but not kept
    found.unplaced                           # why, for elements whose identity was not read

Two ways to the same result. by_graph (the paper's, for sequences without
identity frames) needs the whole board: the element boundaries enclosed by
the border lattice, labelled by the element graph's topology and oriented by
the marker. by_identity (issue 13) labels every element in view by its
identity code, whole or cut by the image edge, and then checks the labels:
against the labelled neighbours (consistency.py), against the checker colours
of frame 0 (parity and marker, as the graph path orients), and against the
stars' angles (frames out of order, a mirrored labelling). A mirrored view is
refused (indexing.handedness_reason): its codes label it, but no board pose
mrcal can fit (a rotation) gives a mirrored board.

The refinement window of a corner is 0.65 x the half-side of the largest
square about it inside its element, capped at `window` (pipeline.py): the
element's square as the homography of the corners labelled around it
projects it (grid_windows), or, where too few are labelled, the square
inside the element's region of pixels (window_of), which moves with the
frames' noise. For an element cut by the image edge the square is measured
as if the element went on beyond the edge, and the corner is kept only when
that window, plus one pixel, lies inside the image: a corner near the edge
gets the same window as any other or none.
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from rotstar_mrcal.pattern.layout import Layout
from rotstar_mrcal.detect.boundaries import element_boundaries, inscribed_square, on_border
from rotstar_mrcal.detect.consistency import label_consistency, predict_from_neighbours
from rotstar_mrcal.detect.identity import read_identities
from rotstar_mrcal.detect.indexing import (
    GridError, checker_phase, contact_graph, frame_angles, grid_array, grid_labels, grid_labels_grown,
    handedness_reason, mirror_reason, order_reason, orient, prune_triangles,
)
from rotstar_mrcal.detect.response import binarize, response_map
from rotstar_mrcal.detect.rough import rough_corners

LARGE_ELEMENT = 12.0  # px, inscribed half-size above which the curve intersection starts the refinement
WINDOW_FRACTION = 0.65
MIN_WINDOW = 2.0
REGION_EDGE_PX = 1.0  # an identity region's edge pixels lie inside the element's edge (median 0.9 px against
#                       the border lattice's holes on a simulated D435 view): added to its half-side
PARITY_MIN = 0.25  # |checker phase| above which frame 0's colours are decided
MAX_PARITY_DISAGREE = 0.25  # share of elements whose colours may contradict their identity before the pose fails


@dataclasses.dataclass
class LabelledElements:
    labels: np.ndarray  # (N, 2) int (i, j)
    rough: np.ndarray  # (N, 2) rough corners, full-image px
    window: np.ndarray  # (N,) refinement half-windows, px
    rejected: dict = dataclasses.field(default_factory=dict)  # {(i, j): why}
    unplaced: list = dataclasses.field(default_factory=list)  # why, per element whose identity was not read
    by_identity: bool = False  # labelled by the identity codes (else by the element graph)
    error: str = ""  # '' or why the pose gives no board (then no element)


def no_board(why: str) -> LabelledElements:
    """No labelled element, and why the pose gives no board

    >>> e = no_board("board partly out of view"); e.error, e.labels.shape
    ('board partly out of view', (0, 2))
    """
    return LabelledElements(np.zeros((0, 2), int), np.zeros((0, 2)), np.zeros(0), error=why)


def window_of(contour: np.ndarray, centre: np.ndarray, shape, window: float) -> float:
    """The refinement half-window about centre in an element bounded by contour, ignoring image-border points

    contour: the element's identity region, whose edge pixels lie about
    REGION_EDGE_PX inside the element's edge.
    """
    inner = ~on_border(contour, shape)
    half = inscribed_square(contour[inner] if inner.any() else contour, centre) + REGION_EDGE_PX
    return float(np.clip(WINDOW_FRACTION * half, MIN_WINDOW, window))


def square_in_quad(quad: np.ndarray, centre: np.ndarray) -> float:
    """Half-side of the largest axis-aligned square about centre inside the convex quadrilateral quad (4, 2)

    Each edge, a line n . x = c with n its inward normal, bounds the square's
    half-side by (n . centre - c) / (|n_x| + |n_y|) (the square's nearest
    corner touches it); the least of the four bounds.

    >>> square_in_quad(np.array([[0.0, 0], [10, 0], [10, 6], [0, 6]]), np.array([5.0, 3.0]))
    3.0
    >>> round(square_in_quad(np.array([[0.0, -5], [5, 0], [0, 5], [-5, 0]]), np.zeros(2)), 6)   # a diamond
    2.5
    """
    a = np.asarray(quad, float)
    e = np.roll(a, -1, axis=0) - a
    n = np.stack((-e[:, 1], e[:, 0]), axis=-1)
    n *= np.sign(np.sum(n * (a.mean(axis=0) - a), axis=-1))[:, None]  # inward, whichever the winding
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return float(np.min(np.sum(n * (np.asarray(centre, float) - a), axis=-1) / np.abs(n).sum(axis=-1)))


def grid_windows(labels: np.ndarray, corners: np.ndarray, layout: Layout, window: float) -> np.ndarray:
    """(N,) each corner's refinement half-window from the labelled grid; NaN where it cannot be measured so

    WINDOW_FRACTION x the half-side of the largest axis-aligned square about
    the corner inside its element (layout.half_element display px about it),
    the element projected by the homography of the corners labelled within
    one grid step of it (itself included; at least 4, not all on one line),
    between MIN_WINDOW and `window` px: the detector's estimate of
    simulate.visibility.true_windows. Unlike the square inside an element's
    region of pixels, it does not jump by a pixel when the frames' noise
    moves one pixel of the region's edge (issue 23: the window's draw moved
    a small element's corner by 0.01 px).

    >>> from rotstar_mrcal.pattern.layout import make_layout
    >>> L = make_layout(screen=(800, 600), pitch=100, band=24)         # half_element 38 display px
    >>> lab = np.array([[i, j] for j in range(2) for i in range(3)])
    >>> grid_windows(lab, lab * [20.0, 10.0] + 50, L, 10.0).round(2)  # 20 / 10 px per grid step
    array([2.47, 2.47, 2.47, 2.47, 2.47, 2.47])
    """
    labels = np.asarray(labels, int)
    q = np.asarray(corners, float)
    h = layout.half_element / layout.pitch
    quad = np.array([[-h, -h], [h, -h], [h, h], [-h, h]])
    out = np.full(len(labels), np.nan)
    ok = np.isfinite(q).all(axis=1)
    for n in np.flatnonzero(ok):
        near = ok & (np.abs(labels - labels[n]).max(axis=1) <= 1)
        if near.sum() < 4 or len(np.unique(labels[near, 0])) < 2 or len(np.unique(labels[near, 1])) < 2:
            continue
        H, _ = cv2.findHomography(labels[near].astype(np.float64), q[near], 0)
        if H is None:
            continue
        p = cv2.perspectiveTransform(np.vstack((labels[n], labels[n] + quad))[None].astype(np.float64), H)[0]
        out[n] = WINDOW_FRACTION * square_in_quad(p[1:], p[0])
    return np.where(np.isfinite(out), np.clip(out, MIN_WINDOW, window), np.nan)


def inside_image(points: np.ndarray, w: np.ndarray, shape) -> np.ndarray:
    """(N,) the square of half-side w + 1 about each point lies inside the image"""
    H, W = shape
    m = w + 1.0
    return ((points[:, 0] - m >= 0) & (points[:, 1] - m >= 0)
            & (points[:, 0] + m <= W - 1) & (points[:, 1] + m <= H - 1))


def _parity_check(frame0, labels, rough, layout: Layout) -> np.ndarray:
    """(N,) True where frame 0's checker colours contradict the element's identity (parity and marker)"""
    grid = grid_array(labels, rough, layout.nx, layout.ny)
    s = checker_phase(frame0, grid)[labels[:, 1], labels[:, 0]]
    i, j = labels[:, 0], labels[:, 1]
    expect = np.where((i + j) % 2 == 0, -1.0, 1.0)
    expect[(i == layout.marker[0]) & (j == layout.marker[1])] *= -1
    return np.isfinite(s) & (np.abs(s) > PARITY_MIN) & (np.sign(s) != expect)


def misordered_reason(fault: tuple, layout: Layout) -> str:
    """Why a pose whose identity frames are inverted or swapped (IdentityCode.misordered) is refused, naming them

    >>> from rotstar_mrcal.pattern.layout import make_layout
    >>> misordered_reason(("swapped", 3, 7, 60, 124, 126), make_layout())[:68]
    'identity frames 3 and 7 (identity_03.png, identity_07.png) swapped, '
    """
    files = [f["file"] for f in layout.frames() if f["kind"] == "identity"]
    *what, read, fixed, n = fault
    if what[0] == "inverted":
        k = what[1]
        return (f"identity frame {k} ({files[k]}) inverted (its white and black exchanged): as recorded the codes "
                f"of {read} of {n} elements read, with it inverted {fixed}")
    a, b = what[1:]
    return (f"identity frames {a} and {b} ({files[a]}, {files[b]}) swapped, on disk or in pattern.json: as recorded "
            f"the codes of {read} of {n} elements read, with the two exchanged {fixed} (put the frames in "
            "pattern.json's order)")


def by_identity(frames: np.ndarray, identity: np.ndarray, layout: Layout, window: float) -> LabelledElements:
    """LabelledElements from the identity frames (.error: '' or a one-line reason); see the module doc"""
    H, W = frames.shape[1:]
    ids = read_identities(frames, identity, layout.identity_code)
    if ids.misordered:
        return no_board(misordered_reason(ids.misordered, layout))
    read = ids.index >= 0
    unplaced = list(ids.reason[~read])
    if read.sum() < 4:
        seen = len(ids.index)
        if seen == 0:
            return no_board("no identity frames that show elements "
                            "(no element changes between the identity frames)")
        return no_board(f"identities of {read.sum()} of {seen} elements read; {unplaced[0] if unplaced else ''}"
                        .rstrip("; "))
    labels = ids.labels(layout.nx)[read]
    cs = [c for c, r in zip(ids.contours, read) if r]
    cen = ids.centroids[read]
    whole = ~ids.touches_edge[read]
    # rough corners (paper 3.2) on the elements' bounding box
    x0, y0 = np.maximum(np.floor(np.min([c.min(axis=0) for c in cs], axis=0)).astype(int) - 2, 0)
    x1, y1 = np.minimum(np.max([c.max(axis=0) for c in cs], axis=0).astype(int) + 3, (W, H))
    sub = frames[:, y0:y1, x0:x1]
    rough = cen.copy()
    large = (ids.inscribed[read] >= LARGE_ELEMENT) | ~whole  # a cut element's centroid is not its corner
    rough_ok = whole.copy()
    if large.any():
        q, ok = rough_corners(sub, [c - (x0, y0) for c, l in zip(cs, large) if l], cen[large] - (x0, y0))
        idx = np.flatnonzero(large)
        rough[idx[ok]] = q[ok] + (x0, y0)
        rough_ok[idx] = ok | whole[idx]
    # the identities against the image: each element against its labelled neighbours
    ok, why = label_consistency(labels[rough_ok], rough[rough_ok])
    keep = rough_ok.copy()
    keep[rough_ok] = ok
    rejected = {tuple(lab): r for lab, r in zip(labels[rough_ok][~ok], why[~ok])}
    # cut elements whose checker lines did not give the corner, or gave it badly: placed by their
    # neighbours, when that place is inside the element (a misread identity puts it in another one)
    late = np.flatnonzero(~keep & ~whole)
    if len(late):
        pred, _ = predict_from_neighbours(labels, rough, keep)
        for e in late:
            p = pred[e]
            if np.isfinite(p).all() and cv2.pointPolygonTest(cs[e].reshape(-1, 1, 2).astype(np.int32),
                                                             (float(p[0]), float(p[1])), False) >= 0:
                rough[e], keep[e] = p, True
                rejected.pop(tuple(labels[e]), None)
            elif tuple(labels[e]) not in rejected:
                rejected[tuple(labels[e])] = "cut by the image edge: its corner is not in view"
    # the stars' angles: frames in order, and turning from i toward j under these labels
    if keep.sum() >= 4:
        grid = grid_array(labels[keep], rough[keep], layout.nx, layout.ny)
        why = handedness_reason(grid)  # labelled right by the codes, but no rotation fits a mirrored board
        if why:
            return no_board(why)
        phi = frame_angles(frames, grid, layout.half_element / layout.pitch)
        why = order_reason(phi, layout.step) or mirror_reason(phi, layout.step)
        if why:
            return no_board(why)
    # frame 0's colours: parity and the marker, as the graph path orients
    bad = keep & _parity_check(frames[0], labels, np.where(keep[:, None], rough, np.nan), layout)
    if bad.sum() > MAX_PARITY_DISAGREE * keep.sum():
        return no_board(f"the checker colours of frame 0 contradict the identities of {bad.sum()} of {keep.sum()} "
                        "elements (is the first rotating-star frame the one at angle 0?)")
    for lab in labels[bad]:
        rejected[tuple(lab)] = "frame 0's checker colours contradict its identity"
    keep &= ~bad
    if keep.sum() < 4:
        return no_board(f"only {keep.sum()} elements whose identities agree with the image" + (
            f" ({next(iter(rejected.values()))})" if rejected else ""))
    labels, rough, cs = labels[keep], rough[keep], [c for c, k in zip(cs, keep) if k]
    w = grid_windows(labels, rough, layout, window)
    for n in np.flatnonzero(~np.isfinite(w)):  # too few labelled neighbours: the square inside its region
        w[n] = window_of(cs[n], rough[n], (H, W), window)
    inside = inside_image(rough, w, (H, W))
    for lab in labels[~inside]:
        rejected[tuple(lab)] = "refinement window leaves the image"
    return LabelledElements(labels[inside], rough[inside], w[inside], rejected, unplaced, by_identity=True)


MIN_SPACING = 12.0  # px between corners below which the elements are not reliably separated


def element_count_reason(el, n_expected: int, layout: Layout) -> str:
    """'' when the element boundaries hold the whole grid, else what was seen

    A border lattice that touches the image edge is fine as long as every
    element is inside (each element is a hole closed by the lattice).
    """
    n = len(el.contours)
    if n == n_expected:
        return ""
    if el.lattice is None or not len(el.lattice):
        return "no rotating-star pattern found (no border lattice that flips between frames)"
    seen = f"found {n} elements, expected {layout.nx}x{layout.ny} = {n_expected}"
    if n > 2 * n_expected:
        return f"{seen}: the response map is dominated by noise (too dark or too noisy?)"
    if el.touches_edge:
        return f"board partly out of view ({n} of {n_expected} elements inside the image)"
    w, h = np.ptp(el.lattice, axis=0)
    spacing = float(np.sqrt(w * h / n_expected))  # the lattice spans about nx x ny grid steps
    if spacing < MIN_SPACING:
        return (f"{seen}: board too small in the image (corners about {spacing:.0f} px apart, need "
                f"{MIN_SPACING:.0f}); move closer or show a larger pitch")
    if n < n_expected:
        return f"{seen}: part of the board is hidden or blurred (an occluder, glare, or too steep a view?)"
    return f"{seen}: more elements than the grid of pattern.json (is it the pattern.json of this screen?)"


def by_graph(frames: np.ndarray, layout: Layout, window: float) -> LabelledElements:
    """LabelledElements of a whole board from the element graph and the marker (.error: '' or a one-line reason)"""
    resp = response_map(frames)
    mask, _ = binarize(resp)
    el = element_boundaries(mask)
    why = element_count_reason(el, layout.nx * layout.ny, layout)
    if why:
        return no_board(why)
    H, W = frames.shape[1:]
    m = int(np.ceil(window)) + 4
    x0, y0 = np.maximum(el.lattice.min(axis=0) - m, 0)
    x1, y1 = np.minimum(el.lattice.max(axis=0) + m + 1, (W, H))
    off = np.array([x0, y0], float)
    frames = frames[:, y0:y1, x0:x1]
    contours = [c - (x0, y0) for c in el.contours]
    centroids = el.centroids - off
    rough = centroids.copy()
    inscribed = el.inscribed
    large = inscribed >= LARGE_ELEMENT
    if large.any():
        q, ok = rough_corners(frames, [c for c, l in zip(contours, large) if l], centroids[large])
        rough[np.flatnonzero(large)[ok]] = q[ok]
    A, contact = contact_graph(contours, frames.shape[1:], el.lattice - (x0, y0))
    hef = layout.half_element / layout.pitch
    try:
        try:
            labels = grid_labels(prune_triangles(A, contact), layout.nx, layout.ny)
        except GridError as e:  # small elements: diagonal neighbours touch like side ones
            try:
                labels = grid_labels_grown(A, centroids, layout.nx, layout.ny)
            except GridError:
                raise e from None
        why = order_reason(frame_angles(frames, grid_array(labels, rough, layout.nx, layout.ny), hef), layout.step)
        if why:
            return no_board(why)
        labels = orient(labels, rough, frames[0], layout.nx, layout.ny, layout.marker)
    except GridError as e:
        return no_board(str(e))
    why = mirror_reason(frame_angles(frames, grid_array(labels, rough, layout.nx, layout.ny), hef), layout.step)
    if why:
        return no_board(why)
    w = grid_windows(labels, rough, layout, window)
    w = np.where(np.isfinite(w), w, np.clip(WINDOW_FRACTION * inscribed, MIN_WINDOW, window))
    return LabelledElements(labels, rough + off, w)

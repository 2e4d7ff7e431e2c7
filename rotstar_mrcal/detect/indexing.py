"""Grid indexing: which element is corner (i, j) (paper 3.2, third step)

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.detect.indexing import adjacency, grid_labels
    >>> jj, ii = np.mgrid[0:3, 0:4]
    >>> centres = np.stack((ii * 20 + 20, jj * 20 + 20), -1).reshape(-1, 2)
    >>> contours = list(centres[:, None, :] + np.array([[-7, -7], [7, -7], [7, 7], [-7, 7]]))
    >>> A = adjacency(contours, (100, 120))
    >>> labels = grid_labels(A, nx=4, ny=3)
    >>> np.abs(labels - labels[0]).max(axis=0).tolist()
    [3, 2]

1. Adjacency graph (`adjacency`): the paper links elements whose
   bounding-rectangle vertices are close, which separates side from diagonal
   neighbours by only sqrt(2); blur and foreshortening undo that margin.
   Instead every lattice pixel goes to the nearest element (a Voronoi
   partition), side neighbours share a boundary along the band between them,
   boundary pixels near a band crossing (a third element about as near) do
   not count, and links that cross another link (both diagonals of one cell)
   or close a triangle are dropped.
2. The boundary chain (elements with fewer than four neighbours) must be one
   cycle with four corners (two neighbours each) whose sides have nx and ny
   elements. Labels follow from graph distances to two adjacent corners:
   i + j = d(corner00), (nx-1-i) + j = d(corner10). Every edge of the graph
   must then join labels one step apart; anything else is an error, never a
   guess. Where that fails because the elements are so small that diagonal
   neighbours touch like side ones, `grid_labels_grown` labels the unpruned
   graph cell by cell from the board's outline, with the same refusal rules.
3. `orient` fixes the labelling among the grid's symmetries with the marker
   element (inverted checker colours in frame 0) and the checker parity, and
   refuses a mirror image (`handedness_reason`).
"""

from __future__ import annotations

from collections import deque

import cv2
import numpy as np

from rotstar_mrcal.detect.nearest import knn_third_party, nearest_label  # scipy's EDT and k-d tree answers, without importing scipy


class GridError(Exception):
    """The elements do not form the expected grid: the board is skipped"""


def adjacency(contours: list, shape: tuple[int, int], lattice: np.ndarray | None = None,
              min_contact: float = 0.3) -> np.ndarray:
    """Boolean (N, N) adjacency of elements by shared border: contact_graph, triangles pruned"""
    return prune_triangles(*contact_graph(contours, shape, lattice, min_contact))


def contact_graph(contours: list, shape: tuple[int, int], lattice: np.ndarray | None = None,
                  min_contact: float = 0.3) -> tuple[np.ndarray, np.ndarray]:
    """(A, contact): elements linked by shared border in the band lattice, and the border lengths

    Every pixel between the elements is given to the nearest element (a
    Voronoi partition of the border lattice). Side neighbours share a
    boundary along the band segment between them, about a side of an
    element long; diagonal neighbours touch only where the bands cross, so
    boundary pixels with a third element about as near (within 25%) are not
    counted; nor are pixels outside `lattice` (the outer contour of the border
    lattice), where the corner elements' neighbours would meet around them.
    Two elements are linked when their boundary is longer than `min_contact`
    times the smaller element's mean side (the square root of its area;
    foreshortening can make the contact across the short direction a
    quarter of that). Under strong shear (steep tilts about a diagonal) the
    two elements on the short diagonal of a band crossing can share a real
    boundary; a grid graph has no triangles, so `adjacency` prunes such
    links (prune_triangles); grid_labels_grown takes A as it is here.
    Links that cross another link (both diagonals of a cell) are already
    dropped (drop_crossing_links). Unlike rules on the elements' outlines
    (such as the paper's bounding-rectangle vertex distance) this holds
    under shear, steep perspective and blur.
    """
    N = len(contours)
    if N == 0:
        return np.zeros((0, 0), bool), np.zeros((0, 0))
    allpts = np.concatenate(contours)
    owner = np.repeat(np.arange(N), [len(c) for c in contours])
    pad = 4
    x0, y0 = np.maximum(allpts.min(axis=0) - pad, 0)
    x1, y1 = np.minimum(allpts.max(axis=0) + pad + 1, (shape[1], shape[0]))
    lab = np.zeros((y1 - y0, x1 - x0), np.int32)
    for k, c in enumerate(contours):
        cv2.drawContours(lab, [(c - (x0, y0)).astype(np.int32)[:, None, :]], 0, k + 1, thickness=-1)
    area = np.array([max(cv2.contourArea(c.astype(np.float32)), 1.0) for c in contours])
    side = np.sqrt(area)
    vor = nearest_label(lab, 0.75 * np.median(side))  # the nearest element, if near: stay near the elements
    if lattice is not None:  # and inside the border lattice: no contact around the board's corners
        inside = np.zeros_like(lab, np.uint8)
        cv2.fillPoly(inside, [(np.asarray(lattice) - (x0, y0)).astype(np.int32)[:, None, :]], 1)
        vor[inside == 0] = 0
    # boundary pixels between two different elements (horizontal and vertical pairs)
    ya, xa = np.nonzero((vor[:, :-1] != vor[:, 1:]) & (vor[:, :-1] > 0) & (vor[:, 1:] > 0))
    yb, xb = np.nonzero((vor[:-1, :] != vor[1:, :]) & (vor[:-1, :] > 0) & (vor[1:, :] > 0))
    a = np.concatenate((vor[ya, xa], vor[yb, xb])) - 1
    b = np.concatenate((vor[ya, xa + 1], vor[yb + 1, xb])) - 1
    p = np.concatenate((np.column_stack((xa + 0.5, ya)), np.column_stack((xb, yb + 0.5)))) + (x0, y0)
    if len(p):
        kk = min(24, len(allpts))
        keep, ask = knn_third_party(allpts, owner, p, a, b, k=kk) if kk == 24 else (None, np.ones(len(p), bool))
        if ask.any():  # ties at the 24th distance that cKDTree's order decides
            # scipy.spatial costs 0.5-0.8 s to import (python -X importtime), more than detecting
            # a pose: imported only on such rare ties
            from scipy.spatial import cKDTree

            q = np.flatnonzero(ask)
            dd, ii = cKDTree(allpts).query(p[q], k=kk)
            dd, ii = dd.reshape(len(q), kk), ii.reshape(len(q), kk)
            own = owner[ii]
            d_ab = np.where((own == a[q, None]) | (own == b[q, None]), dd, np.inf).min(axis=1)
            d_3 = np.where((own != a[q, None]) & (own != b[q, None]), dd, np.inf).min(axis=1)
            keep = np.zeros(len(p), bool) if keep is None else keep
            keep[q] = d_3 > 1.25 * d_ab
        a, b = a[keep], b[keep]
    contact = np.zeros((N, N))
    np.add.at(contact, (a, b), 1)
    contact = contact + contact.T
    np.fill_diagonal(contact, 0)
    A = contact > np.maximum(2.0, min_contact * np.minimum(side[:, None], side[None, :]))
    centroids = np.array([c.mean(axis=0) for c in contours], float)
    return drop_crossing_links(A, centroids), contact


def drop_crossing_links(A: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Drop every link whose segment properly crosses another link's

    SYNOPSIS

        >>> import numpy as np
        >>> square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
        >>> A = ~np.eye(4, dtype=bool)                 # four sides and both diagonals
        >>> drop_crossing_links(A, square).astype(int)  # the diagonals cross: gone
        array([[0, 1, 0, 1],
               [1, 0, 1, 0],
               [0, 1, 0, 1],
               [1, 0, 1, 0]])

    The side links of a grid seen in perspective never cross (a
    perspective view of a plane keeps segments straight and their order);
    the two diagonals of one cell do cross each other. Where the elements
    are so small that diagonal neighbours touch as much as side ones, every
    cell can carry both diagonals (the king's graph), and pruning triangles
    alone would then drop the side links, which have more common neighbours.
    A lone diagonal crosses nothing and is left to prune_triangles.
    """
    i, j = np.nonzero(np.triu(A))
    if len(i) < 2:
        return A
    p, q = points[i], points[j]  # (L, 2) segment ends

    def orient(a, b, c):  # sign of the turn a -> b -> c, broadcast over link pairs
        return np.sign((b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1])
                       - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0]))

    P, Q = p[:, None], q[:, None]
    R, S = p[None], q[None]
    cross = ((orient(P, Q, R) * orient(P, Q, S) < 0) & (orient(R, S, P) * orient(R, S, Q) < 0))
    shared = (i[:, None] == i[None]) | (i[:, None] == j[None]) | (j[:, None] == i[None]) | (j[:, None] == j[None])
    bad = (cross & ~shared).any(axis=1)
    A = A.copy()
    A[i[bad], j[bad]] = A[j[bad], i[bad]] = False
    return A


def prune_triangles(A: np.ndarray, strength: np.ndarray) -> np.ndarray:
    """Drop links until no three elements are mutually linked

    A grid graph has no triangles; a diagonal link closes one with each
    common neighbour of its two elements. The link that shares the most
    common neighbours goes first (a diagonal inside a complete square has
    two, a side link at most as many as there are wrong diagonals next to
    it), ties broken by the weaker shared boundary.
    """
    A = A.copy()
    while True:
        Af = A.astype(np.float32)  # BLAS: an integer matmul here cost ~3 ms a link; counts stay exact
        common = np.where(A, Af @ Af, 0)
        if not common.any():
            return A
        top = common.max()
        i, j = np.unravel_index(np.argmin(np.where(common == top, strength, np.inf)), A.shape)
        A[i, j] = A[j, i] = False


def _bfs(A: np.ndarray, start: int) -> np.ndarray:
    N = len(A)
    dist = np.full(N, -1)
    dist[start] = 0
    nbrs = [np.flatnonzero(r) for r in A]
    q = deque([start])
    while q:
        n = q.popleft()
        for m in nbrs[n]:
            if dist[m] < 0:
                dist[m] = dist[n] + 1
                q.append(m)
    return dist


def grid_labels(A: np.ndarray, nx: int, ny: int) -> np.ndarray:
    """(N, 2) integer labels (i, j) of the elements, up to a symmetry of the grid

    Raises GridError when the graph is not an nx x ny grid.
    """
    N = len(A)
    if N != nx * ny:
        raise GridError(f"found {N} elements, expected {nx}x{ny} = {nx * ny}")
    deg = A.sum(axis=1)
    corners = np.flatnonzero(deg == 2)
    if len(corners) != 4 or deg.max(initial=0) > 4:
        raise GridError(f"element adjacency has {len(corners)} corner elements (expected 4) and maximum degree {deg.max(initial=0)}")
    # the boundary chain: one cycle through every element with fewer than 4 neighbours
    border = deg < 4
    expected_border = 2 * (nx + ny) - 4
    if border.sum() != expected_border:
        raise GridError(f"boundary chain has {border.sum()} elements, expected {expected_border}")
    sub = A & border[:, None] & border[None, :]
    if np.any(sub[border].sum(axis=1) != 2) or (_bfs(sub, corners[0])[border] < 0).any():
        raise GridError("the boundary chain is not a single closed cycle")
    d0 = _bfs(A, corners[0])
    if (d0 < 0).any():
        raise GridError("the elements do not form one connected grid")
    side = {int(d0[c]) for c in corners[1:]}
    if side != {nx - 1, ny - 1, nx + ny - 2}:
        raise GridError(f"boundary sides do not match a {nx}x{ny} grid (corner distances {sorted(side)})")
    cA = corners[1:][np.argmax(d0[corners[1:]] == nx - 1)]
    dA = _bfs(A, cA)
    i2 = d0 - dA + nx - 1
    j2 = d0 + dA - (nx - 1)
    if np.any(i2 % 2) or np.any(j2 % 2):
        raise GridError("graph distances are inconsistent with a grid")
    lab = np.stack((i2 // 2, j2 // 2), axis=-1)
    if lab.min() < 0 or np.any(lab.max(axis=0) >= (nx, ny)):
        raise GridError("graph distances put elements outside the grid")
    if len({(a, b) for a, b in lab}) != N:
        raise GridError("two elements got the same grid position")
    e0, e1 = np.nonzero(np.triu(A))
    if np.any(np.abs(lab[e0] - lab[e1]).sum(axis=1) != 1) or len(e0) != nx * (ny - 1) + ny * (nx - 1):
        raise GridError("element adjacency is not that of a grid")
    return lab


def _hull_corners(points: np.ndarray) -> np.ndarray:
    """Indices of the 4 convex-hull vertices with the sharpest turns, in hull order"""
    hull = cv2.convexHull(points.astype(np.float32), returnPoints=False).ravel()
    if len(hull) < 4:
        raise GridError("the elements do not span a quadrilateral")
    p = points[hull]
    a, b = p - np.roll(p, 1, axis=0), np.roll(p, -1, axis=0) - p
    turn = np.abs(np.arctan2(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0], (a * b).sum(axis=1)))
    return hull[np.sort(np.argsort(turn)[-4:])]


def _side_chain(points: np.ndarray, a: int, b: int, tol: float) -> np.ndarray:
    """Elements on the segment from element a to element b (within tol px), ordered from a"""
    d = points[b] - points[a]
    L = np.linalg.norm(d)
    rel = points - points[a]
    t = rel @ d / L**2
    off = np.abs(rel[:, 0] * d[1] - rel[:, 1] * d[0]) / L
    on = np.flatnonzero((off < tol) & (t > -0.01) & (t < 1.01))
    return on[np.argsort(t[on])]


def grid_labels_grown(A: np.ndarray, centroids: np.ndarray, nx: int, ny: int) -> np.ndarray:
    """(N, 2) labels (i, j) grown cell by cell from a corner; tolerates diagonal links

    SYNOPSIS

        >>> import numpy as np
        >>> jj, ii = np.mgrid[0:3, 0:4]
        >>> pts = np.stack((ii * 10.0, jj * 6.0), -1).reshape(-1, 2)
        >>> d = np.abs(pts[:, None] - pts[None]) / (10, 6)
        >>> king = (d.max(axis=-1) < 1.5) & ~np.eye(12, dtype=bool)   # sides and all diagonals
        >>> lab = grid_labels_grown(king, pts, 4, 3)
        >>> np.abs(lab - lab[0]).max(axis=0).tolist()
        [3, 2]

    For views where the elements are so small that diagonal neighbours
    touch as much as side ones (steep, distant boards), so that A holds
    every side link and some or all diagonals and grid_labels fails. The
    board's outline is found geometrically: its four corners are the
    sharpest turns of the centroids' convex hull (a perspective view of a
    rectangle is a convex quadrilateral), its first row and column the
    elements along two hull sides, which must hold nx and ny elements and be
    linked in A one after the other. Then each cell is completed: (i+1, j+1)
    is the one common neighbour of (i+1, j) and (i, j+1) other than (i, j)
    (true whether or not the cells' diagonals are linked). Anything else
    raises GridError; the result is checked by `orient` like grid_labels'.
    """
    N = len(A)
    if N != nx * ny:
        raise GridError(f"found {N} elements, expected {nx}x{ny} = {nx * ny}")
    c = _hull_corners(centroids)
    nn = np.sort(np.linalg.norm(centroids[:, None] - centroids[None], axis=-1), axis=1)[:, 1]
    tol = 0.3 * np.median(nn)
    chains = [_side_chain(centroids, c[k], c[(k + 1) % 4], tol) for k in range(4)]
    sizes = [len(ch) for ch in chains]
    if sizes[0] == nx and sizes[1] == ny and sizes[2] == nx and sizes[3] == ny:
        row, col = chains[0], chains[3][::-1]
    elif sizes[0] == ny and sizes[1] == nx and sizes[2] == ny and sizes[3] == nx:
        row, col = chains[3][::-1], chains[0]
    else:
        raise GridError(f"board outline sides hold {sizes} elements, expected {nx} and {ny} alternately")
    if not (A[row[:-1], row[1:]].all() and A[col[:-1], col[1:]].all()):
        raise GridError("the elements along the board's outline are not linked one after the other")
    grid = np.full((ny, nx), -1)
    grid[0], grid[:, 0] = row, col
    nbrs = [set(np.flatnonzero(r)) for r in A]
    taken = set(row) | set(col)
    for j in range(ny - 1):
        for i in range(nx - 1):
            cand = (nbrs[grid[j, i + 1]] & nbrs[grid[j + 1, i]]) - {grid[j, i]} - taken
            if len(cand) != 1:
                raise GridError(f"cannot complete grid cell ({i}, {j}): {len(cand)} candidates")
            grid[j + 1, i + 1] = cand.pop()
            taken.add(grid[j + 1, i + 1])
    lab = np.zeros((N, 2), int)
    jj, ii = np.mgrid[0:ny, 0:nx]
    lab[grid.ravel(), 0], lab[grid.ravel(), 1] = ii.ravel(), jj.ravel()
    return lab


def grid_symmetries(nx: int, ny: int) -> list[np.ndarray]:
    """Affine maps (i, j, 1) -> (i', j') of the grid onto itself, as 2x3 integer matrices"""
    I, J = nx - 1, ny - 1
    g = [
        np.array([[1, 0, 0], [0, 1, 0]]),
        np.array([[-1, 0, I], [0, 1, 0]]),
        np.array([[1, 0, 0], [0, -1, J]]),
        np.array([[-1, 0, I], [0, -1, J]]),
    ]
    if nx == ny:
        g += [np.array([[0, 1, 0], [1, 0, 0]]), np.array([[0, -1, J], [1, 0, 0]]),
              np.array([[0, 1, 0], [-1, 0, I]]), np.array([[0, -1, J], [-1, 0, I]])]
    return g


def grid_array(labels: np.ndarray, values: np.ndarray, nx: int, ny: int) -> np.ndarray:
    """(ny, nx, ...) values placed by their (i, j) labels, NaN elsewhere"""
    out = np.full((ny, nx) + values.shape[1:], np.nan)
    out[labels[:, 1], labels[:, 0]] = values
    return out


def axis_vectors(grid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-corner image vectors to the next corner along i and along j

    grid: (ny, nx, 2). One-sided differences at the edges.
    """
    ei = np.gradient(grid, axis=1)
    ej = np.gradient(grid, axis=0)
    return ei, ej


def bilinear(img: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Bilinear interpolation of img at points p (..., 2), mrcal pixel convention; NaN at NaN points"""
    H, W = img.shape
    nan = ~np.isfinite(p).all(axis=-1)
    x = np.clip(np.where(nan, 0.0, p[..., 0]), 0, W - 1.001)
    y = np.clip(np.where(nan, 0.0, p[..., 1]), 0, H - 1.001)
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    v = (img[y0, x0] * (1 - fx) * (1 - fy) + img[y0, x0 + 1] * fx * (1 - fy)
         + img[y0 + 1, x0] * (1 - fx) * fy + img[y0 + 1, x0 + 1] * fx * fy)
    return np.where(nan, np.nan, v) if nan.any() else v


def checker_phase(frame0: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Signed quadrant contrast of every element in frame 0, (ny, nx)

    s = I(c + a + b) + I(c - a - b) - I(c + a - b) - I(c - a + b), with
    a, b = 0.2 x the vectors to the next corners along i and j: the checker's
    diagonal quadrants, as frame 0's lines run along the grid axes. In the
    true labelling s < 0 where (i + j) is even, s > 0 where odd, and the
    opposite at the marker. Normalised by |s| of a full-contrast element.
    """
    ei, ej = axis_vectors(grid)
    a, b = 0.2 * ei, 0.2 * ej
    s = (bilinear(frame0, grid + a + b) + bilinear(frame0, grid - a - b)
         - bilinear(frame0, grid + a - b) - bilinear(frame0, grid - a + b))
    return s / (np.nanmedian(np.abs(s)) + 1e-12)


def orient(labels: np.ndarray, corners: np.ndarray, frame0: np.ndarray, nx: int, ny: int,
           marker: tuple[int, int]) -> np.ndarray:
    """Relabel so that the marker lands on `marker`; (N, 2) labels

    Tries every symmetry of the grid; the right one makes the checker phase of
    frame 0 agree with parity everywhere and flags exactly the marker. Raises
    GridError when no symmetry fits clearly, or when the board is seen
    mirrored (the i and j axes turn the wrong way in the image).
    """
    N = len(labels)
    j, i = np.mgrid[0:ny, 0:nx]
    expect = np.where((i + j) % 2 == 0, -1.0, 1.0)
    expect[marker[1], marker[0]] *= -1
    fits, scores = [], []
    for g in grid_symmetries(nx, ny):
        lab = (np.column_stack((labels, np.ones(N, int))) @ g.T).astype(int)
        grid = grid_array(lab, corners, nx, ny)
        s = checker_phase(frame0, grid)
        good = (np.sign(s) == expect) & (np.abs(s) > 0.25)
        score = float(np.mean(good))
        scores.append(score)
        # the marker's orbit is a full one, so only the right symmetry puts an
        # inverted element on `marker`; the parity of the rest checks frame 0
        if good[marker[1], marker[0]] and score >= 0.9:
            fits.append((lab, grid))
    if len(fits) != 1:
        raise GridError(
            f"orientation marker not found clearly ({len(fits)} orientations fit; best explains "
            f"{max(scores):.0%} of the checker phases; is the first rotstar frame the one at angle 0?)"
        )
    lab, grid = fits[0]
    why = handedness_reason(grid)
    if why:
        raise GridError(why)
    return lab


def handedness_reason(grid: np.ndarray) -> str:
    """'' or why a labelled board whose i and j axes turn the wrong way in the image is refused

    A camera sees the screen's front: the turn from the i axis to the j axis
    has the sign it has on the screen (clockwise in the image, y down). A
    mirrored view (an image flipped, or the screen seen through a mirror)
    turns the other way. Its labels may be right, but mrcal's board-to-camera
    transform is a rotation: a mirrored board fits only with a reflection
    (determinant -1), so its corners would pull the calibration off.

    >>> jj, ii = np.mgrid[0:3, 0:4]
    >>> grid = np.stack((10.0 * ii, 10.0 * jj), -1)
    >>> handedness_reason(grid), handedness_reason(grid[:, ::-1])[:21]
    ('', 'board seen mirrored (')
    """
    ei, ej = axis_vectors(grid)
    cross = ei[..., 0] * ej[..., 1] - ei[..., 1] * ej[..., 0]
    if not np.isfinite(cross).any() or np.nanmedian(cross) >= 0:
        return ""
    return ("board seen mirrored (the image flipped, or the screen seen through a mirror): the grid's i and j "
            "axes turn the wrong way in the image, and mrcal's board pose, a rotation, cannot fit a mirrored board")


def frame_angle(frame: np.ndarray, grid: np.ndarray, radius: float, n: int = 32) -> float:
    """Angle of a frame's checker lines on the screen, from the i axis toward j, mod pi/2

    grid: (ny, nx, 2) labelled corners; radius: of the ring sampled around
    each corner, in grid steps. On a ring about a checker corner whose lines
    run at phi, the image is a square wave sign(sin 2(alpha - phi)); its second
    harmonic Z has arg Z = -2 phi - pi/2 (+ pi for inverted colours), so the
    sum of Z^2 over the elements gives phi mod pi/2 whatever each element's
    colours. The ring is mapped to the image through the local grid axes, so
    the angle is the screen's, under any tilt.
    """
    ei, ej = axis_vectors(grid)
    ok = np.isfinite(grid).all(axis=-1) & np.isfinite(ei).all(axis=-1) & np.isfinite(ej).all(axis=-1)
    c, ei, ej = grid[ok], ei[ok], ej[ok]
    alpha = (np.arange(n) + 0.5) * 2 * np.pi / n
    pts = c[:, None] + radius * (np.cos(alpha)[None, :, None] * ei[:, None] + np.sin(alpha)[None, :, None] * ej[:, None])
    Z = bilinear(frame, pts) @ np.exp(-2j * alpha)
    W = np.sum(Z**2)
    return float((-np.angle(W) - np.pi) / 4 % (np.pi / 2))


def _angle_diff(a, b):
    """Distance of angles mod pi/2"""
    return np.abs((np.asarray(a) - b + np.pi / 4) % (np.pi / 2) - np.pi / 4)


def frame_angles(frames: np.ndarray, grid: np.ndarray, half_element_fraction: float) -> np.ndarray:
    """(nframes,) frame_angle of every frame, the ring inside the element

    half_element_fraction: the element's half-side over the grid step.
    """
    return np.array([frame_angle(f, grid, 0.55 * half_element_fraction) for f in frames])


def _tolerance(step: float) -> float:
    """How far a frame's measured angle may sit from its own: 0.45 steps (at most 7.5 degrees)

    Measured on boards with 9-10 px corner spacing and a 1.1 px PSF: frame
    angles up to 4.6 degrees off (a third of a step, pi/16), smooth over the
    frames. A frame shown in another frame's place is a whole step (11.25
    degrees) off, so it stays more than the tolerance away however the
    measurement errs by up to 0.1 step.
    """
    return min(0.45 * abs(step), np.pi / 24)


def order_reason(phi: np.ndarray, step: float) -> str:
    """'' or which frames are not at their place in the sequence (angles phi from any labelling)

    Before the marker fixes the labelling the grid's axes may be flipped,
    which turns every angle into its negative: frame k must show k * step
    for one common sign.
    """
    theta = np.arange(len(phi)) * step
    tol = _tolerance(step)
    errs = [_angle_diff(sg * phi, theta) for sg in (1, -1)]
    sg, err = min(zip((1, -1), errs), key=lambda e: np.sum(e[1] > tol))
    wrong = np.flatnonzero(err > tol)
    if not len(wrong):
        return ""
    k = int(wrong[0])
    near = np.flatnonzero(_angle_diff(sg * phi[k], theta) < tol)
    shows = f"the angle of frame {near[0]}" if len(near) else "no angle of the sequence"
    return (f"frames out of order: frame {k} shows {shows} ({len(wrong)} of {len(phi)} frames off their "
            "angle); record the sequence in the order of pattern.json")


def mirror_reason(phi: np.ndarray, step: float) -> str:
    """'' or why frames that turn the wrong way under the final labelling make it wrong

    The marker alone cannot catch a mirrored view when pattern.json's marker
    is mirrored too; the stars' direction of turn (from i toward j) can.
    """
    theta = np.arange(len(phi)) * step
    tol = _tolerance(step)
    informative = _angle_diff(theta, -theta) > 2 * tol
    if not informative.any():
        return ""
    if np.median(_angle_diff(-phi, theta)[informative]) < np.median(_angle_diff(phi, theta)[informative]):
        return ("board seen mirrored: the stars turn the wrong way (an image flipped with a pattern.json "
                "whose marker is mirrored too, or the sequence played backwards); its corner order would be wrong")
    return ""

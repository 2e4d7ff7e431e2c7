"""Display maps: what the screen does to each frame, told apart from what the camera does

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.detect.display_offsets import frame_shifts, dataset_offsets
    >>> j, i = np.mgrid[0:4, 0:5]
    >>> labels = np.column_stack((i.ravel(), j.ravel()))
    >>> q = labels * 20.0 + 50                       # 20 camera px per grid step
    >>> off = np.array([[0.5, 0], [-0.5, 0], [0, 1], [0, -1]])    # display px, 4 frames
    >>> per = q[None] + off[:, None, :] * 0.2        # 0.2 camera px per display px
    >>> per[3, :, 1] += (labels[:, 1] - 1.5) * 100 * 400e-6 * 0.2  # frame 3 also 400 ppm taller
    >>> fs = frame_shifts(per, q, labels, pitch=100)
    >>> (np.round(fs.offsets, 3) + 0.0).tolist()     # display pixels at the board's centre, zero mean
    [[0.5, 0.0], [-0.5, 0.0], [0.0, 1.0], [0.0, -1.0]]
    >>> (np.round(fs.linear[:, 1, 1] * 1e6) + 0.0).tolist()     # the y scale, ppm, zero mean over frames
    [-100.0, -100.0, -100.0, 300.0]
    >>> round(fs.residual_px, 6), round(fs.px_per_display, 3)
    (0.0, 0.2)

A real screen can show the frames of the sequence a pixel or so apart from one
another, and some of them slightly scaled (the player, the video decoder or
the panel's scaler); such a map is fixed in the screen's frame and repeats in
every pose (measured on real captures of a monitor: whole-pixel shifts and one
frame one display pixel taller, doc/detector.md). A camera that moves during a
pose moves the frames too, but differently in every pose.

Per pose, each frame is refined alone for a subset of corners; the frame's
displacement from the joint corner is carried to the screen through the
local Jacobian of the homography from grid to image, and an affine map per
frame is fitted to those screen displacements (robust least squares): the
frame's *display map*, in display pixels, a shift at the board's centre and a
2x2 linear part (scale, rotation, shear), zero mean over the frames (a map
common to all frames cannot be told from the board's pose). What an affine
map on the screen does not explain is the pose's *residual motion*.

Over a dataset, the maps of every pose are compared with their median:
a pose whose frames moved differently from the others had a moving camera
(a shift, or a turn of the image during the sequence, which an affine map
per pose absorbs). With fewer than MIN_POSES poses the two cannot be told
apart and only the residual motion is checked.
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

MIN_POSES = 4
MAX_MOTION = 0.15  # px: frames that moved more against each other than this mean a moving camera
MIN_OFFSET = 0.05  # display px: maps that move no point of the board by more are reported as none
NOISE_FACTOR = 4.0  # maps within this many standard errors of zero are reported as none
MIN_AFFINE = 8  # corners a frame needs for its affine map; with fewer, a shift only
OUTLIER_SIGMA = 4.0  # robust sigmas beyond which a corner's displacement is left out of its frame's map


@dataclasses.dataclass
class FrameShifts:
    """Per-frame display maps of one pose, and the motion they do not explain

    Frame k's displacement on the screen at the display point uv (display
    px, relative to corner (0, 0)) is offsets[k] + linear[k] @ (uv - centre).
    """

    offsets: np.ndarray  # (nframes, 2) display px at the centre, zero mean over frames
    px_per_display: float  # camera pixels per display pixel near the board's corners (median)
    residual_px: float  # median over corners of the largest frame-to-frame disagreement not explained by the maps
    linear: np.ndarray | None = None  # (nframes, 2, 2) the maps' linear parts (scale, turn, shear), zero mean
    centre: np.ndarray | None = None  # (2,) display px: the board's centre, where offsets apply
    uv: np.ndarray | None = None  # (n, 2) display px of the corners the maps were measured at
    applied: bool = False  # whether the pose's joint refinement modelled these maps (they moved a corner enough)

    def __post_init__(self):
        nf = len(self.offsets)
        self.linear = np.zeros((nf, 2, 2)) if self.linear is None else np.asarray(self.linear, float)
        self.centre = np.zeros(2) if self.centre is None else np.asarray(self.centre, float)
        self.uv = np.zeros((1, 2)) + self.centre if self.uv is None else np.asarray(self.uv, float)

    def displacement(self, uv: np.ndarray) -> np.ndarray:
        """(nframes, N, 2) display px by which each frame is shown displaced at display points uv (N, 2)"""
        return map_displacement(self.offsets, self.linear, self.centre, uv)

    def image_shifts(self, jac: np.ndarray, uv: np.ndarray) -> np.ndarray:
        """(nframes, N, 2) camera-pixel displacement of each frame's copy of N corners

        jac: (N, 2, 2) camera pixels per display pixel at the corners; uv: (N, 2) their display points.
        """
        return image_displacement(jac, self.offsets, self.linear, self.centre, uv)


def image_displacement(jac, offsets, linear, centre, uv) -> np.ndarray:
    """(nframes, N, 2) camera px: map_displacement at display points uv (N, 2) through jac (N, 2, 2), camera px
    per display px at each point"""
    return np.einsum("nab,knb->kna", jac, map_displacement(offsets, linear, centre, uv))


def map_displacement(offsets, linear, centre, uv) -> np.ndarray:
    """(nframes, N, 2): offsets (nframes, 2) + linear (nframes, 2, 2) @ (uv (N, 2) - centre (2,))

        >>> map_displacement(np.zeros((1, 2)), np.array([[[0, 0], [0, 1e-3]]]), np.zeros(2),
        ...                  np.array([[0, 100.0]])).tolist()
        [[[0.0, 0.1]]]
    """
    return np.asarray(offsets, float)[:, None] + np.einsum("kab,nb->kna", linear, np.asarray(uv, float) - centre)


def grid_homography(q: np.ndarray, labels: np.ndarray, pitch: float) -> np.ndarray:
    """3x3 homography from display pixels (relative to corner (0, 0)) to image, least squares"""
    H, _ = cv2.findHomography((labels * float(pitch)).astype(np.float64), q.astype(np.float64), 0)
    if H is None:
        raise ValueError("cannot fit a homography to the corners")
    return H


def homography_jacobian(H: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """(N, 2, 2) derivative of the homography's image point by the display point uv (N, 2)"""
    p = np.column_stack((uv, np.ones(len(uv)))) @ H.T
    w = p[:, 2]
    x = p[:, :2] / w[:, None]
    # d(x)/d(uv) = (H[:2, :2] - x H[2, :2]) / w
    return (H[None, :2, :2] - x[:, :, None] * H[None, 2, None, :2]) / w[:, None, None]


def fit_affine(s: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(3, 2) robust least-squares affine s ~ [1, x] @ A of displacements s (n, 2) at points x (n, 2)

    NaN rows are ignored; displacements more than OUTLIER_SIGMA robust sigmas
    off the first fit are left out of the second. With fewer than MIN_AFFINE
    points only a shift (the median) is fitted.

        >>> x = np.array([[i, j] for i in range(-2, 3) for j in range(-2, 3)], float) * 100
        >>> s = 0.5 + x @ np.array([[0, 0], [0, 1e-3]]); s[3] += 9      # one corner off
        >>> (fit_affine(s, x).round(6) + 0.0).tolist()
        [[0.5, 0.5], [0.0, 0.0], [0.0, 0.001]]
    """
    ok = np.isfinite(s).all(axis=1) & np.isfinite(x).all(axis=1)
    A = np.zeros((3, 2))
    if ok.sum() < MIN_AFFINE:
        A[0] = np.median(s[ok], axis=0) if ok.any() else 0.0
        return A
    X = np.column_stack((np.ones(len(x)), x))
    for _ in range(2):
        A = np.linalg.lstsq(X[ok], s[ok], rcond=None)[0]
        r = np.linalg.norm(s - X @ A, axis=1)
        sigma = 1.4826 * np.median(r[ok]) + 1e-9
        keep = ok & (r <= OUTLIER_SIGMA * sigma)
        if keep.sum() < MIN_AFFINE or np.array_equal(keep, ok):
            break
        ok = keep
    return A


def frame_shifts(per_frame: np.ndarray, q: np.ndarray, labels: np.ndarray, pitch: float,
                 jac: np.ndarray | None = None, centre=None) -> FrameShifts:
    """Split per-frame corners (nframes, N, 2) about joint corners q (N, 2) into display maps and the rest

    labels: (N, 2) grid indices (i, j) of the corners; pitch: display pixels per
    grid step. jac: (N, 2, 2) camera px per display px at the corners
    (default: from a homography fitted to q). centre: (2,) display px where
    the maps' offsets apply (the board's centre; default: the corners'
    mean). NaN corners are ignored.
    """
    per_frame = np.asarray(per_frame, float)
    nf = per_frame.shape[0]
    fin = np.isfinite(per_frame).all(axis=2)  # (nf, N)
    ok = (fin.sum(axis=0) >= max(2, nf // 2)) & np.isfinite(q).all(axis=1)
    uv = labels * float(pitch)
    if centre is not None:
        c = np.asarray(centre, float)
    else:
        c = np.mean(uv[ok], axis=0) if ok.any() else np.zeros(2)
    if ok.sum() < 3 or (fin[:, ok].sum(axis=1) < 3).any():
        return FrameShifts(np.zeros((nf, 2)), np.nan, 0.0, centre=c)
    if jac is None:
        jac = homography_jacobian(grid_homography(q[ok], labels[ok], pitch), uv[ok])
    else:
        jac = jac[ok]
    d = per_frame[:, ok] - q[None, ok]  # (nf, n, 2) camera px, NaN where a frame's corner failed
    s = np.einsum("nab,knb->kna", np.linalg.inv(jac), d)  # display px
    A = np.stack([fit_affine(sk, uv[ok] - c) for sk in s])  # (nf, 3, 2)
    A -= A.mean(axis=0)
    shifts = FrameShifts(A[:, 0], np.nan, 0.0, A[:, 1:].transpose(0, 2, 1), c, uv[ok])
    rest = d - shifts.image_shifts(jac, uv[ok])
    rest -= np.nanmedian(rest, axis=0)  # a common shift of all frames is the corner itself
    spread = np.nanmax(np.linalg.norm(rest[:, None] - rest[None], axis=-1), axis=(0, 1))
    shifts.px_per_display = float(np.median(np.sqrt(np.abs(np.linalg.det(jac)))))
    shifts.residual_px = float(np.nanmedian(spread))
    return shifts


def largest_pair_distance(disp: np.ndarray) -> float:
    """Median over points of the largest distance between two frames' displacements: disp (nframes, N, 2)

        >>> largest_pair_distance(np.array([[[0, 0], [0, 0]], [[0.3, 0], [0.1, 0]]]))
        0.2
    """
    return float(np.median(np.linalg.norm(disp[:, None] - disp[None], axis=-1).max(axis=(0, 1))))


@dataclasses.dataclass
class DisplayCheck:
    """The display maps of a dataset and each pose's motion beyond them"""

    offsets: np.ndarray | None  # (nframes, 2) display px at the board's centre, median over poses; None: too few
    motion_px: dict  # pose -> largest frame-to-frame shift not explained by the display, camera px
    poses: int  # how many poses the maps come from
    noise: float = 0.0  # standard error of the maps' displacement of a board point, display px (poses' spread)
    linear: np.ndarray | None = None  # (nframes, 2, 2) the maps' linear parts, median over poses
    centre: np.ndarray | None = None  # (2,) display px: where offsets apply
    uv: np.ndarray | None = None  # (n, 2) display px: board points the maps are judged at (the widest view's)

    def displacement(self) -> np.ndarray:
        """(nframes, n, 2) display px by which the maps move each frame at the board points uv"""
        if self.offsets is None:
            return np.zeros((0, 0, 2))
        lin = np.zeros((len(self.offsets), 2, 2)) if self.linear is None else self.linear
        c = np.zeros(2) if self.centre is None else self.centre
        uv = c[None] if self.uv is None else self.uv
        return map_displacement(self.offsets, lin, c, uv)

    def largest(self) -> float:
        """The most a map moves a board point, display px (0 without maps)"""
        d = self.displacement()
        return float(np.linalg.norm(d, axis=-1).max()) if d.size else 0.0

    def significant(self) -> bool:
        """Whether the maps stand out of their own noise (and move a board point by MIN_OFFSET display px)

        SYNOPSIS

            >>> c = DisplayCheck(np.array([[0.06, 0.0], [-0.06, 0.0]]), {}, 10, noise=0.02)
            >>> c.significant(), dataclasses.replace(c, noise=0.005).significant()
            (False, True)
        """
        if self.offsets is None:
            return False
        return self.largest() >= max(MIN_OFFSET, NOISE_FACTOR * self.noise)

    def moved(self, max_motion: float = MAX_MOTION) -> list[str]:
        """The poses whose frames moved against each other by more than max_motion px"""
        return [p for p, m in self.motion_px.items() if m > max_motion]

    def frame_lines(self) -> list[str]:
        """One line per frame, relative to frame 0: the shift at the board's centre (display px), scale x / y,
        turn, shear (ppm)"""
        lin = np.zeros((len(self.offsets), 2, 2)) if self.linear is None else self.linear
        out = []
        for k, ((x, y), L) in enumerate(zip(self.offsets - self.offsets[0], (lin - lin[0]) * 1e6)):
            out.append(f"frame {k}: shift ({x:+.2f}, {y:+.2f}) display px, "
                       f"scale x {L[0, 0]:+.0f} y {L[1, 1]:+.0f} ppm, turn {(L[1, 0] - L[0, 1]) / 2:+.0f} ppm, "
                       f"shear {(L[1, 0] + L[0, 1]) / 2:+.0f} ppm")
        return out

    def summary(self) -> str:
        if self.offsets is None:
            return (f"display maps not separable from camera motion with {self.poses} pose(s) "
                    f"(need {MIN_POSES}); only what an affine map per frame does not explain is checked")
        if not self.significant():
            return (f"display maps: none (the most a frame is moved: {self.largest():.3f} display px over "
                    f"{self.poses} poses; the estimate's noise {self.noise:.3f})")
        return (f"display maps (per frame relative to frame 0, the same in all {self.poses} poses; a pixel-exact "
                f"player on a good screen shows none: check the player and the screen's scaling):\n  " + "\n  ".join(self.frame_lines()))

    def refinement_maps(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(offsets, linear, centre) for the joint refinement: the maps, or zeros when they are not significant"""
        n = len(self.offsets)
        if not self.significant():
            return np.zeros((n, 2)), np.zeros((n, 2, 2)), np.zeros(2)
        lin = np.zeros((n, 2, 2)) if self.linear is None else self.linear
        return self.offsets, lin, np.zeros(2) if self.centre is None else self.centre

    def as_dict(self) -> dict | None:
        """The maps for a JSON file: offsets (display px at centre), linear (2x2 per frame), centre; None: none"""
        if self.offsets is None:
            return None
        return {"offsets": self.offsets.tolist(), "centre": (self.centre if self.centre is not None
                                                             else np.zeros(2)).tolist(),
                "linear": (self.linear if self.linear is not None else np.zeros((len(self.offsets), 2, 2))).tolist()}


def dataset_offsets(shifts: dict) -> DisplayCheck:
    """Median display maps over poses and each pose's motion beyond them

    shifts: pose -> FrameShifts. A pose's motion is the larger of its residual
    motion and the median over its corners of the largest difference, in
    camera px, between two of its frames' deviations from the dataset's maps.
    """
    good = {p: s for p, s in shifts.items() if np.isfinite(s.px_per_display)}
    if len(good) < MIN_POSES:
        return DisplayCheck(None, {p: s.residual_px for p, s in shifts.items()}, len(good))
    off = np.median(np.stack([s.offsets for s in good.values()]), axis=0)
    lin = np.median(np.stack([s.linear for s in good.values()]), axis=0)
    centre = next(iter(good.values())).centre
    widest = max(good.values(), key=lambda s: np.ptp(s.uv, axis=0).prod() if len(s.uv) > 1 else 0).uv
    dev = {p: s.displacement(s.uv) - map_displacement(off, lin, centre, s.uv) for p, s in good.items()}
    # the median's standard error, from the poses' robust spread about it (pooled over frames, points and axes)
    sigma = 1.4826 * float(np.median(np.concatenate([np.abs(d).ravel() for d in dev.values()])))
    noise = 1.2533 * sigma / np.sqrt(len(good))
    motion = {p: s.residual_px if p not in dev else max(largest_pair_distance(dev[p] * s.px_per_display),
                                                        s.residual_px) for p, s in shifts.items()}
    return DisplayCheck(off, motion, len(good), noise, lin, centre, widest)


def still_display(shifts: dict, max_motion: float = MAX_MOTION) -> DisplayCheck:
    """dataset_offsets, then the maps again from the poses it did not find moved (their motion verdicts kept)

    A camera that moved pulls the median maps of a few poses; the display is
    what the still poses show. With fewer than MIN_POSES still poses the maps
    are not given (offsets None), the verdicts are.
    """
    first = dataset_offsets(shifts)
    moved = set(first.moved(max_motion))
    if not moved or first.offsets is None:
        return first
    still = dataset_offsets({p: s for p, s in shifts.items() if p not in moved})
    return dataclasses.replace(still, motion_px=first.motion_px)


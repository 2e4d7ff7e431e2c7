"""Display offsets: what the screen does to each frame, told apart from what the camera does

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.detect.display_offsets import frame_shifts, dataset_offsets
    >>> j, i = np.mgrid[0:4, 0:5]
    >>> labels = np.column_stack((i.ravel(), j.ravel()))
    >>> q = labels * 20.0 + 50                       # 20 camera px per grid step
    >>> off = np.array([[0.5, 0], [-0.5, 0], [0, 1], [0, -1]])    # display px, 4 frames
    >>> per = q[None] + off[:, None, :] * 0.2        # 0.2 camera px per display px
    >>> fs = frame_shifts(per, q, labels, pitch=100)
    >>> (np.round(fs.offsets, 3) + 0.0).tolist()     # display pixels, zero mean
    [[0.5, 0.0], [-0.5, 0.0], [0.0, 1.0], [0.0, -1.0]]
    >>> round(fs.residual_px, 6), round(fs.px_per_display, 3)
    (0.0, 0.2)

A real screen can show the frames of the sequence a pixel or so apart from one
another (the player, the video decoder or the panel's scaler); the offsets are
fixed in the screen's frame and repeat in every pose (measured on real
captures of a monitor: up to 1.5 camera px, doc/detector.md). A camera that moves during a
pose moves the frames too, but differently in every pose.

Per pose, each frame is refined alone for a subset of corners; the frame's
displacement from the joint corner is carried to the screen through the
local Jacobian of the homography from grid to image, and the per-frame median
of those screen displacements is the frame's *display offset* (display
pixels, zero mean over the frames: a shift common to all frames cannot be
told from the board's position). What a shift on the screen does not explain
(rotation, scale: the camera turned) is the pose's *residual motion*.

Over a dataset, the offsets of every pose are compared with their median:
a pose whose frames moved differently from the others had a moving camera.
With fewer than MIN_POSES poses the two cannot be told apart and only the
residual motion is checked.
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

MIN_POSES = 3
MAX_MOTION = 0.15  # px: frames that moved more against each other than this mean a moving camera
MIN_OFFSET = 0.05  # display px: smaller offsets are reported as none
NOISE_FACTOR = 4.0  # offsets within this many standard errors of zero are reported as none


@dataclasses.dataclass
class FrameShifts:
    """Per-frame displacement of one pose, split into display offsets and the rest"""

    offsets: np.ndarray  # (nframes, 2) display pixels, zero mean over frames
    px_per_display: float  # camera pixels per display pixel near the board's corners (median)
    residual_px: float  # median over corners of the largest frame-to-frame disagreement not explained by offsets

    def image_shifts(self, jac: np.ndarray) -> np.ndarray:
        """(nframes, N, 2) camera-pixel displacement of each frame's copy of N corners

        jac: (N, 2, 2) camera pixels per display pixel at each corner.
        """
        return np.einsum("nab,kb->kna", jac, self.offsets)


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


def frame_shifts(per_frame: np.ndarray, q: np.ndarray, labels: np.ndarray, pitch: float,
                 jac: np.ndarray | None = None) -> FrameShifts:
    """Split per-frame corners (nframes, N, 2) about joint corners q (N, 2) into display offsets and the rest

    labels: (N, 2) grid indices (i, j) of the corners; pitch: display pixels per
    grid step. jac: (N, 2, 2) camera px per display px at the corners
    (default: from a homography fitted to q). NaN corners are ignored.
    """
    per_frame = np.asarray(per_frame, float)
    nf = per_frame.shape[0]
    fin = np.isfinite(per_frame).all(axis=2)  # (nf, N)
    ok = (fin.sum(axis=0) >= max(2, nf // 2)) & np.isfinite(q).all(axis=1)
    if ok.sum() < 3 or (fin[:, ok].sum(axis=1) < 3).any():
        return FrameShifts(np.zeros((nf, 2)), np.nan, 0.0)
    if jac is None:
        jac = homography_jacobian(grid_homography(q[ok], labels[ok], pitch), labels[ok] * float(pitch))
    else:
        jac = jac[ok]
    d = per_frame[:, ok] - q[None, ok]  # (nf, n, 2) camera px, NaN where a frame's corner failed
    s = np.einsum("nab,knb->kna", np.linalg.inv(jac), d)  # display px
    off = np.nanmedian(s, axis=1)
    off -= off.mean(axis=0)
    rest = d - np.einsum("nab,kb->kna", jac, off)
    rest -= np.nanmedian(rest, axis=0)  # a common shift of all frames is the corner itself
    spread = np.nanmax(np.linalg.norm(rest[:, None] - rest[None], axis=-1), axis=(0, 1))
    scale = float(np.median(np.sqrt(np.abs(np.linalg.det(jac)))))
    return FrameShifts(off, scale, float(np.nanmedian(spread)))


@dataclasses.dataclass
class DisplayCheck:
    """The display offsets of a dataset and each pose's motion beyond them"""

    offsets: np.ndarray | None  # (nframes, 2) display px, median over poses; None with too few poses
    motion_px: dict  # pose -> largest frame-to-frame shift not explained by the display, camera px
    poses: int  # how many poses the offsets come from
    noise: float = 0.0  # standard error of one offset component, display px (from the poses' spread)

    def significant(self) -> bool:
        """Whether the offsets stand out of their own noise (and exceed MIN_OFFSET display px)

        SYNOPSIS

            >>> c = DisplayCheck(np.array([[0.06, 0.0], [-0.06, 0.0]]), {}, 10, noise=0.02)
            >>> c.significant(), dataclasses.replace(c, noise=0.005).significant()
            (False, True)
        """
        if self.offsets is None:
            return False
        mag = float(np.linalg.norm(self.offsets, axis=1).max())
        return mag >= max(MIN_OFFSET, NOISE_FACTOR * self.noise)

    def moved(self, max_motion: float = MAX_MOTION) -> list[str]:
        """The poses whose frames moved against each other by more than max_motion px"""
        return [p for p, m in self.motion_px.items() if m > max_motion]

    def summary(self) -> str:
        if self.offsets is None:
            return (f"display offsets not separable from camera motion with {self.poses} pose(s) "
                    f"(need {MIN_POSES}); only rotation and scale between frames are checked")
        mag = np.linalg.norm(self.offsets, axis=1)
        if not self.significant():
            return (f"display offsets: none (largest {mag.max():.3f} display px over {self.poses} poses; "
                    f"the estimate's noise {self.noise:.3f})")
        frames = " ".join(f"({x:+.2f},{y:+.2f})" for x, y in self.offsets)
        return (f"display offsets (display px, per frame, the same in all {self.poses} poses): {frames}; "
                "a pixel-exact player shows none: check the player and the screen's scaling")


def dataset_offsets(shifts: dict) -> DisplayCheck:
    """Median display offsets over poses and each pose's motion beyond them

    shifts: pose -> FrameShifts. A pose's motion is the larger of its residual
    motion and the largest difference, in camera px, between two of its frames'
    deviations from the dataset's offsets.
    """
    good = {p: s for p, s in shifts.items() if np.isfinite(s.px_per_display)}
    if len(good) < MIN_POSES:
        return DisplayCheck(None, {p: s.residual_px for p, s in shifts.items()}, len(good))
    every = np.stack([s.offsets for s in good.values()])
    med = np.median(every, axis=0)
    # the median's standard error, from the poses' robust spread about it (pooled over frames and axes)
    sigma = 1.4826 * float(np.median(np.abs(every - med)))
    noise = 1.2533 * sigma / np.sqrt(len(good))
    motion = {}
    for p, s in shifts.items():
        if not np.isfinite(s.px_per_display):
            motion[p] = s.residual_px
            continue
        dev = (s.offsets - med) * s.px_per_display
        between = float(np.linalg.norm(dev[:, None] - dev[None], axis=-1).max())
        motion[p] = max(between, s.residual_px)
    return DisplayCheck(med, motion, len(good), noise)

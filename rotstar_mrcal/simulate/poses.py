"""Random board poses for a simulated calibration

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.pattern.layout import make_layout
    >>> from rotstar_mrcal.simulate.camera import preset_model
    >>> from rotstar_mrcal.simulate.poses import random_poses, default_distance_range, pose_ok
    >>> model, layout = preset_model("d435"), make_layout()
    >>> default_distance_range(model, layout)
    (0.3, 0.6)
    >>> rt = random_poses(model, layout, 4, np.random.default_rng(0))
    >>> rt.shape, all(pose_ok(model, layout, r) for r in rt)
    ((4, 6), True)

A pose is rt_cam_board (mrcal rt: Rodrigues rotation, then translation) that
maps board points to the camera: p_cam = mrcal.transform_point_rt(rt, p_board).
The board frame has its origin at grid corner (0, 0), x right, y down, +z into
the screen; rt = 0 would put the camera at corner (0, 0) looking at the screen
head-on, seeing it upright.

random_poses draws, per pose:

- the image point where the centre of the band lattice (layout.board_extent())
  appears: stratified over a grid of cells covering the whole imager, so the
  boards reach every part of it (pulled toward the image centre only as far
  as needed for the board to fit);
- the distance from the camera centre to that board centre, uniform in the
  distance range;
- the tilt: the angle between the board normal and the line of sight to the
  board centre, uniform in [min_tilt, max_tilt] (0-60 degrees by default),
  about an in-plane axis of uniform direction;
- the roll about the board normal, uniform in [0, 2 pi).

A pose is kept only if pose_ok: the whole band lattice is in front of the
camera, seen from the front, projects inside the image with a margin, and the
projection does not fold (the Jacobian of board -> image keeps its sign and
mrcal.unproject gives back the same rays).

hanging_poses draws boards that hang over the imager's edges and corners
(the partial views of a calibration that fills the image), per pose:

- the image point of the board centre: near one of the 4 image corners or
  on one of the 4 edges (equally likely), up to HANG_INSET of the image's
  width and height inside;
- the distance: uniform in (0.5 x the near end, the far end) of
  default_distance_range (closer than random_poses: larger elements);
- tilt (uniform in [0, max_tilt_deg]), tilt axis and roll as random_poses;

and keeps it when the camera sees the screen from the front and the fraction
of corners in view (visibility.in_view: the corner's refinement window inside
the image) lies in the `in_view` range.

    >>> from rotstar_mrcal.simulate.poses import hanging_poses
    >>> from rotstar_mrcal.simulate.visibility import in_view
    >>> rt = hanging_poses(model, layout, 3, np.random.default_rng(0))
    >>> f = [in_view(model, layout, r).mean() for r in rt]
    >>> all(0.3 <= v <= 0.75 for v in f)
    True
"""

from __future__ import annotations

import math

import mrcal
import numpy as np

from rotstar_mrcal.pattern.layout import Layout, make_layout
from rotstar_mrcal.simulate.screen import screen_to_board
from rotstar_mrcal.simulate.visibility import in_view as in_view_mask

HANG_INSET = 0.25  # the centre of a hanging board: at most this fraction of the image size inside an edge

REFERENCE_DISTANCE_M = (0.3, 0.6)
"""Distance range for the D435 preset (fx / W = 0.5) and the default layout"""


def _reference_board_width() -> float:
    L = make_layout()
    x0, _, x1, _ = L.board_extent()
    return (x1 - x0) * L.pixel_pitch_m


def board_extent_m(layout: Layout) -> np.ndarray:
    """(2, 2) board-frame corners [[x0, y0], [x1, y1]] of the band lattice, metres"""
    x0, y0, x1, y1 = layout.board_extent()
    return screen_to_board(np.array(((x0, y0), (x1, y1)), float), layout)[:, :2]


def board_centre_m(layout: Layout) -> np.ndarray:
    """(3,) board-frame centre of the band lattice"""
    return np.append(board_extent_m(layout).mean(axis=0), 0.0)


def board_samples(layout: Layout, n: int = 16) -> np.ndarray:
    """(m, 3) board points on the outline of the band lattice and a grid inside it"""
    (x0, y0), (x1, y1) = board_extent_m(layout)
    t = np.linspace(0, 1, n + 1)
    x = x0 + (x1 - x0) * t
    y = y0 + (y1 - y0) * t
    yy, xx = np.meshgrid(y, x, indexing="ij")
    return np.stack((xx, yy, np.zeros_like(xx)), axis=-1).reshape(-1, 3)


def default_distance_range(model: mrcal.cameramodel, layout: Layout) -> tuple[float, float]:
    """REFERENCE_DISTANCE_M scaled so the board fills the same image fraction

    The distance scales with fx / W (narrower field: farther) and with the
    width of the band lattice relative to the default layout.
    """
    fx = model.intrinsics()[1][0]
    W = model.imagersize()[0]
    (x0, _), (x1, _) = board_extent_m(layout)
    k = (fx / W) / 0.5 * (x1 - x0) / _reference_board_width()
    return tuple(float(round(d * k, 12)) for d in REFERENCE_DISTANCE_M)


def _R_axis_angle(axis: np.ndarray, angle) -> np.ndarray:
    return mrcal.R_from_r(np.asarray(axis, float) * np.asarray(angle, float)[..., None])


def look_at_pose(
    model: mrcal.cameramodel,
    layout: Layout,
    target_xy,
    distance: float,
    tilt: float = 0.0,
    tilt_axis: float = 0.0,
    roll: float = 0.0,
) -> np.ndarray:
    """rt_cam_board putting the board centre at `distance` along pixel target_xy

    tilt (radians): angle between the board normal and the line of sight,
    about the in-plane axis at angle tilt_axis from board x; roll (radians)
    about the board normal. tilt = roll = 0 faces the camera squarely, upright.
    """
    ell = mrcal.unproject(np.asarray(target_xy, float), *model.intrinsics(), normalize=True)
    axis = np.cross((0.0, 0.0, 1.0), ell)
    sa = np.linalg.norm(axis)
    R0 = np.eye(3) if sa < 1e-15 else _R_axis_angle(axis / sa, math.atan2(sa, ell[2]))
    Rt = _R_axis_angle(np.array((math.cos(tilt_axis), math.sin(tilt_axis), 0.0)), tilt)
    Rr = _R_axis_angle(np.array((0.0, 0.0, 1.0)), roll)
    R = R0 @ Rt @ Rr
    t = distance * ell - R @ board_centre_m(layout)
    return np.concatenate((mrcal.r_from_R(R), t))


def centred_pose(rt_cam_board, layout: Layout, other: Layout) -> np.ndarray:
    """rt of board `other` seen like `layout`: same rotation, its centre where layout's is; (..., 6)

    SYNOPSIS

        >>> import numpy as np
        >>> from rotstar_mrcal.pattern.layout import make_layout
        >>> a, b = make_layout(), make_layout(nx=9, ny=9)
        >>> rt = np.array([0.1, -0.2, 0.3, 0.01, 0.02, 0.5])
        >>> q = centred_pose(rt, a, b)
        >>> bool(np.allclose(mrcal.transform_point_rt(q, board_centre_m(b)),
        ...                  mrcal.transform_point_rt(rt, board_centre_m(a))))
        True

    For comparing boards of different sizes from the same views (the
    benchmark and the demo show mrgingham, which needs a square grid, the
    same poses as the rotating-star board).
    """
    rt = np.asarray(rt_cam_board, float)
    shift = mrcal.rotate_point_r(rt[..., :3], board_centre_m(layout) - board_centre_m(other))
    return np.concatenate((rt[..., :3], rt[..., 3:] + shift), axis=-1)


def tilt_angle(rt_cam_board: np.ndarray, layout: Layout) -> np.ndarray:
    """Angle (radians) between board normal and line of sight to the board centre; (..., 6) -> (...)"""
    rt = np.asarray(rt_cam_board, float)
    n = mrcal.rotate_point_r(rt[..., :3], np.array((0.0, 0.0, 1.0)))
    c = mrcal.transform_point_rt(rt, board_centre_m(layout))
    cosang = np.sum(n * c, axis=-1) / np.linalg.norm(c, axis=-1)
    return np.arccos(np.clip(cosang, -1, 1))


def pose_ok(model: mrcal.cameramodel, layout: Layout, rt_cam_board, margin_px: float = 0.0) -> bool:
    """Is the whole band lattice seen from the front, unfolded, inside the image with a margin?"""
    rt = np.asarray(rt_cam_board, float)
    W, H = model.imagersize()
    pb = board_samples(layout)
    pc = mrcal.transform_point_rt(rt, pb)
    R = mrcal.R_from_r(rt[:3])
    if np.any(pc[:, 2] <= 0) or (R.T @ rt[3:])[2] <= 0:
        # a point behind the camera, or the camera behind the screen
        # (camera centre -R^T t must have board z < 0)
        return False
    q, dq_dp, _ = mrcal.project(pc, *model.intrinsics(), get_gradients=True)
    if not np.all(np.isfinite(q)):
        return False
    if np.any(q < margin_px) or np.any(q[:, 0] > W - 1 - margin_px) or np.any(q[:, 1] > H - 1 - margin_px):
        return False
    J = dq_dp @ R[:, :2]  # d q / d (board x, y)
    if np.any(np.linalg.det(J) <= 0):
        return False
    v = mrcal.unproject(q, *model.intrinsics(), normalize=True)
    pn = pc / np.linalg.norm(pc, axis=-1, keepdims=True)
    return bool(np.all(np.sum(v * pn, axis=-1) > math.cos(1e-6)))


def random_poses(
    model: mrcal.cameramodel,
    layout: Layout,
    n: int,
    rng: np.random.Generator | int | None = None,
    *,
    distance: tuple[float, float] | None = None,
    max_tilt_deg: float = 60.0,
    margin_px: float | None = None,
    max_tries: int = 400,
    min_tilt_deg: float = 0.0,
) -> np.ndarray:
    """n random valid poses (n, 6) spread over the imager; see the module docstring

    distance defaults to default_distance_range(model, layout); margin_px to
    2% of the image width; the tilt is uniform in [min_tilt_deg,
    max_tilt_deg]. Raises RuntimeError if a pose cannot be placed (board too
    large for the image at these distances).
    """
    rng = np.random.default_rng(rng)
    W, H = (float(v) for v in model.imagersize())
    dmin, dmax = default_distance_range(model, layout) if distance is None else distance
    margin = 0.02 * W if margin_px is None else margin_px
    max_tilt, min_tilt = math.radians(max_tilt_deg), math.radians(min_tilt_deg)
    gx = max(1, math.ceil(math.sqrt(n * W / H)))
    gy = max(1, math.ceil(n / gx))
    cells = rng.permutation(gx * gy)
    centre = np.array(((W - 1) / 2, (H - 1) / 2))
    out = np.empty((n, 6))
    for i in range(n):
        cx, cy = divmod(int(cells[i % len(cells)]), gy)
        target0 = (np.array((cx, cy)) + rng.random(2)) / (gx, gy) * (W, H) - 0.5
        for attempt in range(max_tries):
            pull = min(1.0, attempt / (0.75 * max_tries))
            target = target0 + (centre - target0) * pull
            rt = look_at_pose(
                model,
                layout,
                target,
                rng.uniform(dmin, dmax),
                tilt=rng.uniform(min_tilt, max_tilt),
                tilt_axis=rng.uniform(0, 2 * math.pi),
                roll=rng.uniform(0, 2 * math.pi),
            )
            if pose_ok(model, layout, rt, margin):
                out[i] = rt
                break
        else:
            raise RuntimeError(
                f"could not place pose {i} after {max_tries} tries: the board does not fit "
                f"at {dmin:.3g}-{dmax:.3g} m with tilts up to {max_tilt_deg:g} deg"
            )
    return out


def hang_target(rng: np.random.Generator, W: float, H: float) -> np.ndarray:
    """An image point near an image corner or on an edge, up to HANG_INSET inside (see the module doc)"""
    inset = rng.uniform(0, HANG_INSET, 2) * (W, H)
    far = rng.random(2) < 0.5  # which corner, or which edge
    xy = np.where(far, (W - 1, H - 1) - inset, inset)
    if rng.random() < 0.5:  # an edge: free along one axis
        k = rng.integers(2)
        xy[k] = rng.uniform(0, (W - 1, H - 1)[k])
    return xy


def hanging_poses(
    model: mrcal.cameramodel,
    layout: Layout,
    n: int,
    rng: np.random.Generator | int | None = None,
    *,
    in_view: tuple[float, float] = (0.3, 0.75),
    max_tilt_deg: float = 60.0,
    distance: tuple[float, float] | None = None,
    max_tries: int = 5000,
) -> np.ndarray:
    """n poses (n, 6) of boards hanging over the imager's edges and corners; see the module docstring

    in_view: the range of the fraction of corners in view (both ends
    included); distance defaults to (0.5 near, far) of
    default_distance_range. Raises RuntimeError when max_tries draws give no
    pose.
    """
    rng = np.random.default_rng(rng)
    W, H = (float(v) for v in model.imagersize())
    if distance is None:
        d0, d1 = default_distance_range(model, layout)
        distance = (0.5 * d0, d1)
    max_tilt = math.radians(max_tilt_deg)
    out = np.empty((n, 6))
    for i in range(n):
        for _ in range(max_tries):
            rt = look_at_pose(model, layout, hang_target(rng, W, H), rng.uniform(*distance),
                              tilt=rng.uniform(0, max_tilt), tilt_axis=rng.uniform(0, 2 * math.pi),
                              roll=rng.uniform(0, 2 * math.pi))
            if in_view[0] <= in_view_mask(model, layout, rt).mean() <= in_view[1]:
                out[i] = rt
                break
        else:
            raise RuntimeError(f"no pose with {in_view[0]:.0%}-{in_view[1]:.0%} of the corners in view after "
                               f"{max_tries} draws")
    return out

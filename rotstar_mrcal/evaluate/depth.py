"""What a stereo calibration means for depth: held-out board corners triangulated, against the true depth

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.simulate.camera import preset_model
    >>> from rotstar_mrcal.evaluate.stereo import shifted_pair
    >>> from rotstar_mrcal.evaluate.depth import heldout_points, depth_error
    >>> true = shifted_pair(preset_model("d435"), 0.050)           # a D435-like pair, 50 mm baseline
    >>> cal = shifted_pair(preset_model("d435"), 0.0505)           # calibrated 0.5 mm (1 %) too long
    >>> p = heldout_points(true, spacing=0.02, distances=(0.5, 1.0, 2.0))
    >>> e = depth_error(p, true, cal)
    >>> [round(e.at(z)["mean_pct"], 3) for z in (0.5, 1.0, 2.0)]  # a baseline 1 % long: depth 1 % long
    [1.0, 1.0, 1.0]

The question a stereo user asks of a calibration is "how wrong are my
depths?". Points whose true position is known (the corners of held-out
boards at 0.5, 1 and 2 m, in view of both cameras, heldout_points) are
projected into both cameras with the TRUE models (plus, optionally, the
corner detector's noise), then turned back into depth with the CALIBRATED
pair exactly as a depth camera would: mrcal.rectified_system builds the
rectified pair of the calibrated models, each pixel goes to its rectified
pixel (unproject with the calibrated lens, rotate into the rectified frame,
project), the disparity is the difference of the rectified columns and
mrcal.stereo_range turns it into range, hence the point and its depth z in
camera 0's frame. The depth error is this depth minus the true depth.

Why the rectified disparity and not mrcal.triangulate: stereo matching
(SGBM, the D435's ASIC, mrcal-stereo) searches along the rows of the
rectified images, so an error of the calibration reaches depth through the
disparity; the difference of the rectified rows (row_px) is the other half
of what it does: a few tenths of a pixel break block matching, which a
triangulation would hide by taking the closest point of two skew rays.
method="triangulate" uses mrcal.triangulate (Lee-Civera mid2) instead, for
comparison; without noise the two agree to ~1e-6 of the depth.

What to expect: with a disparity d = f B / Z, a disparity error dd gives a
depth error dZ = Z^2 dd / (f B) (the error of a rotation error about the
vertical axis, dd = f dtheta, grows with Z^2); a baseline length wrong by dB
scales every depth by (B + dB) / B.
"""

from __future__ import annotations

import dataclasses
import math

import mrcal
import numpy as np
from rotstar_mrcal.simulate.camera import fov_deg
from rotstar_mrcal.evaluate.crossval import verdict
from rotstar_mrcal.evaluate.uncertainty import imager_grid

DISTANCES = (0.5, 1.0, 2.0)
"""Depths (m) of the held-out boards"""


def _fov(model) -> tuple[float, float]:
    h, v, _ = fov_deg(model)
    return float(h), float(v)


def _in_view(model, p_cam, margin: float) -> np.ndarray:
    """(...,) bool: p_cam (..., 3) in front of the camera and inside its imager with a margin"""
    W, H = model.imagersize()
    q = mrcal.project(p_cam, *model.intrinsics())
    ok = (p_cam[..., 2] > 0) & np.all(np.isfinite(q), axis=-1)
    return ok & (q[..., 0] >= margin) & (q[..., 1] >= margin) & (q[..., 0] <= W - 1 - margin) \
        & (q[..., 1] <= H - 1 - margin)


def board_grid(nx: int, ny: int, spacing: float) -> np.ndarray:
    """(ny, nx, 3) board corners, metres, centred on the board's middle

    SYNOPSIS

        >>> board_grid(3, 2, 0.1)[:, :, :2].tolist()
        [[[-0.1, -0.05], [0.0, -0.05], [0.1, -0.05]], [[-0.1, 0.05], [0.0, 0.05], [0.1, 0.05]]]
    """
    j, i = np.mgrid[0:ny, 0:nx]
    return np.stack(((i - (nx - 1) / 2) * spacing, (j - (ny - 1) / 2) * spacing, np.zeros((ny, nx))), axis=-1)


def heldout_points(models_true, spacing: float, nx: int = 14, ny: int = 9, distances=DISTANCES, across: int = 3,
                   tilt_deg: float = 20.0, margin: float = 10.0) -> dict[float, np.ndarray]:
    """{depth: (Nboards, ny, nx, 3)} corners of held-out boards, camera 0's (= the reference) frame, metres

    At each depth, boards on an across x across grid of directions over the
    central 70 % of camera 0's field of view, their centres at that depth
    (z), turned by tilt_deg about the vertical axis (alternately +/-); a
    board any of whose corners falls outside either camera's imager (margin
    px) moves toward the middle of the field until it fits, and is left out
    if it never does.
    """
    m0, m1 = models_true
    W, H = m0.imagersize()
    f = np.linspace(0.15, 0.85, across) if across > 1 else np.array((0.5,))
    targets = np.stack(np.meshgrid(f * (W - 1), f * (H - 1)), axis=-1).reshape(-1, 2)
    c = np.array(((W - 1) / 2, (H - 1) / 2))
    g = board_grid(nx, ny, spacing)
    Rt_cam1_ref = m1.Rt_cam_ref()
    out = {}
    for z in distances:
        boards = []
        for k, t in enumerate(targets):
            a = math.radians(tilt_deg) * (1 if k % 2 == 0 else -1)
            R = mrcal.R_from_r(np.array((0.0, a, 0.0)))
            for s in np.linspace(0, 1, 21):
                v = mrcal.unproject(t + (c - t) * s, *m0.intrinsics(), normalize=False)
                p = mrcal.rotate_point_R(R, g) + v / v[2] * z
                if _in_view(m0, p, margin).all() and _in_view(m1, mrcal.transform_point_Rt(Rt_cam1_ref, p),
                                                               margin).all():
                    boards.append(p)
                    break
        out[float(z)] = np.array(boards).reshape(-1, ny, nx, 3)
    return out


def project_pair(p_ref, models) -> np.ndarray:
    """(..., 2, 2): the pixels of points p_ref (..., 3) in camera 0 and camera 1 of a pair (mrcal.triangulate's q)"""
    q = [mrcal.project(mrcal.transform_point_rt(m.rt_cam_ref(), p_ref), *m.intrinsics()) for m in models]
    return np.stack(q, axis=-2)


def rectify_pixels(q, models, models_rectified) -> np.ndarray:
    """(..., 2, 2): pixels q (..., 2, 2) of both cameras moved to their rectified pixels

    Each rectified camera sits where its camera is, turned: unproject with
    the camera's lens, rotate into the rectified frame, project with the
    rectified (LATLON or PINHOLE) model.
    """
    out = []
    for i in (0, 1):
        v = mrcal.unproject(np.ascontiguousarray(q[..., i, :]), *models[i].intrinsics())
        R = mrcal.compose_Rt(models_rectified[i].Rt_cam_ref(), models[i].Rt_ref_cam())[:3]
        out.append(mrcal.project(mrcal.rotate_point_R(R, v), *models_rectified[i].intrinsics()))
    return np.stack(out, axis=-2)


@dataclasses.dataclass
class Stereo:
    """Points of the calibrated pair: where they are and how they were seen"""

    p: np.ndarray  # (..., 3) in calibrated camera 0's frame, metres
    disparity: np.ndarray  # (...,) rectified pixels (NaN: method "triangulate")
    row_px: np.ndarray  # (...,) rectified row of camera 0 minus camera 1's (NaN: "triangulate")


def triangulate(q, models, method: str = "rectified", az_fov_deg: float | None = None,
                el_fov_deg: float | None = None) -> Stereo:
    """The points seen at pixels q (..., 2, 2) by a calibrated pair, in camera 0's frame

    method "rectified": mrcal.rectified_system (LATLON, the fields of view
    of camera 0 unless given), the rectified disparity, mrcal.stereo_range;
    "triangulate": mrcal.triangulate (Lee-Civera mid2).
    """
    q = np.asarray(q, float)
    if method == "triangulate":
        p = mrcal.triangulate(q, tuple(models))
        nan = np.full(q.shape[:-2], np.nan)
        return Stereo(p, nan, nan)
    if method != "rectified":
        raise ValueError(f"method: 'rectified' or 'triangulate', not {method!r}")
    h, v = _fov(models[0])
    rect = mrcal.rectified_system(tuple(models), az_fov_deg=az_fov_deg or h, el_fov_deg=el_fov_deg or v)
    qr = rectify_pixels(q, models, rect)
    d = qr[..., 0, 0] - qr[..., 1, 0]
    r = mrcal.stereo_range(d, rect, qrect0=np.ascontiguousarray(qr[..., 0, :]))
    v_rect = mrcal.unproject(np.ascontiguousarray(qr[..., 0, :]), *rect[0].intrinsics(), normalize=True)
    Rt = mrcal.compose_Rt(models[0].Rt_cam_ref(), rect[0].Rt_ref_cam())
    p = mrcal.transform_point_Rt(Rt, v_rect * r[..., None])
    return Stereo(p, d, qr[..., 0, 1] - qr[..., 1, 1])


def error_stats(err, truth) -> dict:
    """Mean (signed), RMS and 95th percentile of |err| (mm), and the same in % of truth (both metres)

    SYNOPSIS

        >>> s = error_stats(np.array((0.001, -0.002)), np.array((1.0, 1.0)))
        >>> s["mean_mm"], round(s["rms_mm"], 3), s["mean_pct"]
        (-0.5, 1.581, -0.05)
    """
    err, truth = np.asarray(err, float).ravel(), np.asarray(truth, float).ravel()
    ok = np.isfinite(err)
    e, pct = err[ok], 100.0 * err[ok] / truth[ok]
    if not len(e):
        return {"points": 0}
    return {"points": int(len(e)),
            "mean_mm": float(np.mean(e) * 1e3), "rms_mm": float(np.sqrt(np.mean(e**2)) * 1e3),
            "p95_mm": float(np.percentile(np.abs(e), 95) * 1e3),
            "mean_pct": float(np.mean(pct)), "rms_pct": float(np.sqrt(np.mean(pct**2))),
            "p95_pct": float(np.percentile(np.abs(pct), 95))}


@dataclasses.dataclass
class DepthError:
    """Per depth: the true depth z of every held-out corner and the calibrated pair's error"""

    z_true: dict  # depth -> (N, ny, nx) metres
    error: dict  # depth -> (N, ny, nx) calibrated minus true depth, metres
    row_px: dict  # depth -> (N, ny, nx) rectified row difference, px
    method: str
    noise_px: float

    def at(self, depth: float) -> dict:
        s = error_stats(self.error[depth], self.z_true[depth])
        r = np.abs(self.row_px[depth])
        if np.isfinite(r).any():
            s["row_rms_px"] = float(np.sqrt(np.nanmean(r**2)))
        s["boards"] = int(len(self.error[depth]))
        return s

    def summary(self) -> dict:
        return {"method": self.method, "noise_px": self.noise_px,
                "depths": {f"{z:g}": self.at(z) for z in self.error}}


def depth_error(points: dict, models_true, models_cal, noise_px: float = 0.0, rng=None,
                method: str = "rectified") -> DepthError:
    """The calibrated pair's depth error on held-out points {depth: (..., 3) in the true camera 0's frame}

    The points are seen with the true models (plus Gaussian noise of
    noise_px per coordinate, rng a seed or Generator) and triangulated with
    the calibrated ones (triangulate(method)).
    """
    rng = np.random.default_rng(rng)
    z_true, err, row = {}, {}, {}
    for z, p in points.items():
        q = project_pair(p, models_true)
        if noise_px:
            q = q + rng.normal(0, noise_px, q.shape)
        s = triangulate(q, models_cal, method)
        z_true[z] = p[..., 2]
        err[z] = s.p[..., 2] - p[..., 2]
        row[z] = s.row_px
    return DepthError(z_true, err, row, method, float(noise_px))


def depth_uncertainty(p_ref, models, stdev: float = -1.0) -> np.ndarray:
    """(N,) 1-sigma of the depth z of points p_ref (N, 3) from the calibration's noise (mrcal.triangulate)

    stdev < 0: the calibration's own corner noise, estimated from its
    residuals (mrcal's q_calibration_stdev). The models need their
    optimization_inputs (a joint calibration of both cameras). Keep N small:
    mrcal returns the (N, 3, N, 3) covariance.
    """
    q = project_pair(np.asarray(p_ref, float), models)
    _, var = mrcal.triangulate(q, tuple(models), q_calibration_stdev=stdev)
    n = len(q)
    return np.sqrt(var.reshape(n, 3, n, 3)[np.arange(n), 2, np.arange(n), 2])


def grid_points(models, depth: float, gridn_width: int = 8, margin: float = 10.0) -> np.ndarray:
    """(N, 3) points at depth z on the rays of a grid over camera 0's imager (its central 90 %) that camera 1 sees

    SYNOPSIS

        >>> from rotstar_mrcal.simulate.camera import preset_model
        >>> from rotstar_mrcal.evaluate.stereo import shifted_pair
        >>> p = grid_points(shifted_pair(preset_model("d435"), 0.05), 1.0)
        >>> p.shape, bool(np.allclose(p[:, 2], 1.0))
        ((40, 3), True)
    """
    W, H = models[0].imagersize()
    c = np.array(((W - 1) / 2, (H - 1) / 2))
    q = c + (imager_grid((W, H), gridn_width) - c) * 0.9
    v = mrcal.unproject(q, *models[0].intrinsics()).reshape(-1, 3)
    p = v / v[:, 2:] * depth
    return p[_in_view(models[1], mrcal.transform_point_rt(models[1].rt_cam_ref(), p), margin)]


def depth_crossval(pair_a, pair_b, distances=DISTANCES, gridn_width: int = 8) -> dict:
    """mrcal's cross-validation in depth terms: two calibrations of a pair, their depth diff against their uncertainty

    At each depth, points on a grid over camera 0's imager (grid_points of
    pair A) are seen through pair A (its pixels in both cameras) and
    triangulated with pair B; the difference of B's depth from A's is
    compared with sqrt(sigma_A^2 + sigma_B^2), each the 1-sigma depth
    uncertainty from its calibration's corner noise (depth_uncertainty,
    mrcal.triangulate). With only noise between the two, the ratio is about
    1 or below (crossval.verdict's words); far above: model errors.
    {depth: {"diff_median_mm", "diff_p95_mm", "unc_median_mm", "ratio_median", "verdict", "points"}}
    """
    out = {}
    for z in distances:
        p = grid_points(pair_a, z, gridn_width)
        pb = triangulate(project_pair(p, pair_a), pair_b, "triangulate").p
        diff = np.abs(pb[:, 2] - p[:, 2])
        entry = {"points": int(len(p)), "diff_median_mm": float(np.median(diff) * 1e3),
                 "diff_p95_mm": float(np.percentile(diff, 95) * 1e3)}
        try:
            u = np.hypot(depth_uncertainty(p, pair_a), depth_uncertainty(pb, pair_b))
            ratio = float(np.median(diff / u))
            entry.update(unc_median_mm=float(np.median(u) * 1e3), ratio_median=ratio, verdict=verdict(ratio))
        except Exception as e:  # models without optimization_inputs: the diff alone
            entry["error"] = f"{type(e).__name__}: {e}"
        out[f"{z:g}"] = entry
    return out

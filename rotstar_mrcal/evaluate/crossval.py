"""mrcal's cross-validation: two calibrations of one camera, their diff against their uncertainty

SYNOPSIS

    import mrcal
    from rotstar_mrcal.evaluate.crossval import cross_validate
    a = mrcal.cameramodel("A/camera-0.cameramodel")
    b = mrcal.cameramodel("B/camera-0.cameramodel")
    x = cross_validate(a, b)
    x.diff_median, x.unc_median, x.ratio_median, x.verdict
    # e.g. 0.04 0.06 0.7 'consistent'

The procedure of mrcal's docs (how-to-calibrate.org, "Cross-validation
diffs"): calibrate twice from independent data, compare the two models with
mrcal.projection_diff (the implied rotation between the two camera frames is
fitted first, weighted by the uncertainties), and compare the difference
with the uncertainties: "if we had low model errors, the difference would be
about uncertainty_0 + uncertainty_1"; a diff far above twice that means model
errors (a lens model that does not fit, or corners that are wrong in a way
the solve cannot see). Both are evaluated on a grid over the imager of model
0, the second model's uncertainty where the implied transform maps each
point.

Summaries are medians over the grid: the diff, u0 + u1, and the ratio
diff / (u0 + u1). VERDICTS turns the median ratio into a word.
"""

from __future__ import annotations

import dataclasses

import mrcal
import numpy as np

from rotstar_mrcal.evaluate.uncertainty import uncertainty_of_points

VERDICTS = ((1.0, "consistent"), (2.0, "borderline"), (np.inf, "model errors"))
"""(upper bound of the median ratio diff/(u0+u1), verdict)"""


def verdict(ratio: float) -> str:
    """'consistent' (<= 1), 'borderline' (<= 2) or 'model errors'

    SYNOPSIS

        >>> verdict(0.6), verdict(1.5), verdict(7.0)
        ('consistent', 'borderline', 'model errors')
    """
    if not np.isfinite(ratio):
        return "unknown"
    return next(v for bound, v in VERDICTS if ratio <= bound)


@dataclasses.dataclass
class CrossVal:
    """Projection diff and uncertainties of two models on a grid over imager 0"""

    q: np.ndarray  # (Ny, Nx, 2) pixels of model 0
    diff: np.ndarray  # (Ny, Nx) |projection difference|, px
    u0: np.ndarray  # (Ny, Nx) 1-sigma of model 0, px
    u1: np.ndarray  # (Ny, Nx) 1-sigma of model 1 at the mapped points, px
    rotation_deg: float  # the implied rotation between the two camera frames
    distance: float | None  # None: at infinity

    @property
    def ratio(self) -> np.ndarray:
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.diff / (self.u0 + self.u1)

    @property
    def diff_median(self) -> float:
        return float(np.nanmedian(self.diff))

    @property
    def diff_p95(self) -> float:
        return float(np.nanpercentile(self.diff, 95))

    @property
    def unc_median(self) -> float:
        """Median of u0 + u1"""
        return float(np.nanmedian(self.u0 + self.u1))

    @property
    def ratio_median(self) -> float:
        return float(np.nanmedian(self.ratio))

    @property
    def verdict(self) -> str:
        return verdict(self.ratio_median)

    def summary(self) -> dict:
        return {
            "diff_median_px": self.diff_median,
            "diff_p95_px": self.diff_p95,
            "unc_median_px": self.unc_median,
            "u0_median_px": float(np.nanmedian(self.u0)),
            "u1_median_px": float(np.nanmedian(self.u1)),
            "ratio_median": self.ratio_median,
            "rotation_deg": self.rotation_deg,
            "distance_m": self.distance,
            "verdict": self.verdict,
        }


def cross_validate(model0: mrcal.cameramodel, model1: mrcal.cameramodel, gridn_width: int = 40,
                   distance: float | None = None, what: str = "worstdirection-stdev") -> CrossVal:
    """mrcal.projection_diff of two calibrations, and each one's projection uncertainty

    Both models need their optimization_inputs (as mrcal-calibrate-cameras
    writes them). distance None compares at infinity (mrcal's default);
    otherwise at that range, metres.
    """
    difflen, _, q0, Rt10 = mrcal.projection_diff((model0, model1), gridn_width=gridn_width,
                                                 distance=distance, use_uncertainties=True)
    v0 = mrcal.unproject(q0, *model0.intrinsics(), normalize=True)
    u0 = uncertainty_of_points(model0, v0, distance, what)
    if distance is None:
        v1 = mrcal.rotate_point_R(Rt10[:3], v0)
    else:
        v1 = mrcal.transform_point_Rt(Rt10, v0 * distance)
    u1 = uncertainty_of_points(model1, v1, distance, what)
    angle = float(np.degrees(np.linalg.norm(mrcal.r_from_R(Rt10[:3]))))
    return CrossVal(q0, difflen, u0, u1, angle, distance)


"""The demo's camera, lens, pose groups and exposures

SYNOPSIS

    >>> from rotstar_lab.demo.scene import EXPOSURES, exposure_dir
    >>> [label for label, gain in EXPOSURES]
    ['2000 us', '4000 us', '8000 us (saturated)']
    >>> exposure_dir("out", "8000 us (saturated)")
    'out/e8000'

The camera: the `d435` preset (Intel RealSense D435 left IR, 1280x800 Y16,
OPENCV8 lens, fx = 640) with a wavefront PSF from rotstar_mrcal.optics:
Seidel coma growing linearly with the field radius (COMA_WAVES at the image
corners, its centroid put back on the chief ray by an equal and opposite
tilt, so the true model is where the light's centroid lands), plus field
curvature (FOCUS_WAVES x h^2) and diffraction at F/2 with 3 um pixels. The
screen: the default layout (iPad 2360x1640, 14 x 9 corners) with the paper's
whole sequence, its 8-bit frames encoded for a display gamma of
PATTERN_GAMMA and shown with the screen's SCREEN_GAMMA, its pixels under
GLASS_MM of cover glass of index GLASS_INDEX (a laminated tablet's; every ray
refracted on its way to them, simulate.irradiance; the truth stays the
emitting pixels).

The experiment (paper 4.2): two groups of poses, each the iPad turned about
a fixed axis in 30-degree steps from 0 to 60 degrees (the paper: 10-degree
steps) at three places of the field of view; group B starts rolled by 30
degrees, turns about the other axis and is closer, so its corners reach
farther from the image centre. Three exposures, named after the paper's
(2000, 4000, 8000 us): gains 0.35, 0.7 and 1.4 of full scale for a white
screen, the last one saturating the white.
"""

from __future__ import annotations

import math
import os

import numpy as np
from rotstar_mrcal.peers.registry import reason_counts
from rotstar_mrcal.optics.wavefront import Seidel
from rotstar_mrcal.optics.psf import Optics, radial_psf
from rotstar_mrcal.optics.refraction import DEFAULT_INDEX, Glass
from rotstar_mrcal.simulate.dataset import true_corners
from rotstar_mrcal.simulate.poses import look_at_pose, pose_ok
from rotstar_mrcal.pattern.layout import make_layout
from rotstar_mrcal import dataset, simulate

COMA_WAVES = 1.5  # Seidel coma at the image corners (h = 1), waves
FOCUS_WAVES = 0.3  # field curvature: defocus at the image corners, waves
EXPOSURES = (("2000 us", 0.35), ("4000 us", 0.7), ("8000 us (saturated)", 1.4))
NOISE = 0.01  # read noise, fraction of full scale
SHOT = 1e-4  # shot noise variance per unit signal (a 10000 e- full well)
CAPTURES = 8  # checkerboard (and star) captures averaged
PATTERN_GAMMA = 2.2  # the display gamma rotstar-pattern encodes its frames for
SCREEN_GAMMA = 2.4  # the screen's own: a modest mismatch (simulate.screen.shown_light)
GLASS_MM = 0.7  # the screen's cover glass (issue 22: laminated tablets 0.5-1.5 mm), as make stereo's
GLASS_INDEX = DEFAULT_INDEX
TILTS = (0, 30, 60)
LENSMODEL = "LENSMODEL_OPENCV5"
SQUARE_N = 9  # mrgingham's board

GROUPS = {
    # name: (targets (x, y, sign of the turn), distance m, tilt axis deg, roll deg)
    "A": (((430, 400, 1), (640, 400, -1), (850, 400, -1)), 0.30, 90.0, 0.0),
    "B": (((250, 200, 1), (1030, 600, -1), (250, 600, 1)), 0.26, 0.0, 30.0),
}


def exposure_dir(out: str, label: str) -> str:
    """out/e<number>: the folder of one exposure"""
    return os.path.join(out, "e" + label.split()[0])


def camera_and_boards(pattern_dir: str):
    """(the true camera model, the pattern's layout, the square SQUARE_N x SQUARE_N board on the same screen)"""
    _, layout = dataset.read_pattern(pattern_dir)
    square = make_layout(screen=(layout.screen_width, layout.screen_height), pixel_pitch_m=layout.pixel_pitch_m,
                         pitch=layout.pitch, band=layout.band, nx=SQUARE_N, ny=SQUARE_N)
    return simulate.preset_model("d435"), layout, square


def pose_group(model, layout, targets, distance, tilt_axis_deg, roll_deg, tilts=TILTS, margin=20.0) -> np.ndarray:
    """The board turned about one axis at each target; a target moves toward the centre until it fits"""
    W, H = model.imagersize()
    c = np.array(((W - 1) / 2, (H - 1) / 2))
    out = []
    for x, y, sign in targets:
        for tilt in tilts:
            for k in np.linspace(0, 1, 41):
                t = np.array((x, y)) + (c - (x, y)) * k
                rt = look_at_pose(model, layout, t, distance, math.radians(tilt) * sign,
                                  math.radians(tilt_axis_deg), math.radians(roll_deg))
                if pose_ok(model, layout, rt, margin):
                    out.append(rt)
                    break
            else:
                raise RuntimeError(f"no valid pose near {x, y} at {tilt} degrees")
    return np.array(out)


def group_poses(model, layout, tilts=TILTS) -> dict[str, np.ndarray]:
    """{group: (npose, 6) rt_cam_board}"""
    return {g: pose_group(model, layout, *spec, tilts=tilts) for g, spec in GROUPS.items()}


def reach_px(model, layout, rts: dict) -> dict[str, float]:
    """{group: the 90th percentile of its corners' distance from the image centre, px}"""
    c = (np.array(model.imagersize()) - 1) / 2
    return {g: float(np.percentile(np.linalg.norm(true_corners(model, layout, v) - c, axis=-1), 90))
            for g, v in rts.items()}


def screen_glass() -> Glass:
    """The cover glass over the screen's pixels (every capture of every method is seen through it)"""
    return Glass.mm(GLASS_MM, GLASS_INDEX)


def coma_psf(imagersize):
    W, H = imagersize
    centre = ((W - 1) / 2, (H - 1) / 2)
    return radial_psf(Seidel(coma=COMA_WAVES, tilt=-COMA_WAVES, focus=FOCUS_WAVES), centre, Optics(),
                      node_px=64, field_radius_px=math.hypot(*centre), zero_centroid=True)


def setup_notes(npose, reach) -> str:
    """The report's set-up section (Markdown)"""
    return f"""\
Simulated Intel RealSense D435 infrared camera (1280x800 Y16, `OPENCV8` lens with fx = 640) looking at an
iPad (2360x1640, 264 ppi) showing the paper's whole sequence (`rotstar-pattern --paper-sequence`): the
rotating star (14 x 9 corners, 8 frames), the 13 identity frames, 4-step phase shifts along x and y
(8 frames), a checkerboard and the 16-segment star of Schops et al. The frames are 8-bit, encoded for a
display gamma of {PATTERN_GAMMA}; the screen's own gamma is {SCREEN_GAMMA} (a modest mismatch: it bends the
phase shifts' sinusoids, the binary frames do not notice). The screen's pixels lie under {GLASS_MM:g} mm of
cover glass (index {GLASS_INDEX:g}, a laminated tablet's): every ray is refracted on its way to them, so every
method's corners are seen displaced by an amount that changes with the viewing angle; the truth is the
emitting pixels. Every calibration is corrected for the known glass (`rotstar-crossval --glass {GLASS_MM:g}`);
the tables give the corrected calibrations, and the plain ones beside them in the glass table.
The lens has a wavefront PSF (rotstar_mrcal.optics): coma growing with the field radius to {COMA_WAVES} waves
at the image corners (a comet about {3 * 2 * 0.367 * COMA_WAVES:.1f} px long there; its centroid is kept on the
chief ray, so the true model is where the light's centroid lands), field curvature ({FOCUS_WAVES} waves of
defocus at the corners), diffraction at F/2. Noise: read noise {NOISE:.0%} of full scale plus shot noise;
16-bit values.

Two pose groups as in the paper: in each, the iPad is turned about a fixed axis in 30-degree steps from 0
to 60 degrees (the paper: 10-degree steps), at three places in the field of view ({npose['A']} poses in A,
{npose['B']} in B). Group B is rolled by 30 degrees, turns about the other axis, is closer and spread wider:
90% of its corners lie within {reach['B']:.0f} px of the image centre, against {reach['A']:.0f} px for A.
Three exposures (gains 0.35, 0.7 and 1.4 of full scale for white; the last saturates the white).
Each method detects its own corners on the same poses: rotstar on the 8 rotating-star frames and the 13
identity frames (one capture each); rotstar-psf-sim the same, less the symmetric fit's offset from the
light's centroid simulated through the coma its edges show, pooled over the group's poses as
`rotstar-detect --refine psf-sim` pools a dataset's (doc/blur-map.md); phase shifting on the 8 phase-shift frames (one capture each), from
rotstar's corners (`phase` rejects a corner whose window holds a clipped value, `phase-keep` fits the
clipped values as the paper's pipeline does); the star (the symmetric refinement on the one star frame,
from rotstar's corners) and the checkerboard methods on their frame averaged over 8 captures (the same
photons as the 8 rotating-star frames); mrgingham on a square 9 x 9 checkerboard seen from the same poses. Every corner set is calibrated with mrcal
(`{LENSMODEL}`: the true lens has no rational terms, and the splined model needs more poses than a group
has) on group A and on group B.
"""


def rejection_notes(rejected: dict) -> str:
    """The report's line on the corners a method rejected, per exposure (Markdown; '' if none)

    rejected: {exposure label: per pose {method: (ny, nx) reasons, '' = found}}.

    >>> r = np.array([["", "saturated: a sample at full scale"], ["", ""]], dtype=object)
    >>> print(rejection_notes({"2000 us": [{"phase": r}, {"phase": r}]}))
    <BLANKLINE>
    Corners rejected: phase at 2000 us: 2 of 8 (2 saturated: a sample at full scale).
    <BLANKLINE>
    """
    parts = []
    for label, per_pose in rejected.items():
        for m in dict.fromkeys(k for p in per_pose for k in p):
            r = np.concatenate([np.asarray(p[m], dtype=object).ravel() for p in per_pose if m in p])
            n = int(sum(bool(x) for x in r))
            if n:
                parts.append(f"{m} at {label}: {n} of {r.size} ({reason_counts(r)})")
    return "\nCorners rejected: " + "; ".join(parts) + ".\n" if parts else ""

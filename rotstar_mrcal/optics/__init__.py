"""Optics of the synthetic experiment: Seidel wavefront PSFs and the Cramer-Rao bound

SYNOPSIS

    >>> from rotstar_mrcal.optics.wavefront import Seidel
    >>> from rotstar_mrcal.optics.psf import Optics, wavefront_psf, asymmetry
    >>> k = wavefront_psf(Seidel(coma=4.0), Optics(), supersample=4)
    >>> asymmetry(k) > 0.2, asymmetry(wavefront_psf(Seidel(spherical=2.0), Optics(), 4)) < 1e-9
    (True, True)

Modules, one concept each:

    wavefront  Seidel coefficients and the pupil function P exp(2 pi i W)
    psf        H = A |F(P exp(2 pi i W))|^2 sampled at the renderer's sub-pixels;
               adapters for simulate.render_irradiance (SeidelPSF, radial_psf, LensPSF)
    crlb       Fisher information of a corner position and its Cramer-Rao bound

See doc/optics.md.
"""

from rotstar_mrcal.optics.crlb import closed_form_corner_bound, crlb_cov, crlb_rms, fisher_information
from rotstar_mrcal.optics.psf import (
    LensPSF, Optics, SeidelPSF, asymmetry, centroid_px, gaussian_psf, geometric_radius_px, radial_psf,
    second_moment_px, wavefront_psf,
)
from rotstar_mrcal.optics.wavefront import TERMS, Seidel, pupil_function, wavefront

__all__ = [
    "Seidel", "TERMS", "wavefront", "pupil_function",
    "Optics", "wavefront_psf", "gaussian_psf", "SeidelPSF", "radial_psf", "LensPSF",
    "asymmetry", "centroid_px", "second_moment_px", "geometric_radius_px",
    "fisher_information", "crlb_cov", "crlb_rms", "closed_form_corner_bound",
]

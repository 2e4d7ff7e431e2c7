"""Optics: Seidel wavefront PSFs, the point-spread functions the simulator applies, and the Cramer-Rao bound

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
    blur       point-spread functions applied to a supersampled image (Gaussian, a kernel, one per tile, blended
               between nodes;
               the renderer's psf argument), and the convolution they share
    refraction where a pixel under a cover glass is seen from a point (Snell's law at the glass)
    crlb       Fisher information of a corner position and its Cramer-Rao bound

See doc/optics.md.
"""

from rotstar_mrcal.lazy import attach

# each name imported from its module when first used: importing the package imports none of them
__getattr__, __dir__, __all__ = attach(__name__, {
    "wavefront": ["Seidel", "TERMS", "pupil_function"],  # (the function wavefront: optics.wavefront.wavefront)
    "psf": ["Optics", "wavefront_psf", "gaussian_psf", "SeidelPSF", "radial_psf", "LensPSF",
            "asymmetry", "centroid_px", "second_moment_px", "geometric_radius_px"],
    "blur": ["GaussianPSF", "KernelPSF", "TiledPSF", "SmoothPSF", "as_psf", "gaussian_kernel"],
    "crlb": ["fisher_information", "crlb_cov", "crlb_rms", "closed_form_corner_bound"],
})

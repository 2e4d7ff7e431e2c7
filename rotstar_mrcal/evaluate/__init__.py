"""Evaluation of calibrations: against the truth, on held-out poses, against each other

SYNOPSIS

    >>> from rotstar_mrcal.simulate.camera import preset_model
    >>> from rotstar_mrcal.evaluate import uncertainty
    >>> q = uncertainty.imager_grid(preset_model("d435").imagersize(), 8)
    >>> q.shape
    (5, 8, 2)

Modules, one concept each:

    truth        on simulated data: the calibrated model against the true one
    heldout      the paper's metric: poses of a test set solved with the
                 intrinsics fixed, mean reprojection error
    tilts        the held-out error grouped by the tilt of the test poses
    uncertainty  mrcal's projection uncertainty on a grid over the imager
    crossval     mrcal's cross-validation: the projection diff of two
                 calibrations against the sum of their uncertainties
    detection    a dataset's corners by several methods as corners.vnl files;
                 one recording split into two interleaved groups
    compare      every number above for one corner set and two pose groups
    groups       several corner sets of two pose groups side by side
    stereo       a camera pair: each camera and the extrinsics against the
                 truth, two calibrations of the pair cross-validated
    depth        a calibrated pair in depth terms: held-out board corners
                 triangulated against the true depth

Functions of arrays, models and file names; report/ draws and writes them.
See doc/validation.md.
"""

"""Calibration with mrcal, and the numbers that say whether it is any good

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.simulate import preset_model
    >>> from rotstar_mrcal.validate import heldout, uncertainty
    >>> model = preset_model("d435")
    >>> q = uncertainty.imager_grid(model.imagersize(), 8)
    >>> q.shape
    (5, 8, 2)

Modules, one concept each:

    calibrate    the mrcal-calibrate-cameras command (lens model, focal seed,
                 object geometry, image glob), running it, the inputs'
                 checks, the lean-then-splined choice and the model's checks
                 (calibrate(): a Calibration result with its JSON)
    detection    a dataset's corners by several methods as corners.vnl files;
                 one recording split into two interleaved groups
    mrcalshow    mrcal's mrcal-show-* views of a calibration, with scales for
                 our small errors and a gnuplot that reads PNG
    modelcheck   rotstar-calibrate's default model against rotstar-detect's
                 printed command on simulated captures (make calib-bench)
    heldout      the paper's metric: poses of a test set solved with the
                 intrinsics fixed, mean reprojection error
    uncertainty  mrcal's projection uncertainty on a grid over the imager
    crossval     mrcal's cross-validation: the projection diff of two
                 calibrations against the sum of their uncertainties
    truth        on simulated data: the calibrated model against the true one
    cornersets   the corner sets of one dataset by each detector (rotstar and
                 the checkerboard baselines)
    compare      all of the above for several corner sets of the same poses
    plots        the figures (matplotlib)
    report       the Markdown and HTML report, and its headline table
    stereo       a camera pair: each camera and the extrinsics against the
                 truth, two calibrations of the pair cross-validated
    depth        a calibrated pair in depth terms: held-out board corners
                 rectified (mrcal.rectified_system), triangulated, against
                 the true depth; mrcal's depth uncertainty
    stereoreport the report's stereo section (make stereo)

Everything here is a function of arrays, models and file names; the
command-line tools (rotstar-calibrate, rotstar-crossval, rotstar-report) do
the printing. See doc/validation.md for what the numbers mean.
"""

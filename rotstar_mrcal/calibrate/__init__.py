"""Calibration: mrcal's solve of the detected corners, the model's choice and its checks

Modules, one concept each:

    focal       a focal-length seed for mrcal from the detected boards
    cornerset   a corner set on disk: its corners.vnl, the dataset it came
                from, the imager size, the truth (CornerSet)
    solve       the mrcal-calibrate-cameras command for a corners.vnl,
                running it, the inputs' checks, the fit's checks, the
                lean-then-splined choice (calibrate(): a Calibration)
    rig         several cameras calibrated at once, one glob per camera

The stage after detect/; evaluate/ measures what it made. See
doc/validation.md.
"""

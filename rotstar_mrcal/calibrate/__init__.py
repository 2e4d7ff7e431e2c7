"""Calibration: mrcal's solve of the detected corners, the model's choice and its checks

Modules, one concept each:

    command     the mrcal-calibrate-cameras command: its argv for a corners.vnl,
                the lens model by name, the hint rotstar-detect prints
    focal       a focal-length seed for mrcal from the detected boards
    cornerset   a corner set on disk: its corners.vnl, the dataset it came
                from, the imager size, the truth (CornerSet, TestSet, TrueCamera)
    checks      the inputs' checks before mrcal runs, the fit's after each solve
    solve       running mrcal-calibrate-cameras, what a calibration says about
                itself, the lean-then-splined choice (calibrate(): a Calibration)
    rig         several cameras calibrated at once, one glob per camera

In import order: command imports nothing of calibrate/; focal, cornerset
and checks import command; solve imports those four, rig all of them.

The stage after detect/; evaluate/ measures what it made. See
doc/validation.md.
"""

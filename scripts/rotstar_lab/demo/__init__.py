"""`make demo` (scripts/demo.py): the paper's real-world experiment on a simulated D435 with coma

SYNOPSIS

    from rotstar_lab.demo import scene, capture, sets
    model, layout, square = scene.camera_and_boards(pattern_dir)
    rts = scene.group_poses(model, layout)                  # {"A": (9, 6), "B": (9, 6)}
    found = capture.capture_all(jobs, ...)                  # every pose rendered once, every exposure detected
    vnls = sets.write_group(...)                            # the corner sets rotstar-crossval calibrates

Modules, one concept each:

    scene    the camera, its coma PSF, the two pose groups, the exposures, the set-up notes
    capture  one pose rendered once, then per exposure: noise, every method's corners, the square board's PNG
    sets     the corner sets and the truth of each group on disk; mrgingham over all square-board images
    plots    the close-ups of one corner at each exposure

The pattern is the paper's whole sequence (rotstar-pattern --paper-sequence:
the rotating star, the phase shifts, the checkerboard, the star); the methods
are rotstar_mrcal.peers.registry.METHODS with demo=True (rotstar, the checkerboard
methods, phase, phase-keep and star). rotstar-report turns the run into the
paper's table by tilt and its claims as verdicts (validate.tilts,
validate.claims). See doc/validation.md (the demo).
"""

"""The paper's synthetic experiment (4.1): PSF symmetry, patterns, refiners, the bound

SYNOPSIS

    >>> from rotstar_mrcal.synth.experiment import quick_protocol, run_task
    >>> from rotstar_mrcal.synth.table import tabulate, over_tilts
    >>> from rotstar_mrcal.synth.verdicts import verdicts
    >>> p = quick_protocol(phis_deg=(40,), alphas_deg=(0, 60, 120), repeats=2, noises=(0.0,),
    ...                    patterns=("checkerboard", "rotstar"), refiners=("symmetric",))
    >>> res = {(a, 0.0, 40): run_task(p, a, 40, (0.0,))[0.0] for a in p.aberrations}
    >>> rows = over_tilts(tabulate(p, res))
    >>> [round(r["range"], 2) for r in rows]        # coma: the detection moves with the view
    [0.09, 0.02, 0.0, 0.0]
    >>> verdicts(rows)[0].status           # finding 1, from these numbers
    'reproduced'

Modules, one concept each:

    patterns   the checkerboard, rotating-star and 16-segment-star corners as wedges,
               the phase shifts as fringes
    views      the poses: a tilt phi about an in-plane axis at angle alpha
    imaging    exact sub-pixel coverage, PSF convolution, block summation; the
               pixel-integrated gradients for the Cramer-Rao bound
    refiners   OpenCV cornerSubPix, the saddle fit, the symmetric refinement (Eq. 1),
               the phase-shift corner (peers.phase); which applies to which pattern
    metrics    pairwise-distance range, RMS error, failure rate
    experiment the protocol and one task: render, expose, refine
    sweep      run the configurations on local processes or Dask, cached
    table      rows per configuration and their means over the tilts
    verdicts   the paper's three findings, decided from the table; our phase observation
    bound      the CRLB of each pattern for one PSF
    plots      figures (range against tilt, PSFs, what the refiners see)

The command line is rotstar-synth (rotstar_mrcal.cli.synth); see doc/optics.md.
"""

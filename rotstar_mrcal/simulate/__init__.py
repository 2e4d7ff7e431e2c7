"""Simulator of "the screen seen by a camera": ground truth for tests and benchmarks

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.pattern.layout import make_layout
    >>> from rotstar_mrcal import simulate
    >>> layout = make_layout(screen=(800, 600), pitch=100, band=24)
    >>> model = simulate.preset_model("pinhole-small")
    >>> screen = simulate.make_screen(simulate.exact_frames(layout), layout)
    >>> rt = simulate.random_poses(model, layout, 1, np.random.default_rng(0))[0]
    >>> E = simulate.render_irradiance(screen, model, rt, supersample=4, psf=1.0)
    >>> img = simulate.expose(E, gain=0.9, noise=0.01, bits=16, rng=0)
    >>> img.shape, img.dtype
    ((19, 400, 640), dtype('uint16'))

Modules, one concept each:

    camera    camera presets; the cached per-pixel rays of a camera model
    screen    the screen as a light source (frames -> summed-area tables)
    irradiance  rays -> board plane -> screen, area-sampled sub-pixels, PSF, blocks
    exposure  gain, black level, noise, saturation, 8/16-bit quantisation
    poses     random calibration poses that keep the board inside the image;
              boards hanging over the image's edges (partial views)
    visibility  which corners a detector can report: true refinement windows, in view
    dataset   write a dataset + truth.json/truth.cameramodel; load the truth
    rig       several cameras (a D435's infrared pair and colour camera): poses, dataset, truth

See doc/simulator.md.
"""

from rotstar_mrcal.lazy import attach

# each name imported from its module when first used: importing the package imports none of them
__getattr__, __dir__, __all__ = attach(__name__, {
    "camera": ["PRESETS", "RayGrid", "camera_rays", "fov_deg", "preset_model"],
    "dataset": ["Settings", "Truth", "load_truth", "pose_names", "render_pose", "true_corners", "write_dataset"],
    "exposure": ["expose", "full_scale_code"],
    "poses": ["default_distance_range", "hanging_poses", "look_at_pose", "pose_ok", "random_poses", "tilt_angle"],
    "irradiance": ["render_irradiance"],
    "screen": ["Screen", "exact_frames", "make_screen", "png_frames", "shown_light"],
})

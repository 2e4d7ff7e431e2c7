"""The rotating-star detector: recorded frames of a pose in, labelled sub-pixel corners out

    from rotstar_mrcal.detect import detect_pose, detect_dataset

The stages, in the paper's order (section 3):

    sequence         is this the rotating-star sequence, in order? (the
                     border bands' colour, frame by frame)
    response         the response map: where the display sequence changes (3.2)
    boundaries       the element boundaries: the border lattice and the
                     elements it encloses (3.2, first step)
    rough            rough corners: the point nearest to the checker lines of
                     every frame (3.2, second step)
    indexing         grid indexing: which element is corner (i, j) (3.2,
                     third step); nearest: its nearest-element queries
    identity         the identity frames name every element in view (ours,
                     beside the paper's graph); consistency: each element
                     against its labelled neighbours
    elements         the labelled elements: rough corners, grid labels and
                     refinement windows
    refine           symmetric refinement: the point about which every frame
                     is point-symmetric (3.3, Eq. 1)
    display_offsets  what the screen does to each frame, told apart from what
                     the camera does

    pipeline         one pose through the stages: detect_pose
    run              a whole dataset (dataset.open_dataset), one camera or
                     several: detect_dataset -> Detection (corners, per-pose
                     reasons, focal seeds, mrcal's command)
    rig              several cameras: each board's labelling checked across
                     the cameras

The methods rotstar is compared against are in rotstar_mrcal.peers. See
doc/detector.md.
"""

import importlib

__all__ = ["detect_pose", "detect_dataset"]
_HOME = {"detect_pose": "rotstar_mrcal.detect.pipeline", "detect_dataset": "rotstar_mrcal.detect.run"}


def __getattr__(name: str):
    """detect_pose and detect_dataset, imported when first asked for (PEP 562, as scikit-image's lazy_loader)

    Importing a stage (rotstar_mrcal.detect.elements, which the simulator
    uses) runs this package's __init__ first: an eager re-export here would
    make every stage import the whole pipeline, the dataset runner and,
    through it, calibrate/ (the mrcal command), a circle through every
    package that uses one stage.
    """
    if name in _HOME:
        return getattr(importlib.import_module(_HOME[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + __all__)

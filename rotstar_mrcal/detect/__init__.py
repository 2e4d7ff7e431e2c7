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
    run              a whole dataset: detect_dataset
    rig              several cameras' poses, their labelling checked across
                     cameras

The methods rotstar is compared against are in rotstar_mrcal.peers. See
doc/detector.md.
"""

from rotstar_mrcal.detect.pipeline import detect_pose
from rotstar_mrcal.detect.run import detect_dataset

__all__ = ["detect_pose", "detect_dataset"]

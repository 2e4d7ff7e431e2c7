"""Split the recordings of several cameras with the same frame boundaries

SYNOPSIS

    from rotstar_mrcal.capture.rig_segment import segment_rig
    rs = segment_rig([left.frames, right.frames, colour.frames], pattern["frames"], layout,
                     [65535, 65535, 255])
    rs.reference                         # the camera whose recording set the boundaries (0 unless it failed)
    rs.cameras[2].images["rotstar_00.png"]    # camera 2's average over the same displayed frame
    rs.cameras[2].ranges                 # its frames averaged: camera 0's, trimmed at a late transition

Each camera's recording holds one frame per lockstep step (capture.rig):
frame t of every camera was taken at about the same instant. The displayed
frames are found on one camera, the reference, by segment.segment (camera 0
by default; when its recording cannot be split, the next camera that can
be, with a note: the camera that sees the screen best sets the
boundaries). Every other camera then takes the same frames, checked:

1. all recordings hold the same number of frames, and every frame of one
   camera has one size (else SegmentError: the recordings were not made
   together, or a camera changed mode);
2. over the frames the reference averaged for each pattern frame, the
   camera's own difference signal (its screen pixels, its threshold) must be
   quiet: it saw one still pattern frame there. A camera that is a frame
   late (the colour camera's clock) shows the transition at one end of the
   range; those end frames are dropped, and at least min_average frames
   must remain. A change in the middle of the range is an error naming the
   camera, the pattern frame and the camera frames;
3. the camera's levels over the loop (the start marker, then every pattern
   frame) must follow the levels pattern.json predicts (segment.check_order),
   as for the reference: a camera that saw a different loop entry fails
   here.

The averages are each camera's own frames in its own units; nothing is
resampled. Failures raise SegmentError with a one-line reason.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from rotstar_mrcal.pattern.loop import expected_levels, player_loop
from rotstar_mrcal.pattern.layout import Layout
from rotstar_mrcal.capture.motion import difference_signal, screen_pixels
from rotstar_mrcal.capture.segment import (
    Options, Segmentation, SegmentError, _mean, check_order, segment, threshold,
)


@dataclasses.dataclass
class RigSegmentation:
    cameras: list[Segmentation]  # per camera: its averages and ranges; stretches and loops are the reference's
    reference: int  # the camera whose recording set the boundaries
    notes: list[str]  # e.g. why another camera than 0 set them, frames trimmed per camera

    def summary(self) -> str:
        return f"boundaries from camera {self.reference}: " + self.cameras[self.reference].summary()


def check_recordings(recordings, names: list[str] | None = None) -> None:
    """SegmentError unless every recording is (T, H, W) with one T for all

    SYNOPSIS

        >>> check_recordings([np.zeros((5, 2, 2)), np.zeros((5, 3, 4))])
        >>> check_recordings([np.zeros((5, 2, 2)), np.zeros((4, 2, 2))])
        Traceback (most recent call last):
        ...
        rotstar_mrcal.capture.segment_base.SegmentError: the cameras hold different frame counts (camera-0: 5, camera-1: 4): record them together (rotstar-capture --stereo / --rgb-device)
    """
    names = names or [f"camera-{k}" for k in range(len(recordings))]
    for name, r in zip(names, recordings):
        if len(np.shape(r)) != 3:
            raise SegmentError(f"{name}: expected a recording of (frames, height, width), not {np.shape(r)}")
    counts = [len(r) for r in recordings]
    if len(set(counts)) > 1:
        raise SegmentError("the cameras hold different frame counts ("
                           + ", ".join(f"{n}: {c}" for n, c in zip(names, counts))
                           + "): record them together (rotstar-capture --stereo / --rgb-device)")


def still_range(d: np.ndarray, tau: float, a: int, b: int) -> tuple[int, int]:
    """[a, b) with the end frames that are across a change from their neighbour dropped

    d[t] compares frame t with frame t - 1.

    SYNOPSIS

        >>> d = np.array([np.nan, 0, 0, 1, 0, 0, 0, 0, 1, 0])
        >>> still_range(d, 0.5, 2, 8)       # frame 2 is before the change at 3
        (3, 8)
        >>> still_range(d, 0.5, 3, 9)       # frame 8 is after the change at 8
        (3, 8)
    """
    while b - a > 1 and not d[a + 1] < tau:
        a += 1
    while b - a > 1 and not d[b - 1] < tau:
        b -= 1
    return a, b


def follow(frames, reference: Segmentation, loop: list[dict], want: np.ndarray, full_scale: float,
           opts: Options, name: str, ref: str = "camera-0") -> tuple[Segmentation, list[str]]:
    """Another camera's averages over the reference's frames, checked; see the module doc"""
    mask = screen_pixels(frames, full_scale, opts.step)
    d, level = difference_signal(frames, full_scale, opts.step, mask)
    tau = threshold(d, opts.k, opts.ratio)
    # the start marker's frames (a split by content may not have seen it: then it is left out of the order check)
    marker = reference.stretches[reference.loop.stretches[0]].core if reference.markers.any() else None
    images, ranges, levels, trimmed = {}, {}, [], 0
    at = {e["file"]: k for k, e in enumerate(loop)}  # the reference may lack a frame the pose can spare
    for file, (a0, b0) in reference.ranges.items():
        a, b = still_range(d, tau, a0, b0)
        if np.any(~(d[a + 1 : b] < tau)):
            raise SegmentError(f"{name} did not see one still frame where {ref} saw {file} (camera frames "
                               f"{a0}-{b0 - 1}): the view changes in the middle (is the camera in step, and still?)")
        if b - a < opts.min_average:
            raise SegmentError(f"{name}: only {b - a} still frame(s) where {ref} saw {file} (camera frames "
                               f"{a0}-{b0 - 1}; need {opts.min_average}): the cameras are out of step by more than "
                               f"the player's hold allows")
        trimmed += (a - a0) + (b0 - b)
        images[file], ranges[file] = _mean(frames, a, b), (a, b)
        levels.append(float(np.mean(level[a:b])))
    seen = [at[f] for f in reference.ranges]
    if marker is None:
        corr, why = check_order(np.array(levels), want[seen], opts.min_correlation)
    else:
        corr, why = check_order(np.r_[np.mean(level[marker[0] : marker[1]]), levels], want[[0] + seen],
                                opts.min_correlation)
    if why:
        raise SegmentError(f"{name}: over the frames {ref} split, {why}")
    notes = [f"{name}: {trimmed} frame(s) at the edges of the ranges left out (a transition seen a frame later)"] \
        if trimmed else []
    seg = dataclasses.replace(reference, images=images, ranges=ranges, d=d, level=level, tau=tau, mask=mask)
    return seg, notes


def segment_rig(recordings: list, frames_list: list[dict], layout: Layout, full_scales: list[float],
                opts: Options = Options(), reference: int | None = None,
                names: list[str] | None = None) -> RigSegmentation:
    """Split every camera's recording with the same frame boundaries; see the module docstring

    reference: the camera that sets the boundaries; None: camera 0, or the
    first that can be split when camera 0 cannot.
    """
    names = names or [f"camera-{k}" for k in range(len(recordings))]
    check_recordings(recordings, names)
    order = [reference] if reference is not None else list(range(len(recordings)))
    notes, errors, ref_seg, ref = [], [], None, None
    for k in order:
        try:
            ref_seg, ref = segment(recordings[k], frames_list, layout, full_scales[k], opts), k
            break
        except SegmentError as e:
            errors.append((names[k], str(e)))
    if ref_seg is None:
        if len({e for _, e in errors}) == 1:
            raise SegmentError(errors[0][1] + (f" (on {', '.join(n for n, _ in errors)})" if len(errors) > 1 else ""))
        raise SegmentError("; ".join(f"{n}: {e}" for n, e in errors))
    errors = [f"{n}: {e}" for n, e in errors]
    if errors:
        notes.append(f"boundaries from {names[ref]}, as " + "; ".join(errors))
    loop = player_loop(frames_list)
    want = expected_levels(layout, loop)
    cams = []
    for k, frames in enumerate(recordings):
        if k == ref:
            cams.append(ref_seg)
            continue
        seg, n = follow(frames, ref_seg, loop, want, full_scales[k], opts, names[k], names[ref])
        cams.append(seg)
        notes += n
    return RigSegmentation(cams, ref, notes)

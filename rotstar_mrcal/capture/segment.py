"""Split a recording of the looping player into the displayed frames

SYNOPSIS

    from rotstar_mrcal import dataset
    from rotstar_mrcal.capture.segment import Options, segment
    pattern, layout = dataset.read_pattern("pattern/pattern.json")
    seg = segment(recording.frames, pattern["frames"], layout, full_scale=65535)
    seg.images["rotstar_00.png"]     # (H, W) float64: the average of the stretch's middle frames
    seg.summary()                    # one line: loop used, frames averaged, motion, order check

The player (display/player.py) shows a start marker (all black) and then
every frame of pattern.json, each held for some display refreshes, in a
loop. A camera recording it sees stable stretches separated by one or two
transition frames (the display changes during the exposure, row by row as
the panel scans out). Segmentation, step by step:

1. the pixels the player changes (motion.screen_pixels: the screen, not the
   room around it), then over them the difference signal d[t] = mean
   |f_t - f_(t-1)| of 4x-downsampled frames (motion.difference_signal) and
   each frame's mean level. Over the screen alone, a change flips a large
   part of the pixels averaged however small the board is in the image: the
   identity frames, which differ in about half of the elements (a quarter of
   the board's area, about 0.6 of what the band flip between rotating-star
   frames changes), stay far above the threshold;
2. a robust threshold: tau = median(d) + max(k * 1.4826 * MAD(d),
   (ratio - 1) * median(d)) (the stable frames are the majority, so median
   and MAD describe the noise floor);
3. stretches: maximal runs of frames joined by d < tau, at least min_len
   frames long; shorter runs (transition frames) are dropped. Inside the
   stretches d must be near the sensor noise (motion.noise_floor, estimated
   from a frame itself over the same pixels; edges on the screen make it an
   overestimate when the board is small, up to about 2x): a moving view
   raises the median, and with it the threshold, so this is what
   recognises it;
4. each stretch's core: `guard` frames dropped at each end, then the middle
   `average` frames (the paper averages 8); its level is the core's mean;
5. start markers: the darkest stretches, split from the rest at the widest
   gap in level among the lowest (one per loop, plus one);
6. loops: a marker followed by exactly len(frames) stretches and then the
   next marker (or the end of the recording). Fewer means a display frame
   was dropped, more means something flickered: that loop is rejected with
   the reason and another loop is used. Files are assigned in the order of
   time, so two display frames merged into one stretch leave the loop a
   frame short and reject it rather than shift the files after them (only a
   merge and a split in the same loop could shift them: over the rotating-
   star frames the level steps of 7 catch that; over the identity frames
   the detector's reading does, as a missing or repeated frame changes the
   number of white frames in most elements);
7. order check against pattern.json: the loop's levels must follow the
   expected levels (display/loop.py): correlation >= min_correlation, and
   every large expected step between neighbours (the border band flips
   white/black each frame) must have the recorded sign. The identity frames'
   levels differ by a few elements' area (and by which elements are in
   view), so their steps are never "large": they count in the correlation
   only, where the band flips and the black start marker dominate. The
   same holds for the phase-shift frames of the paper's sequence (their
   four steps have nearly the same level; each step moves the fringes by a
   quarter period, a change the difference signal sees over half the
   board) and the star frame;
8. motion: in every stretch, the image shift between the first and the
   second half of its stable frames (motion.image_shift), per frame; the
   mean over the loop's stretches (noise averages out, a steady drift adds
   up) times the loop's length must stay below max_motion px;
9. of the loops that pass, the one with the most frames averaged per
   stretch (then the least motion) is used.

When no loop between two start markers is usable, segment() (method
'auto') splits the recording by the content of the displayed frames instead
(capture.content): any window of the loop that shows every frame once,
short holds, camera frames that blend two displayed frames left out.

A doubled display frame (held twice as long) is one longer stretch; a
recording that starts or ends mid-loop leaves incomplete loops that are
skipped. Failures raise SegmentError with a one-line reason; Segmentation
keeps the signal, the threshold and every loop's verdict for plots and logs.
The detector's own motion check (0.15 px per frame) is the fine test of a
still camera; this one catches a camera that is visibly moving.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from rotstar_mrcal.pattern.loop import expected_levels, player_loop
from rotstar_mrcal.pattern.layout import Layout
from rotstar_mrcal.capture.motion import difference_signal, image_shift, noise_floor, screen_pixels
from rotstar_mrcal.capture.segment_base import (  # noqa: F401  (re-exported: the types segmentation returns)
    LoopVerdict, Options, Segmentation, SegmentError, Stretch, _mean, check_order, threshold,
)
from rotstar_mrcal.capture.content import segment_content


# ---- the steps -------------------------------------------------------------------
def stable_runs(d: np.ndarray, tau: float, min_len: int) -> list[tuple[int, int]]:
    """[start, stop) of the maximal runs of frames joined by d < tau, at least min_len long

    SYNOPSIS

        >>> d = np.array([np.nan, 0, 0, 0, 1, 1, 0, 0, 0, 0, 1, 0])
        >>> stable_runs(d, 0.5, 3)
        [(0, 4), (5, 10)]
    """
    runs, start = [], 0
    for t in range(1, len(d) + 1):
        if t == len(d) or not d[t] < tau:
            if t - start >= min_len:
                runs.append((start, t))
            start = t
    return runs


def core_range(start: int, stop: int, guard: int, average: int) -> tuple[int, int]:
    """The middle `average` frames of [start + guard, stop - guard)

    SYNOPSIS

        >>> core_range(10, 30, 1, 8), core_range(10, 15, 1, 8)
        ((16, 24), (11, 14))
    """
    a, b = start + guard, stop - guard
    if b - a > average:
        a += (b - a - average) // 2
        b = a + average
    return a, max(a, b)


def find_markers(levels: np.ndarray, n_loop: int, min_gap: float = 0.15) -> np.ndarray:
    """Which stretches show the start marker: the darkest, split off at the widest gap

    The number of markers is at most one per loop plus one; among the lowest
    levels the split goes where the gap to the next level is widest, and that
    gap must be at least min_gap of the level range (and 0.3 min_gap of the
    brightest level: a flat recording has no marker).

    SYNOPSIS

        >>> lv = np.array([.64, .36, .51, .02, .64, .36, .64, .36, .51, .03, .64])
        >>> find_markers(lv, 5).nonzero()[0].tolist()
        [3, 9]
    """
    S = len(levels)
    if S < 2:
        raise SegmentError(f"{S} stable stretch(es): not a recording of the looping player")
    order = np.argsort(levels)
    srt = levels[order]
    mmax = min(S - 1, math.ceil(S / n_loop) + 1)
    gaps = srt[1 : mmax + 1] - srt[:mmax]
    i = int(np.argmax(gaps)) + 1
    span = srt[-1] - srt[0]
    if span <= 0 or gaps[i - 1] < min_gap * span or gaps[i - 1] < 0.3 * min_gap * srt[-1]:
        raise SegmentError(f"no start marker: no stretch is clearly darker than the others (largest gap "
                           f"{gaps.max() / max(span, 1e-12):.0%} of the level range); is the player running, "
                           f"and the whole screen in view?")
    return levels <= srt[i - 1]



def stretch_drift(frames, s: Stretch, guard: int, step: int = 2) -> np.ndarray | None:
    """(dx, dy) per frame (px / frame) between a stretch's first and second half, or None"""
    a, b = s.start + guard, s.stop - guard
    if b - a < 2:
        return None
    m = (a + b) // 2
    return image_shift(_mean(frames, a, m), _mean(frames, m, b), step=step) / ((b - a) / 2)


def judge_loop(frames, stretches: list[Stretch], markers: np.ndarray, i: int, n_frames: int,
               want: np.ndarray, opts: Options) -> LoopVerdict:
    """The verdict on the loop that starts at marker stretch i"""
    S = len(stretches)
    idx = list(range(i, i + n_frames + 1))
    if idx[-1] >= S:
        return LoopVerdict(i, [], False, f"incomplete: the recording ends {S - 1 - i} frame(s) into the loop")
    inner = markers[idx[1:]]
    if inner.any():
        j = int(np.argmax(inner))
        return LoopVerdict(i, [], False, f"{j} frame(s) between start markers, pattern.json has {n_frames} "
                                         f"(a display frame was dropped?)")
    if idx[-1] + 1 < S and not markers[idx[-1] + 1]:
        return LoopVerdict(i, [], False, f"more than {n_frames} stable stretches before the next start marker "
                                         f"(a frame flickered, or the camera moved in the middle of one)")
    sts = [stretches[k] for k in idx]
    n_avg = min(s.core[1] - s.core[0] for s in sts)
    corr, why = check_order(np.array([s.level for s in sts]), want, opts.min_correlation)
    if why:
        return LoopVerdict(i, idx, False, why, corr, math.nan, n_avg)
    if n_avg < opts.min_average:
        return LoopVerdict(i, idx, False, f"a stretch leaves only {n_avg} frame(s) to average "
                                          f"(hold the player's frames longer)", corr, math.nan, n_avg)
    # the drift rate of every stretch, averaged: noise averages out, a steady drift does not
    rates = [r for r in (stretch_drift(frames, s, opts.guard) for s in sts[1:]) if r is not None]
    loop_frames = sts[-1].stop - sts[1].start  # (the marker is black: nothing to measure motion on)
    motion = float(np.hypot(*np.mean(rates, axis=0))) * loop_frames if rates else math.nan
    if np.isfinite(motion) and motion > opts.max_motion:
        return LoopVerdict(i, idx, False, f"the camera moved: the image drifts {motion:.2f} px over the loop "
                                          f"(limit {opts.max_motion} px)", corr, motion, n_avg)
    return LoopVerdict(i, idx, True, "", corr, motion, n_avg)


def segment(frames, frames_list: list[dict], layout: Layout, full_scale: float,
            opts: Options = Options(), times: np.ndarray | None = None) -> Segmentation:
    """Split a recording (T, H, W) into the frames of pattern.json; see the module docstring

    opts.method 'auto' splits between start markers (segment_loops) and, when
    no loop is usable, by content (capture.content: any window of the loop,
    short holds); the error then gives both reasons. times: (T,) seconds of
    each camera frame, for the content method (None: one unit per frame).
    """
    if opts.method == "content":
        return segment_content(frames, frames_list, layout, full_scale, opts, times)
    try:
        return segment_loops(frames, frames_list, layout, full_scale, opts)
    except SegmentError as e:
        if opts.method != "auto":
            raise
        try:
            return segment_content(frames, frames_list, layout, full_scale, opts, times)
        except SegmentError as e2:
            raise SegmentError(f"{e}; by content: {e2}") from None


def segment_loops(frames, frames_list: list[dict], layout: Layout, full_scale: float,
                  opts: Options = Options()) -> Segmentation:
    """Split a recording (T, H, W) into the frames of pattern.json between start markers (the module docstring)"""
    loop = player_loop(frames_list)
    n_frames = len(frames_list)
    need = len(loop) * opts.min_len  # one whole loop: every entry still for min_len frames
    if len(frames) < need:
        raise SegmentError(f"the recording is too short: {len(frames)} frame(s), need at least {need} (one whole "
                           f"loop of the player: {len(loop)} entries of >= {opts.min_len} frames each)")
    mask = screen_pixels(frames, full_scale, opts.step)
    d, level = difference_signal(frames, full_scale, opts.step, mask)
    tau = threshold(d, opts.k, opts.ratio)
    runs = stable_runs(d, tau, opts.min_len)
    still = sum(b - a for a, b in runs) / len(frames)
    if still < opts.min_still:
        raise SegmentError(f"the view is not still: only {still:.0%} of the frames belong to stable stretches of "
                           f">= {opts.min_len} frames (camera or screen moving, or the player's hold too short "
                           f"for this frame rate)")
    inside = np.concatenate([d[a + 1 : b] for a, b in runs]) if runs else np.array([])
    floor = noise_floor(frames[len(frames) // 2], full_scale, opts.step, mask)
    if len(inside) and np.median(inside) > opts.max_jitter * floor:
        raise SegmentError(f"the view is not still: consecutive frames differ by {np.median(inside) / floor:.0f}x "
                           f"the sensor noise even between the player's changes (camera or screen moving, or a "
                           f"flickering screen or exposure)")
    stretches = []
    for a, b in runs:
        core = core_range(a, b, opts.guard, opts.average)
        lv = float(np.mean(level[core[0] : core[1]])) if core[1] > core[0] else float(np.mean(level[a:b]))
        stretches.append(Stretch(a, b, core, lv, a == 0 or b == len(frames)))
    levels = np.array([s.level for s in stretches])
    markers = find_markers(levels, len(loop))
    want = expected_levels(layout, loop)
    verdicts = [judge_loop(frames, stretches, markers, i, n_frames, want, opts) for i in np.flatnonzero(markers)]
    good = [k for k, v in enumerate(verdicts) if v.ok]
    if not good:
        why = "; ".join(f"loop at frame {stretches[v.marker].start}: {v.reason}" for v in verdicts) or "no start marker"
        raise SegmentError(f"no usable loop in {len(frames)} frames ({len(stretches)} stretches): {why}")
    chosen = max(good, key=lambda k: (verdicts[k].min_average,
                                      -(verdicts[k].motion_px if np.isfinite(verdicts[k].motion_px) else 0)))
    v = verdicts[chosen]
    images, ranges = {}, {}
    for entry, si in zip(loop[1:], v.stretches[1:]):
        a, b = stretches[si].core
        images[entry["file"]] = _mean(frames, a, b)
        ranges[entry["file"]] = (a, b)
    return Segmentation(images, ranges, stretches, markers, verdicts, chosen, d, level, tau, mask)

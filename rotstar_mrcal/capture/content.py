"""Find every displayed frame by its content, in any window of the player's loop

SYNOPSIS

    from rotstar_mrcal.capture.content import segment_content
    seg = segment_content(frames, pattern["frames"], layout, full_scale, opts, times=seq / fps)
    seg.images["identity_03.png"]      # the mean of every clean camera frame of that displayed frame
    seg.used["identity_03.png"]        # which camera frames those were

What segment.segment does with two start markers and a whole loop between
them, this does with any stretch of the recording that holds every frame of
pattern.json at least once (start anywhere in the loop, wrap around, one
pass or several), with holds as short as two camera frames:

1. every camera frame, area-downsampled over the screen's pixels
   (motion.screen_pixels), is compared with the one before it after fitting
   a gain and an offset (a PWM-dimmed backlight changes the brightness from
   one camera frame to the next, not the picture): the two show the same
   displayed frame when almost no pixel differs by more than k robust
   sigmas of the sensor noise (the noise from the recording itself: the
   quiet quartile of all the frame pairs). A camera frame that blends two
   displayed frames (its exposure straddles a refresh, or the LCD is still
   switching) differs from both of its neighbours over every pixel the two
   displayed frames differ in, so it agrees with neither;
2. runs: consecutive camera frames that agree. A run of two or more is a
   displayed frame seen clean (two consecutive camera frames, 1 / fps
   apart, cannot blend the same two displayed frames in the same
   proportion). A lone camera frame is kept only when it agrees with the
   runs of a displayed frame seen clean elsewhere in the recording;
3. classes: runs that show the same displayed frame (their means agree as
   in step 1, with the noise of the means, up to content_class_fraction of
   the pixels: a run may hold a camera frame with a sliver of a blend too
   thin for step 1, and two displayed frames differ over far more, at least
   a few elements of the board) are one class; the runs of a class, merged
   where consecutive, are its visits;
4. which class is which loop entry: the visits in time order walk round
   the loop. For every entry the first visit could be, the walk assigns
   each next visit: a class seen before keeps its entry (and the time since
   the last visit must allow it), a new class takes the entry whose place in
   the loop the time since the last visit points to (the player's hold per
   kind, opts.hold / opts.marker_hold, scaled by the typical step between
   visits). A hypothesis that maps two classes to one entry, or whose times
   contradict it, is dropped; of the rest, the one whose class levels follow
   the levels pattern.json predicts (pattern.loop.expected_levels: the black
   marker, the border band white and black, the identity frames, the
   checkerboard) is used, and it must be the only one that does
   (segment.check_order), or nothing is decided;
5. motion: the image shift between the two halves of the longer runs and
   between visits of the same class far apart, per camera frame; times the
   frames spanned it must stay below max_motion px;
6. every frame of pattern.json must have a class, but for those a pose can
   do without (pattern.layout.SPARE_KINDS: one identity frame, the
   checkerboard; opts.content_spare): a missing one raises SegmentError
   naming it; the spared ones are listed in Segmentation.missing.

7. blends in some rows: a camera frame that caught a little of the entry
   before or after it in some rows (the panel scanning out, the LCD still
   switching: a few per cent in a band of rows, too few pixels beyond k
   sigmas for step 1) is left out of its displayed frame's average
   (blend_free: per row, the weight of the neighbouring entry's picture in
   the frame's residual, in sigmas of the noise; opts.content_blend_z).

The averages weight every clean camera frame equally.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from rotstar_mrcal.capture.motion import difference_signal, downsample, image_shift, screen_pixels
from rotstar_mrcal.capture.segment_base import (
    LoopVerdict, Options, Segmentation, SegmentError, Stretch, _mean, check_order, threshold,
)
from rotstar_mrcal.pattern.layout import Layout, unspared
from rotstar_mrcal.pattern.loop import entry_holds, expected_levels, player_loop


def frame_vectors(frames, full_scale: float, step: int, mask: np.ndarray | None) -> np.ndarray:
    """(T, P) float32: every frame area-downsampled by step, over the mask, as a fraction of full scale"""
    out = []
    for t in range(len(frames)):
        cur = downsample(frames[t], step)
        out.append((cur[mask] if mask is not None else cur.ravel()) / np.float32(full_scale))
    return np.stack(out)


def gain_residual(x: np.ndarray, y: np.ndarray, max_gain: float = 1.25) -> np.ndarray:
    """y - (g x + o): g (within [1 / max_gain, max_gain]) and o fitted, then again on the pixels that fit

    The brightness of a PWM-dimmed screen changes by a few per cent from one
    camera frame to the next; a gain far from 1 is a different picture (the
    black start marker is not the checkerboard times 0).

    SYNOPSIS

        >>> x = np.linspace(0, 1, 100)
        >>> float(np.abs(gain_residual(x, 0.97 * x + 0.01)).max()) < 1e-9
        True
        >>> y = 0.97 * x + 0.01; y[:10] += 0.5              # a tenth of the pixels changed
        >>> r = gain_residual(x, y); bool(np.abs(r[10:]).max() < 1e-9 and np.all(r[:10] > 0.4))
        True
        >>> float(np.abs(gain_residual(x, 0 * x)).max()) > 0.3   # black is not a dim picture
        True
    """
    x64, y64 = x.astype(np.float64), y.astype(np.float64)
    keep = np.ones(len(x64), bool)
    for _ in range(2):
        xs, ys = x64[keep], y64[keep]
        vx = float(np.var(xs))
        g = float(np.cov(xs, ys, bias=True)[0, 1]) / vx if vx > 0 else 1.0
        g = min(max(g, 1 / max_gain), max_gain)
        o = float(np.median(ys - g * xs))
        r = y64 - (g * x64 + o)
        keep = np.abs(r) <= max(3 * robust_sigma(r), 1e-12)
        if keep.sum() < 10:
            break
    return r


def robust_sigma(r: np.ndarray) -> float:
    """1.4826 MAD"""
    return float(np.median(np.abs(r - np.median(r)))) * 1.4826


def differing(x: np.ndarray, y: np.ndarray, sigma: float, k: float) -> float:
    """Fraction of pixels where y differs from x, after a gain and an offset, by more than k sigma

    sigma: of the difference of the two (for two single frames sqrt(2) times one frame's noise)
    """
    return float(np.mean(np.abs(gain_residual(x, y)) > k * sigma))


def agreeing_fraction(X: np.ndarray, sigma: float, k: float = 5.0, fraction: float = 0.003) -> float:
    """Fraction of consecutive frames of X (T, P) that show the same picture (step 1 of the module doc)

    sigma: the noise of the difference of two frames (from within a frame,
    motion.noise_floor: a window of a moving view has no quiet pairs to
    measure it on). A still view of the player: most pairs agree with long
    holds, a third to two thirds with short ones; a moving view: hardly any.

    SYNOPSIS

        >>> rng = np.random.default_rng(0)
        >>> pic = rng.uniform(0, 1, 500)
        >>> still = np.stack([pic + 0.01 * rng.standard_normal(500) for _ in range(9)])
        >>> moving = np.stack([np.roll(pic, i) + 0.01 * rng.standard_normal(500) for i in range(9)])
        >>> agreeing_fraction(still, 0.014), agreeing_fraction(moving, 0.014)
        (1.0, 0.0)
    """
    res = [np.abs(gain_residual(X[t - 1], X[t])) for t in range(1, len(X))]
    if not res:
        return 0.0
    return float(np.mean([np.mean(r > k * sigma) <= fraction for r in res]))


@dataclasses.dataclass
class Visit:
    frames: list[int]  # camera frames averaged (clean, consecutive or nearly)
    cls: int  # class: one displayed frame
    entry: int = -1  # loop entry, once identified


@dataclasses.dataclass
class ContentRuns:
    runs: list[list[int]]  # camera frames of each run (agreeing consecutive frames), time order
    cls: list[int]  # class of each run (-1: a lone frame matching no class: not used)
    n_classes: int
    sigma: float  # the noise of one frame difference (fraction of full scale)
    d: np.ndarray  # (T,) fraction of pixels differing from the previous frame (NaN for the first)


def find_runs(X: np.ndarray, opts: Options) -> ContentRuns:
    """Steps 1-3: agreeing consecutive frames, runs, and classes of runs (see the module doc)"""
    T = len(X)
    res = [np.abs(gain_residual(X[t - 1], X[t])) for t in range(1, T)]
    sig = [float(np.median(r)) * 1.4826 for r in res]  # (the residual's median is ~0: a robust sigma)
    sigma = max(float(np.percentile(sig, 25)) if sig else 1.0, 1e-6)
    d = np.r_[np.nan, [float(np.mean(r > opts.content_k * sigma)) for r in res]]
    runs, cur = [], [0]
    for t in range(1, T + 1):
        if t < T and d[t] <= opts.content_fraction:
            cur.append(t)
            continue
        runs.append(cur)
        cur = [t]
    means = [X[r].mean(axis=0) for r in runs]
    cls = [-1] * len(runs)
    reps: list[tuple[np.ndarray, int, np.ndarray]] = []  # class -> (mean of its first clean run, frames, z-score)

    def zscore(v):  # a flat picture (the black marker: noise alone) gets no z-score, and no quick look
        sd = float(v.std())
        return (v - v.mean()) / sd if sd > 5 * sigma else None

    def match(i):
        n = len(runs[i])
        if not reps:
            return -1
        # a cheap look first: the same displayed frame correlates almost perfectly (a gain changes nothing)
        zi = zscore(means[i])
        corr = np.array([1.0 if z is None or zi is None else float(np.mean(z * zi)) for _, _, z in reps])
        for c in np.flatnonzero(corr > 0.9):
            m, nm, _ = reps[c]
            s = sigma * math.sqrt((1 / n + 1 / nm) / 2)
            # a lone frame must agree as closely as two consecutive frames do (it may be a blend)
            if differing(m, means[i], s, opts.content_k) <= (opts.content_class_fraction if n >= 2 else
                                                             opts.content_fraction):
                return int(c)
        return -1

    for i in sorted(range(len(runs)), key=lambda i: -len(runs[i])):  # clean runs first, longest first
        if len(runs[i]) >= 2:
            c = match(i)
            if c < 0:
                reps.append((means[i], len(runs[i]), zscore(means[i])))
                c = len(reps) - 1
            cls[i] = c
        else:
            cls[i] = match(i)  # a lone frame: only as a displayed frame seen clean elsewhere
    return ContentRuns(runs, cls, len(reps), sigma, d)


def visits_of(cr: ContentRuns) -> list[Visit]:
    """The classified runs in time order, consecutive runs of one class merged"""
    out: list[Visit] = []
    for r, c in zip(cr.runs, cr.cls):
        if c < 0:
            continue
        if out and out[-1].cls == c:
            out[-1].frames.extend(r)
        else:
            out.append(Visit(list(r), c))
    return out


def entry_offsets(durations: np.ndarray) -> np.ndarray:
    """(n + 1,) start time of every loop entry within one loop, and the loop's length last"""
    return np.r_[0.0, np.cumsum(durations)]


def step_time(durations: np.ndarray, a: int, b: int) -> float:
    """Seconds from the middle of entry a to the middle of entry b, going forward round the loop (b == a: a loop)

    >>> step_time(np.array([1.0, 2.0, 3.0]), 0, 2), step_time(np.array([1.0, 2.0, 3.0]), 2, 1)
    (4.0, 3.5)
    """
    n = len(durations)
    k = (b - a) % n or n
    idx = [(a + j) % n for j in range(k + 1)]
    return float(durations[idx[0]] / 2 + sum(durations[j] for j in idx[1:-1]) + durations[idx[-1]] / 2)


def walk(visits: list[Visit], centres: np.ndarray, e0: int, durations: np.ndarray,
         tol: float) -> tuple[dict[int, int], int]:
    """({class: entry}, conflicts) when the first visit shows entry e0 (step 4 of the module doc)"""
    n = len(durations)
    owner: dict[int, int] = {}
    cmap = {visits[0].cls: e0}
    owner[e0] = visits[0].cls
    conflicts = 0
    prev = e0
    for i in range(1, len(visits)):
        el = centres[i] - centres[i - 1]
        c = visits[i].cls
        if c in cmap:
            e = cmap[c]
            if abs(step_time(durations, prev, e) - el) > tol * (durations[e] + durations[prev]) / 2:
                conflicts += 1
        else:
            cand = [(abs(step_time(durations, prev, (prev + k) % n) - el), (prev + k) % n) for k in range(1, n + 1)]
            err, e = min(cand)
            if err > tol * (durations[e] + durations[prev]) / 2 or e in owner:
                conflicts += 1
                continue
            cmap[c], owner[e] = e, c
        prev = e
    return cmap, conflicts


def identify(visits: list[Visit], centres: np.ndarray, levels: np.ndarray, want: np.ndarray,
             durations: np.ndarray, opts: Options) -> tuple[dict[int, int], float, str]:
    """({class: entry}, correlation, '' or why nothing is decided): step 4 of the module doc"""
    n = len(durations)
    good = []
    for e0 in range(n):
        cmap, conflicts = walk(visits, centres, e0, durations, opts.content_timing)
        if conflicts or len(cmap) < 2:
            continue
        cl = sorted(cmap, key=cmap.get)  # in the loop's order
        corr, why = check_order(levels[cl], want[[cmap[c] for c in cl]], opts.min_correlation)
        good.append((not why, corr, e0, cmap, why))
    ok = [g for g in good if g[0]]
    if not ok:
        best = max(good, key=lambda g: g[1]) if good else None
        return {}, (best[1] if best else math.nan), ("no assignment of the displayed frames to the loop's entries "
                                                    "agrees with their times and levels" +
                                                    (f" (best: {best[4]})" if best else ""))
    if len({tuple(sorted(g[3].items())) for g in ok}) > 1:
        return {}, max(g[1] for g in ok), (f"{len(ok)} assignments of the displayed frames to the loop's entries "
                                           f"fit their times and levels: record longer (a whole loop)")
    return ok[0][3], ok[0][1], ""


def estimate_durations(centres: np.ndarray, relative: np.ndarray) -> np.ndarray:
    """Time per loop entry: relative (the player's holds) scaled so that the typical step between visits fits

    Most steps between visits go to the next entry, so the median step is the
    median entry's time (in the units of centres: seconds, or camera frames).

    >>> estimate_durations(np.array([0.0, 4, 8, 14, 18]), np.array([2, 2, 3, 2]))
    array([4., 4., 6., 4.])
    """
    rel = np.asarray(relative, float)
    steps = np.diff(centres)
    return rel if len(steps) == 0 else rel / float(np.median(rel)) * float(np.median(steps))


def motion_of(frames, visits: list[Visit]) -> float:
    """Step 5: px of drift over the recording (mean drift per camera frame times the frames spanned), or NaN"""
    rates = []
    for v in visits:
        f = v.frames
        if len(f) >= 4:
            m = len(f) // 2
            rates.append(image_shift(_frames_mean(frames, f[:m]), _frames_mean(frames, f[m:]), step=2)
                         / ((f[-1] - f[0] + 1) / 2))
    first: dict[int, Visit] = {}
    for v in visits:
        if v.cls in first and v.frames[0] - first[v.cls].frames[-1] > 0:
            a = first[v.cls]
            span = np.mean(v.frames) - np.mean(a.frames)
            rates.append(image_shift(_frames_mean(frames, a.frames), _frames_mean(frames, v.frames), step=2) / span)
        first.setdefault(v.cls, v)
    if not rates:
        return math.nan
    span = visits[-1].frames[-1] - visits[0].frames[0] + 1
    return float(np.hypot(*np.median(rates, axis=0))) * span


def _frames_mean(frames, idx: list[int]) -> np.ndarray:
    acc = np.zeros(np.shape(frames[idx[0]]), np.float64)
    for t in idx:
        acc += frames[t]
    return acc / len(idx)


def class_levels(X: np.ndarray, visits: list[Visit], n_classes: int) -> np.ndarray:
    """(n_classes,) mean level of every class over all its camera frames"""
    level_of, count = np.zeros(n_classes), np.zeros(n_classes)
    for v in visits:
        level_of[v.cls] += X[v.frames].mean(axis=1).sum()
        count[v.cls] += len(v.frames)
    return level_of / np.maximum(count, 1)


def unseen(loop: list[dict], by_entry: dict[int, int]) -> list[str]:
    """The files of the loop's entries (the marker left out) that no class was assigned to, in the loop's order

    >>> unseen([{"file": "m"}, {"file": "a"}, {"file": "b"}], {0: 3, 2: 1})
    ['a']
    """
    return [loop[e]["file"] for e in range(1, len(loop)) if e not in by_entry]


def assign_entries(visits: list[Visit], X: np.ndarray, n_classes: int, t: np.ndarray, loop: list[dict], layout: Layout,
                   opts: Options, seconds: bool, durations) -> tuple[dict[int, int], float]:
    """Step 4 and 6 of the module doc: {entry: class} for every loop entry but the marker, and the correlation"""
    centres = np.array([(t[v.frames[0]] + t[v.frames[-1]]) / 2 for v in visits])
    rel = entry_holds(loop, opts.hold or None, None, opts.marker_hold or None)
    if durations is None:  # seconds from the holds, or (frame numbers alone) scaled by the typical step
        durations = rel / opts.refresh_hz if seconds else estimate_durations(centres, rel)
    cmap, corr, why = identify(visits, centres, class_levels(X, visits, n_classes), expected_levels(layout, loop),
                               np.asarray(durations, float), opts)
    if why:
        raise SegmentError(f"{why} ({n_classes} displayed frames seen in {len(visits)} visits)")
    for v in visits:
        v.entry = cmap.get(v.cls, -1)
    by_entry = {e: c for c, e in cmap.items()}
    missing = unseen(loop, by_entry)
    if missing and (not opts.content_spare or unspared(loop[1:], missing)):
        raise SegmentError(f"{len(missing)} frame(s) of pattern.json not seen clean: {', '.join(missing)} (record "
                           f"longer, or hold the player's frames longer)")
    return by_entry, corr


def row_blend(r: np.ndarray, D: np.ndarray, rows: np.ndarray, n_rows: int, var: float, smooth: int = 3) -> np.ndarray:
    """(n_rows,) z-score of the blend of D in the residual r, per image row (rows: the row of every element)

    r: a camera frame minus its displayed frame's mean; D: another displayed
    frame minus that mean. Per row the least-squares weight of D in r,
    w = <r, D> / <D, D>, over `smooth` neighbouring rows, divided by its
    standard deviation under noise alone (var: of one element of r). A frame
    whose exposure caught the panel scanning out, or the LCD still switching,
    holds a little of the entry before or after in some rows: a positive
    weight there. 0 where D is flat.

    >>> rng = np.random.default_rng(0)
    >>> rows = np.repeat(np.arange(20), 50); D = rng.choice([-0.8, 0.8], 1000)
    >>> r = 0.005 * rng.standard_normal(1000); r[rows < 2] += 0.02 * D[rows < 2]   # 2 % blended in rows 0-1
    >>> z = row_blend(r, D, rows, 20, 0.005 ** 2); bool(z[:2].min() > 10 and np.abs(z[4:]).max() < 4)
    True
    """
    k = np.ones(smooth)
    rd = np.convolve(np.bincount(rows, r * D, n_rows), k, "same")
    dd = np.convolve(np.bincount(rows, D * D, n_rows), k, "same")
    return np.where(dd > 0, rd / np.sqrt(np.maximum(dd, 1e-30) * var), 0.0)


def blend_free(X: np.ndarray, idx: list[int], others: list[np.ndarray], rows: np.ndarray, sigma: float,
               z: float = 6.0) -> list[int]:
    """The camera frames of idx (one displayed frame's) with no row that blends in one of the others

    others: the means of the displayed frames shown before and after it
    (row_blend's D, after removing this one's mean). A frame is compared with
    the mean of all of idx after fitting its gain and offset (gain_residual);
    sigma: the noise of the difference of two camera frames, so one frame's
    is sigma / sqrt(2). Where a blended frame pulls the mean, the clean
    ones show a negative weight, which is not a blend. Keeps at least one
    frame (the least blended) and all when there are no others.
    """
    if not others or len(idx) < 2:
        return list(idx)
    n_rows = int(rows.max()) + 1
    m = X[idx].mean(axis=0)
    var = sigma * sigma / 2 * (1 + 1 / len(idx))
    worst = []
    for i in idx:
        r = gain_residual(m, X[i])
        worst.append(max(float(row_blend(r, o - m, rows, n_rows, var).max()) for o in others))
    keep = [i for i, w in zip(idx, worst) if w <= z]
    return keep or [idx[int(np.argmin(worst))]]


def content_segmentation(frames, X: np.ndarray, visits: list[Visit], by_entry: dict[int, int], loop: list[dict],
                         full_scale: float, corr: float, motion: float, opts: Options, rows: np.ndarray | None = None,
                         sigma: float = 0.0) -> Segmentation:
    """The Segmentation of a split by content: every clean camera frame of each entry averaged

    rows (the image row of every element of X) and sigma (find_runs'): camera
    frames that blend in a little of the entry before or after in some rows
    are left out (blend_free).
    """
    T = len(frames)
    images, ranges, used = {}, {}, {}
    blends = rows is not None and opts.content_blend_z > 0
    means = {e: X[[i for v in visits if v.cls == c for i in v.frames]].mean(axis=0)
             for e, c in by_entry.items()} if blends else {}
    for e in sorted(set(by_entry) - {0}):  # in the loop's order, the marker left out
        mine = [v for v in visits if v.cls == by_entry[e]]
        f = loop[e]["file"]
        used[f] = sorted(i for v in mine for i in v.frames)
        if blends:
            near = [means[k % len(loop)] for k in (e - 1, e + 1) if k % len(loop) in means]
            used[f] = blend_free(X, used[f], near, rows, sigma, opts.content_blend_z)
        images[f] = _frames_mean(frames, used[f])
        longest = max(mine, key=lambda v: len(v.frames))
        ranges[f] = (longest.frames[0], longest.frames[-1] + 1)
    stretches = [Stretch(v.frames[0], v.frames[-1] + 1, (v.frames[0], v.frames[-1] + 1),
                         float(X[v.frames].mean()), v.frames[0] == 0 or v.frames[-1] == T - 1) for v in visits]
    first: dict[int, int] = {}
    for i, v in enumerate(visits):
        first.setdefault(v.entry, i)
    order = [first.get(e, 0) for e in range(len(loop))]
    verdict = LoopVerdict(order[0], order, True, "", corr, motion, min(len(u) for u in used.values()))
    # the difference signal and threshold of segment_loops, for plots and rotstar-capture --auto (not for the split)
    dmask = screen_pixels(frames, full_scale, opts.step)
    d, level = difference_signal(frames, full_scale, opts.step, dmask)
    return Segmentation(images, ranges, stretches, np.array([v.entry == 0 for v in visits]), [verdict], 0, d, level,
                        threshold(d, opts.k, opts.ratio), dmask, method="content", used=used,
                        missing=unseen(loop, by_entry))


def segment_content(frames, frames_list: list[dict], layout: Layout, full_scale: float, opts: Options = Options(),
                    times: np.ndarray | None = None, durations: np.ndarray | None = None) -> Segmentation:
    """Split a recording (T, H, W) into the frames of pattern.json by their content; see the module doc

    times: (T,) seconds of every camera frame (sequence numbers / fps: a
    dropped frame leaves a gap); None: one unit per frame. durations: (n,)
    time each loop entry is shown, in the units of times (None: the
    player's holds / opts.refresh_hz with times, else estimated).
    """
    loop = player_loop(frames_list)
    T = len(frames)
    if T < 4:
        raise SegmentError(f"the recording is too short: {T} frame(s)")
    t = np.arange(T, dtype=float) if times is None else np.asarray(times, float)
    mask = screen_pixels(frames, full_scale, opts.content_step)
    X = frame_vectors(frames, full_scale, opts.content_step, mask)
    if mask is not None:
        rows = np.nonzero(mask)[0]
    else:
        small = downsample(frames[0], opts.content_step).shape
        rows = np.repeat(np.arange(small[0]), small[1])
    cr = find_runs(X, opts)
    visits = visits_of(cr)
    if cr.n_classes > len(loop):
        raise SegmentError(f"{cr.n_classes} different displayed frames seen, the player's loop has {len(loop)} "
                           f"entries (another pattern.json, a moving view, or a flickering screen?)")
    if len(visits) < 2:
        raise SegmentError(f"{len(visits)} displayed frame(s) seen clean in {T} camera frames: not a recording of "
                           f"the player, or its hold too short for this frame rate")
    by_entry, corr = assign_entries(visits, X, cr.n_classes, t, loop, layout, opts, times is not None, durations)
    motion = motion_of(frames, visits)
    if np.isfinite(motion) and motion > opts.max_motion:
        raise SegmentError(f"the camera moved: the image drifts {motion:.2f} px over the recording "
                           f"(limit {opts.max_motion} px)")
    return content_segmentation(frames, X, visits, by_entry, loop, full_scale, corr, motion, opts, rows,
                                cr.sigma)

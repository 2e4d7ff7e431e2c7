"""The exposure from a short look at the playing screen: the pattern's white high but unclipped

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.capture.exposure import measure_look, next_exposure
    >>> rng = np.random.default_rng(0)
    >>> f = rng.normal(0.02, 0.003, (6, 64, 80))          # the room, 2 % of full scale
    >>> f[1::2, 8:56, 8:72] = 0.30                        # the screen's white in every other frame
    >>> look = measure_look(np.clip(f, 0, 1) * 65535, 65535)
    >>> round(look.white, 3), look.clipped, look.screen
    (0.3, False, True)
    >>> step = next_exposure(look, 4000, 20, 38000)      # 0.30 at 4000 us: 0.75 wants 10000 us
    >>> step.exposure_us, step.done, step.failure
    (10000.0, False, '')

    choice = choose_exposure(src, 8000, look_frames=8, settle=8, shortest_us=20, longest_us=38000)
    choice.exposure_us, choice.white, choice.looks, choice.seconds, choice.failure

The white of a look is the brightest part of the screen: over the downsampled
pixels (4 x 4 block means: a hot pixel moves a block by 1/16 of its excess)
that the playing pattern changes during the look (the room and a lamp do not
change, the screen goes from the black start marker or a black element to
white), in each camera frame the median of the blocks within 10 % of the
frame's 99th percentile (a few specular or hot blocks do not set it, and the
median of that plateau is not pushed up by the noise as a high percentile
is), then the brightest of the frames (a frame between two entries, the black
marker, an identity frame with small white elements, or a dark phase of a
PWM-dimmed backlight give less). `peak` is the highest 99th percentile of the
frames; `spread` how much the whites of the frames showing white differ
(different entries, and the backlight's PWM seen through a short exposure:
the two cannot be told apart in a look of a few frames).

The sensor is linear: white scales with the exposure, so one unclipped look
gives the exposure that puts the white at TARGET of full scale, and the
brightest blocks of the look at most PEAK_MAX (the exposure is the smaller of
the two). A clipped look (white at CLIP or above) only says that the white is
at least full scale: the next look is STEP_DOWN times shorter. A look in which
nothing changes by MEASURABLE of full scale (a screen too dim to see, or
none) is followed by one STEP_UP times longer. A look whose white is within
TOLERANCE of the target ends it (the white is measured, not predicted); so
does the longest exposure when the white there is at least MIN_WHITE.

Why 0.75: the white is a median within the brightest part of the screen, so
its brightest blocks (vignetting, the LCD's viewing angle, a reflection) lie
above it; the sensor's noise and a PWM backlight move a frame's white by
several per cent (measured on the simulated camera with every timing flaw:
99th percentile of the screen under 1 % above the white); 75 % leaves a third of headroom,
while the signal to noise of the corners (which grows with the white) loses
only 12 % against a white at 85 % (screen-physics notes: keep the white under
about 90 %).

PWM: taking the brightest frame's white and keeping the brightest blocks
under PEAK_MAX keeps the flicker from clipping; the exposure is not rounded
to whole PWM periods: a few frames at 25 fps cannot tell a PWM frequency
(hundreds of Hz to kHz) from its aliases, and the frame-to-frame spread of a
short look mixes the backlight with the differences between the entries.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from rotstar_mrcal.capture.motion import downsample
from rotstar_mrcal.capture.source import FrameSource, record, skip

TARGET = 0.75  # the white, as a fraction of full scale (module doc: why)
PEAK_MAX = 0.92  # the brightest blocks of a look at most this (a flickering backlight, vignetting)
CLIP = 0.97  # a white at or above this is clipped: a lower bound only
MEASURABLE = 0.02  # the screen changes by at least this much during a look, or it is not seen
MIN_WHITE = 0.25  # a white below this at the longest exposure: the screen is too dark
TOLERANCE = 0.1  # a look whose white is within 10 % of the target ends the search
STEP_DOWN = 4.0  # after a clipped look
STEP_UP = 8.0  # after a look that sees nothing
MAX_LOOKS = 6
BLOCK = 4  # block means of BLOCK x BLOCK pixels
START_US = 8000.0  # the first look's exposure (a D435's default is 8500 us)
SHORTEST_US = 20.0  # the shortest exposure a look tries


@dataclasses.dataclass(frozen=True)
class Look:
    """What a short look at the playing screen saw, as fractions of full scale (NaN: no screen seen)"""

    white: float  # the screen's white: median over the frames showing white of each one's white plateau
    peak: float  # the brightest frame's 99th percentile
    spread: float  # (white - the darkest frame's white) / white over the frames showing white
    contrast: float  # how much the screen changed during the look (99th percentile of the blocks' ranges)
    frames: int

    @property
    def screen(self) -> bool:
        return self.contrast >= MEASURABLE

    @property
    def clipped(self) -> bool:
        return bool(self.white >= CLIP)


def measure_look(frames, full_scale: float, step: int = BLOCK) -> Look:
    """The Look of camera frames (T, H, W) in the camera's units; see the module doc"""
    b = np.stack([downsample(f, step) for f in frames]) / np.float32(full_scale)
    span = b.max(axis=0) - b.min(axis=0)
    contrast = float(np.percentile(span, 99))
    if len(b) < 2 or contrast < MEASURABLE:
        return Look(math.nan, math.nan, math.nan, contrast, len(b))
    screen = span >= 0.25 * contrast
    tops = np.array([np.percentile(x[screen], 99) for x in b])
    whites = np.array([np.median(x[screen][x[screen] >= 0.9 * t]) for x, t in zip(b, tops)])
    lit = tops >= 0.5 * tops.max()
    white = float(whites.max())
    return Look(white, float(tops.max()), float((white - whites[lit].min()) / white), contrast, len(b))


def round_exposure(us: float) -> float:
    """Two significant digits, at most 100 us steps (a number a user can type, and a step of at most 5 %)

    >>> round_exposure(6237.0), round_exposure(487.2), round_exposure(13480.0)
    (6200.0, 490.0, 13500.0)
    """
    if not us > 0:
        return us
    return float(round(us, max(-2, 1 - int(math.floor(math.log10(us))))))


@dataclasses.dataclass(frozen=True)
class Step:
    """The next exposure to look at, or the end: done (this look's exposure is it) or failure (one line)"""

    exposure_us: float
    done: bool = False
    failure: str = ""


def next_exposure(look: Look, exposure_us: float, shortest_us: float, longest_us: float,
                  target: float = TARGET) -> Step:
    """What a look at exposure_us asks for next, the exposures limited to [shortest_us, longest_us]

    >>> far = Look(math.nan, math.nan, math.nan, 0.001, 8)          # nothing changes
    >>> next_exposure(far, 4000, 20, 38000).exposure_us, next_exposure(far, 38000, 20, 38000).failure[:20]
    (32000.0, 'no screen in view (o')
    >>> dim = Look(0.05, 0.05, 0.0, 0.05, 8)                         # the screen's white at 5 % at the longest
    >>> next_exposure(dim, 38000, 20, 38000).failure[:27]
    'the screen is too dark: its'
    >>> next_exposure(Look(1.0, 1.0, 0.0, 0.9, 8), 30000, 20, 38000).exposure_us    # clipped: 4 times shorter
    7500.0
    >>> next_exposure(Look(0.72, 0.74, 0.03, 0.7, 8), 6200, 20, 38000).done          # within 10 %
    True
    """
    if not look.screen:
        if exposure_us < longest_us:
            return Step(round_exposure(min(longest_us, exposure_us * STEP_UP)))
        return Step(math.nan, failure=(
            f"no screen in view (or it is black): nothing changes by {MEASURABLE:.0%} of full scale during the look "
            f"even at the longest exposure, {exposure_us:.0f} us"))
    if look.clipped:
        if exposure_us <= shortest_us:
            return Step(math.nan, failure=f"the screen's white is clipped even at the shortest exposure, "
                                          f"{exposure_us:.0f} us: dim the screen or lower the gain")
        return Step(round_exposure(max(shortest_us, exposure_us / STEP_DOWN)))
    want = exposure_us * min(target / look.white, PEAK_MAX / look.peak)
    if want >= longest_us and look.white * longest_us / exposure_us < MIN_WHITE:
        return Step(math.nan, failure=(
            f"the screen is too dark: its white would reach only {look.white * longest_us / exposure_us:.0%} of full "
            f"scale at the longest exposure, {longest_us:.0f} us (at least {MIN_WHITE:.0%} needed): turn its "
            f"brightness up, or the gain"))
    want = round_exposure(min(max(want, shortest_us), longest_us))
    if abs(look.white / target - 1) <= TOLERANCE or want == exposure_us:
        return Step(float(exposure_us), done=True)
    return Step(want)


@dataclasses.dataclass(frozen=True)
class AutoExposure:
    """What choose_exposure found: the exposure (NaN on failure), its white, the looks, camera seconds"""

    exposure_us: float
    white: float  # of the last look (at exposure_us when done)
    looks: int
    frames: int  # camera frames read: the looks and the frames dropped after each change of exposure
    seconds: float  # frames / fps (NaN: the frame rate is unknown)
    spread: float = math.nan
    failure: str = ""
    history: tuple = ()  # (exposure_us, white) of every look

    def summary(self) -> str:
        """'exposure: 6200 us (white at 74 % of full scale after 2 looks, 0.6 s)', or the failure"""
        if self.failure:
            return self.failure
        secs = f", {self.seconds:.1f} s" if math.isfinite(self.seconds) else ""
        return (f"exposure: {self.exposure_us:.0f} us (white at {100 * self.white:.0f} % of full scale after "
                f"{self.looks} look{'s' if self.looks != 1 else ''}{secs})")


def look_frames(holds, refresh_hz: float, fps: float) -> int:
    """Camera frames a look needs so that it sees a frame with white wherever in the loop it starts

    The start marker (black) and the longest entry: one whole entry other
    than the marker falls inside, and three frames more (with the short
    holds the entry inside may be one whose white is small and dim, an
    identity frame's elements; measured on the simulated camera with every
    flaw, 90 looks from 30 seeds and three starting exposures: the short
    holds' 3 + 11 refreshes and 3 frames more chose the exposure within 3
    looks every time, 2 more 82 times, 1 more 46 times).

    >>> look_frames([3, 11, 11, 6], 60, 25), look_frames([30, 30, 30], 60, 25)
    (9, 28)
    """
    h = np.asarray(holds)
    return int(math.ceil((int(h[0]) + int(h.max())) / refresh_hz * (fps or 25.0))) + 3


def longest_exposure_us(fps: float) -> float:
    """The longest exposure a look tries: 95 % of the camera's frame period (31.7 ms when fps is unknown: 30 fps)

    >>> longest_exposure_us(25), longest_exposure_us(0)
    (38000.0, 31700.0)
    """
    return round_exposure(0.95e6 / (fps or 30.0))


def choose_exposure(src: FrameSource, start_us: float, look_frames: int, settle: int, shortest_us: float,
                    longest_us: float, target: float = TARGET, max_looks: int = MAX_LOOKS) -> AutoExposure:
    """Look at the screen at start_us, then as next_exposure asks, until done, a failure or max_looks

    Every look sets the exposure (the value read back is the one used),
    drops `settle` frames (a camera takes a few frames to apply it), and
    reads look_frames frames. The camera's exposure is left at the last
    look's. After max_looks without an end: the last unclipped look's
    estimate, unconfirmed, or a failure.
    """
    e = round_exposure(min(max(start_us, shortest_us), longest_us))
    n = 0
    history = []
    look = None
    for k in range(1, max_looks + 1):
        e = float(src.set_exposure_us(e))
        n += skip(src, settle)
        rec = record(src, look_frames)
        n += len(rec.frames)
        look = measure_look(rec.frames, src.full_scale)
        history.append((e, look.white))
        step = next_exposure(look, e, shortest_us, longest_us, target)
        secs = n / src.fps if src.fps else math.nan
        if step.done or step.failure:
            return AutoExposure(e if step.done else math.nan, look.white, k, n, secs, look.spread, step.failure,
                                tuple(history))
        e, last = step.exposure_us, e
    if look.screen and not look.clipped:  # the white at e predicted from the last look
        e = float(src.set_exposure_us(e))
        return AutoExposure(e, look.white * e / last, max_looks, n, secs, look.spread, "", tuple(history))
    return AutoExposure(math.nan, look.white, max_looks, n, secs, look.spread,
                        f"no exposure found in {max_looks} looks (" + ", ".join(
                            f"{x:.0f} us: white {w:.0%}" for x, w in history) + ")", tuple(history))

"""Simulated recordings of the looping player: what a camera streams while the screen plays

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.capture.simulated import player_schedule, camera_stream
    >>> sched = player_schedule(3, hold=6, refresh_hz=60, duration=1.0)
    >>> [(s.entry, round(s.t0, 2)) for s in sched[:4]]
    [(0, 0.0), (1, 0.1), (2, 0.2), (0, 0.3)]
    >>> E = np.stack([np.full((4, 5), v) for v in (0.0, 0.5, 1.0)])   # irradiance of each entry
    >>> img, seq = camera_stream(E, sched, 8, fps=20, t0=0.095, exposure_s=0.01, scan_s=0.0,
    ...                          noise=0, bits=8, drop_frames=[6])
    >>> img[:, 0, 0].tolist(), seq.tolist()       # even frames straddle a change; frame 6 lost
    ([57, 115, 172, 230, 115, 0, 115], [0, 1, 2, 3, 4, 5, 7])

Built on the simulator (rotstar_mrcal.simulate): render the irradiance of
every loop entry once (loop_irradiance: the screen showing the start marker
and the pattern frames, seen from one pose), then make the camera stream
from it:

- player_schedule: when each loop entry is on the screen. Each entry is held
  for `hold` refreshes (the marker for marker_hold); `start_entry` and
  `start_phase` start the recording mid-loop; `drop` skips display frames
  and `double` holds them twice as long (numbers count shown frames from
  the start, 0, 1, 2, ...);
- camera_stream: camera frame i integrates [t0 + i / fps, + exposure_s].
  The panel updates row by row over scan_s, so camera row y sees the
  change at (switch time + scan_s * y / H): a frame that straddles a change
  is a row-dependent blend of two entries. Then the sensor (simulate.expose:
  gain, noise, quantisation), frames listed in drop_frames are lost (a gap
  in the sequence numbers), and drift_px moves the image by that much per
  frame (a camera that is not still);
- write_player_recording: a whole session as a replayable recording (.npy +
  .json), pose after pose with the camera moving in between: what
  `rotstar-simulate --recording` writes;
- SimulatedCamera: the same stream live, one frame per read(), as a
  FrameSource whose exposure is set as a device's (the light scales with
  it): what rotstar-capture's exposure look is tested on.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os

import cv2
import numpy as np

from rotstar_mrcal.capture.source import Frame, FrameSource
from rotstar_mrcal.pattern.loop import entry_holds, player_loop
from rotstar_mrcal.simulate.exposure import expose
from rotstar_mrcal.simulate.irradiance import render_irradiance
from rotstar_mrcal.simulate.screen import exact_frames, make_screen


def loop_irradiance(layout, model, rt_cam_board, supersample: int = 4, psf=1.0, room: float = 0.02,
                    frames: np.ndarray | None = None) -> np.ndarray:
    """(n_entries, H, W) irradiance of every entry of the player's loop, marker first

    The same rendering as simulate.write_dataset with its default Settings
    (exact frames, room 0.02, supersample 4, Gaussian PSF of 1 px), so a
    recording built from it and a directly rendered dataset see the same
    images up to noise.
    """
    fr = exact_frames(layout) if frames is None else np.asarray(frames, np.float32)
    if len(player_loop(layout.frames())) != len(fr) + 1:
        raise ValueError(f"{len(fr)} frames for the layout's {len(layout.frames())}")
    screen = make_screen(np.concatenate([np.zeros_like(fr[:1]), fr]), layout, room)
    return render_irradiance(screen, model, rt_cam_board, supersample=supersample, psf=psf)


@dataclasses.dataclass(frozen=True)
class Shown:
    entry: int  # loop entry on the screen
    t0: float  # seconds: the top row switches to it
    t1: float  # seconds: the top row switches away


def player_schedule(n_entries: int, hold, marker_hold: int | None = None, refresh_hz: float = 60.0,
                    duration: float = 10.0, start_entry: int = 0, start_phase: float = 0.0,
                    drop=(), double=(), late: float = 0.0, early: float = 0.0, rng=None) -> list[Shown]:
    """What the player shows from t = 0 to duration (seconds)

    hold: refreshes per entry, one number or one per loop entry (the
    player's hold per frame kind). late / early: the probability that the
    browser shows the next entry one refresh late (a missed
    requestAnimationFrame: this entry held one refresh longer, everything
    after it one refresh later) or one refresh early (this entry one refresh
    shorter), drawn per shown entry from rng.
    """
    holds = [int(hold)] * n_entries if np.ndim(hold) == 0 else [int(h) for h in hold]
    if marker_hold:
        holds[0] = int(marker_hold)
    rng = np.random.default_rng(rng)
    drop, double = set(drop), set(double)
    out = []
    t = None
    g = 0
    while t is None or t < duration:
        e = (start_entry + g) % n_entries
        n = holds[e] * (2 if g in double else 1)
        if late or early:
            u = rng.uniform()
            n += 1 if u < late else (-1 if u < late + early and n > 1 else 0)
        if t is None:
            t = -start_phase * n / refresh_hz if start_phase else 0.0
        if g not in drop:
            out.append(Shown(e, t, t + n / refresh_hz))
            t += n / refresh_hz
        g += 1
    return out


def ramp_integral(x, c, r: float):
    """Integral from -inf to x of the LCD's response to a switch at c: a ramp from 0 to 1 over r seconds

    >>> float(ramp_integral(3.0, 1.0, 0.0)), float(ramp_integral(3.0, 1.0, 1.0)), float(ramp_integral(1.5, 1.0, 1.0))
    (2.0, 1.5, 0.125)
    """
    x, c = np.asarray(x, float), np.asarray(c, float)
    if r <= 0:
        return np.maximum(x - c, 0.0)
    u = np.clip(x - c, 0.0, r)
    return u * u / (2 * r) + np.maximum(x - c - r, 0.0)


def blend_weights(sched: list[Shown], a: float, b: float, rows: int, scan_s: float,
                  response_s: float = 0.0) -> dict[int, np.ndarray]:
    """{entry: (rows,) fraction of the exposure [a, b] each camera row sees it}

    Row y switches scan_s * (y + 0.5) / rows after the top row; a pixel takes
    response_s to go from the old entry to the new one (linearly: the LCD's
    response), so an exposure that starts just after a switch still sees a
    little of the entry before.
    """
    delay = scan_s * (np.arange(rows) + 0.5) / rows
    out: dict[int, np.ndarray] = {}
    for s in sched:
        if s.t1 + scan_s + response_s <= a or s.t0 >= b:
            continue
        up = ramp_integral(b, s.t0 + delay, response_s) - ramp_integral(a, s.t0 + delay, response_s)
        down = ramp_integral(b, s.t1 + delay, response_s) - ramp_integral(a, s.t1 + delay, response_s)
        w = np.clip(up - down, 0, None) / (b - a)
        if w.any():
            out[s.entry] = out.get(s.entry, 0) + w
    return out


def pwm_gain(a: float, b: float, pwm_hz: float, duty: float, phase: float = 0.0) -> float:
    """Light a PWM-dimmed backlight gives over the exposure [a, b], relative to its mean

    The backlight is on for the first `duty` of every period (1 / pwm_hz),
    shifted by phase (seconds). An exposure of a whole number of periods
    gets exactly the mean; a short one gets more or less.

    >>> pwm_gain(0.0, 0.01, 200, 0.5), pwm_gain(0.0, 0.0025, 200, 0.5), pwm_gain(0.0025, 0.005, 200, 0.5)
    (1.0, 2.0, 0.0)
    """
    if duty >= 1 or pwm_hz <= 0:
        return 1.0

    def on(x):
        q = (x - phase) * pwm_hz
        return (math.floor(q) * duty + min(q - math.floor(q), duty)) / pwm_hz

    return (on(b) - on(a)) / (duty * (b - a))


def impurity(E: np.ndarray, w: dict[int, np.ndarray]) -> tuple[int, float]:
    """(the entry a camera frame is nearest, the largest difference at any pixel from that entry alone)"""
    img = sum(w[k][:, None] * E[k] for k in w)
    return min(((e, float(np.abs(img - E[e]).max())) for e in w), key=lambda p: p[1])


def camera_stream(E: np.ndarray, sched: list[Shown], n: int, fps: float = 25.0, exposure_s: float = 0.016,
                  scan_s: float = 1 / 60, t0: float = 0.0, gain: float = 0.9, noise: float = 0.01,
                  bits: int = 16, value_bits: int | None = None, drop_frames=(), drift_px=(0.0, 0.0),
                  rng=0, response_s: float = 0.0, pwm=None, clock_drift: float = 0.0, drop_rate: float = 0.0,
                  truth: list | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(frames (n - dropped, H, W) uint8/uint16, sequence numbers) of the camera filming the schedule

    E: (n_entries, H, W) irradiance of every loop entry (entry 0 the marker).
    The display's and the camera's timing flaws: response_s (the LCD's
    response, blend_weights), pwm = (Hz, duty, phase s) of a PWM-dimmed
    backlight (pwm_gain), clock_drift (the camera's clock runs 1 +
    clock_drift times fast against the screen's: frame i starts at
    t0 + i / (fps (1 + clock_drift))), drop_rate (the driver loses a frame
    with this probability, besides drop_frames). truth: a list that gets
    (entry, impurity) of every frame kept (the function impurity).
    """
    rng = np.random.default_rng(rng)
    H, W = E.shape[1:]
    drop_frames = set(drop_frames)
    frames, seq = [], []
    for i in range(n):
        a = t0 + i / (fps * (1 + clock_drift))
        w = blend_weights(sched, a, a + exposure_s, H, scan_s, response_s)
        if i in drop_frames or (drop_rate and rng.uniform() < drop_rate):
            continue
        if truth is not None:
            truth.append(impurity(E, w))
        img = np.zeros((H, W))
        for e, we in w.items():
            img += we[:, None] * E[e]
        if pwm:
            img *= pwm_gain(a, a + exposure_s, *pwm)
        if drift_px[0] or drift_px[1]:
            M = np.float32([[1, 0, drift_px[0] * i], [0, 1, drift_px[1] * i]])
            img = cv2.warpAffine(img, M, (W, H), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        frames.append(expose(img, gain=gain, noise=noise, bits=bits, value_bits=value_bits, rng=rng))
        seq.append(i)
    return np.stack(frames), np.array(seq)


@dataclasses.dataclass(frozen=True)
class Flaws:
    """The display's and the camera's timing flaws, each a parameter (0 / None: off)"""

    scan_s: float = 1 / 60  # the panel updates row by row over this time (a straddling exposure: rows blend)
    response_s: float = 0.0  # LCD response: a pixel takes this long to go from one entry to the next
    pwm: tuple | None = None  # (Hz, duty) of a PWM-dimmed backlight, its phase random
    late: float = 0.0  # probability that the browser shows the next entry one refresh late
    early: float = 0.0  # ... or one refresh early
    drop_rate: float = 0.0  # probability that the camera's driver loses a frame
    clock_drift: float = 0.0  # the camera's clock runs 1 + clock_drift times fast against the screen's


ALL_FLAWS = Flaws(scan_s=1 / 60, response_s=0.005, pwm=(480.0, 0.6), late=0.03, early=0.01, drop_rate=0.01,
                  clock_drift=2e-4)
"""Every flaw on: a 60 Hz panel scanning over one refresh with a 5 ms response, a 480 Hz backlight at 60 %
duty, the browser 3 % of the entries a refresh late and 1 % early, the driver losing 1 % of the frames, the
camera's clock 200 ppm fast"""


def record_player(E: np.ndarray, hold, n: int, flaws: Flaws = Flaws(), fps: float = 25.0, exposure_s: float = 0.008,
                  refresh_hz: float = 60.0, start_entry: int = 0, start_phase: float = 0.0, rng=0,
                  truth: list | None = None, **sensor) -> tuple[np.ndarray, np.ndarray]:
    """(frames, sequence numbers): n camera frames of the looping player with the flaws (camera_stream)

    hold: refreshes per entry (one number or one per entry); sensor:
    camera_stream's gain, noise, bits, value_bits, drift_px.
    """
    rng = np.random.default_rng(rng)
    duration = n / fps + 2.0
    # the schedule starts an entry early, so that rows the panel reaches later see what came before
    prev = (start_entry - 1) % len(E)
    sched = player_schedule(len(E), hold, refresh_hz=refresh_hz, duration=duration, start_entry=prev,
                            start_phase=start_phase, late=flaws.late, early=flaws.early, rng=rng)
    pwm = None if flaws.pwm is None else (flaws.pwm[0], flaws.pwm[1], float(rng.uniform(0, 1 / flaws.pwm[0])))
    t0 = sched[0].t1 + start_phase * (sched[1].t1 - sched[1].t0)  # start_phase into start_entry
    return camera_stream(E, sched, n, t0=t0,
                         fps=fps, exposure_s=exposure_s, scan_s=flaws.scan_s, rng=rng,
                         response_s=flaws.response_s, pwm=pwm, clock_drift=flaws.clock_drift,
                         drop_rate=flaws.drop_rate, truth=truth, **sensor)


def pose_frames(fps: float, loop_s: float, loops: float, still_s: float) -> int:
    """Camera frames one pose of a simulated session holds still: --still s, then loops of the player, then one more

    >>> pose_frames(25, 10.0, 2.2, 1.0)      # 1 s + 2.2 loops + 1 loop of margin
    825
    """
    return int(math.ceil((still_s + (loops + 1) * loop_s) * fps))


def write_player_recording(path: str, layout, model, rts, *, hold: int | None, refresh_hz: float = 60.0,
                           fps: float = 25.0, loops: float = 2.2, still_s: float = 1.0, move_s: float = 1.0,
                           exposure_s: float = 0.016, gain: float = 0.9, noise: float = 0.01, bits: int = 16,
                           room: float = 0.02, supersample: int = 4, psf=1.0, frames=None, seed: int = 0,
                           progress=None, chunk: int = 32, flaws: Flaws = Flaws()) -> int:
    """A camera filming the looping player from each pose of rts in turn, as path (.npy + .json); returns frames

    Per pose the camera holds still for pose_frames (enough for rotstar-capture
    --auto to see stillness and record `loops` loops), starting at a random
    point of the loop, then moves for move_s seconds (the image drifts) before
    the next pose. The file's disk space is allocated first (a full disk: an
    OSError naming it, nothing left behind); frames are rendered in chunks.
    The .json beside it (backend_replay) holds the sequence numbers and fps.
    flaws: the display's and the camera's timing flaws (Flaws; frames the
    driver loses leave gaps in the sequence numbers, as a camera's do).
    """
    from rotstar_mrcal.atomic import allocated_npy, atomic_write

    holds = entry_holds(player_loop(layout.frames()), hold)  # hold None: pattern.loop.SHORT_HOLDS per kind
    n_entries = len(holds)
    loop_s = int(holds.sum()) / refresh_hz
    still = pose_frames(fps, loop_s, loops, still_s)
    move = int(math.ceil(move_s * fps)) if len(rts) > 1 else 0
    total = len(rts) * still + (len(rts) - 1) * move
    W, H = (int(v) for v in model.imagersize())
    rng = np.random.default_rng([4, seed])
    lost = set(np.flatnonzero(rng.uniform(size=total) < flaws.drop_rate).tolist()) if flaws.drop_rate else set()
    rate = fps * (1 + flaws.clock_drift)
    buf = allocated_npy(path, np.uint8 if bits == 8 else np.uint16, (total - len(lost), H, W))
    try:
        k = g = 0  # frames written, frames the camera took
        for i, rt in enumerate(rts):
            E = loop_irradiance(layout, model, rt, supersample=supersample, psf=psf, room=room, frames=frames)
            n = still + (move if i < len(rts) - 1 else 0)
            sched = player_schedule(n_entries, holds, refresh_hz=refresh_hz, duration=n / fps + 1.0,
                                    start_entry=int(rng.integers(n_entries)), start_phase=float(rng.uniform()),
                                    late=flaws.late, early=flaws.early, rng=rng)
            pwm = None if flaws.pwm is None else (*flaws.pwm[:2], float(rng.uniform(0, 1 / flaws.pwm[0])))
            for a, b, drift in ((0, still, (0.0, 0.0)), (still, n, (2.0, 1.0))):  # still, then moving
                for c in range(a, b, chunk):
                    m = min(chunk, b - c)
                    gone = [j - g for j in range(g, g + m) if j in lost]
                    out, _ = camera_stream(E, sched, m, fps=rate, exposure_s=exposure_s, t0=c / rate, gain=gain,
                                           noise=noise, bits=bits, rng=rng, drift_px=drift, scan_s=flaws.scan_s,
                                           response_s=flaws.response_s, pwm=pwm, drop_frames=gone)
                    buf[k:k + len(out)] = out
                    k += len(out)
                    g += m
            if progress:
                progress(f"pose {i + 1}/{len(rts)}: {still} still frames" + (f", {move} moving" if move and
                                                                              i < len(rts) - 1 else ""))
        buf.flush()
        with atomic_write(os.path.splitext(path)[0] + ".json") as f:
            json.dump({"sequence": [j for j in range(total) if j not in lost], "fps": float(fps), "simulated": {
                "poses": len(rts), "still_frames": still, "moving_frames": move, "hold": hold,
                "refresh_hz": refresh_hz, "loops": loops, "flaws": dataclasses.asdict(flaws)}}, f)
            f.write("\n")
    except BaseException:
        del buf
        os.remove(path)
        raise
    return total - len(lost)


class SimulatedCamera(FrameSource):
    """A camera filming the looping player live, one frame per read(), its exposure set as a device's is

    E: (n_entries, H, W) irradiance of every loop entry (loop_irradiance), in
    units of the screen's white; hold: refreshes per entry (entry_holds).
    Each frame is camera_stream's, with the flaws of record_player, except
    that the light scales with the exposure: a pixel of irradiance 1 reaches
    full scale at full_scale_us (gain = exposure / full_scale_us; expose
    clips at full scale and adds the noise as today). set_exposure_us takes
    effect `latency` frames later (a D435 needs a few frames) and is limited
    to [1 us, the frame period], as a camera limits it; the value it
    returns is the one used. The camera stops (read() gives None, as a
    replay's end) after `duration` seconds.

    SYNOPSIS

        >>> E = np.stack([np.zeros((8, 10)), np.ones((8, 10))])      # the marker, one white entry
        >>> cam = SimulatedCamera(E, [6, 6], exposure_us=5000, full_scale_us=10000, noise=0, latency=0)
        >>> cam.set_exposure_us(50000), cam.fps                 # at most the frame period at 25 fps
        (40000.0, 25.0)
        >>> cam.set_exposure_us(5000)
        5000.0
        >>> [int(cam.read().image.max()) for _ in range(6)]     # white at half scale; the marker black
        [32768, 0, 0, 32768, 32768, 32768]
        >>> cam.set_exposure_us(20000), max(int(cam.read().image.max()) for _ in range(3))   # twice the light: clipped
        (20000.0, 65535)
    """

    name = "simulated"

    def __init__(self, E: np.ndarray, hold, fps: float = 25.0, refresh_hz: float = 60.0, flaws: Flaws = Flaws(),
                 exposure_us: float = 8000.0, full_scale_us: float = 13300.0, noise: float = 0.01, bits: int = 16,
                 value_bits: int | None = None, latency: int = 2, duration: float = 120.0, start_entry: int = 0,
                 start_phase: float = 0.0, seed=0):
        self.E, self.fps, self.flaws = np.asarray(E), float(fps), flaws
        self.full_scale_us, self.noise, self.bits, self.value_bits = full_scale_us, noise, bits, value_bits
        self.full_scale = float((1 << bits) - 1)
        self.latency, self.duration = int(latency), float(duration)
        self.rng = np.random.default_rng(seed)
        prev = (start_entry - 1) % len(self.E)  # as record_player: rows the panel reaches later see the entry before
        self.sched = player_schedule(len(self.E), hold, refresh_hz=refresh_hz, duration=duration + 1.0,
                                     start_entry=prev, start_phase=start_phase, late=flaws.late, early=flaws.early,
                                     rng=self.rng)
        self.ends = np.array([s.t1 for s in self.sched])
        self.pwm = None if flaws.pwm is None else (flaws.pwm[0], flaws.pwm[1],
                                                   float(self.rng.uniform(0, 1 / flaws.pwm[0])))
        self.t0 = self.sched[0].t1 + start_phase * (self.sched[1].t1 - self.sched[1].t0)
        self.i = 0  # the camera's frame counter (frames the driver loses included)
        self.exposures = [(0, float(exposure_us))]  # (first frame, exposure) of every setting

    def set_exposure_us(self, us: float) -> float:
        us = float(min(max(us, 1.0), 1e6 / self.fps))
        self.exposures.append((self.i + self.latency, us))
        return us

    def exposure_at(self, i: int) -> float:
        """The exposure (us) frame i is taken with"""
        return [e for k, e in self.exposures if k <= i][-1]

    def read(self, timeout: float = 2.0) -> Frame | None:
        while True:
            i = self.i
            a = self.t0 + i / (self.fps * (1 + self.flaws.clock_drift))
            if a - self.t0 > self.duration:
                return None
            self.i += 1
            if not (self.flaws.drop_rate and self.rng.uniform() < self.flaws.drop_rate):
                break
        exposure_s = self.exposure_at(i) * 1e-6
        k = int(np.searchsorted(self.ends, a - self.flaws.scan_s - self.flaws.response_s))
        near = [s for s in self.sched[max(0, k - 1):k + 8] if s.t0 < a + exposure_s]
        img, _ = camera_stream(self.E, near, 1, fps=self.fps, exposure_s=exposure_s, scan_s=self.flaws.scan_s,
                               t0=a, gain=exposure_s * 1e6 / self.full_scale_us, noise=self.noise, bits=self.bits,
                               value_bits=self.value_bits, rng=self.rng, response_s=self.flaws.response_s,
                               pwm=self.pwm)
        return Frame(img[0], i, int(round(a * 1e9)))

    def info(self) -> dict:
        return {"backend": self.name, "fps": self.fps, "exposure_us": self.exposure_at(self.i),
                "shape": list(self.E.shape[1:]), "flaws": dataclasses.asdict(self.flaws)}

"""A capture session of several cameras: one pose -> <pose>/camera-<k>/ folders split with the same boundaries

SYNOPSIS

    from rotstar_mrcal.capture.rig import RigSource
    from rotstar_mrcal.capture.rig_session import RigDataset, capture_rig_one
    rig = RigSource([ir_y12i_source, colour_source])          # cameras 0, 1 (left, right), 2 (colour)
    ds = RigDataset("seq/exp4000us", 4000, rig.cameras)
    out = capture_rig_one(rig, ds, "pose000", pattern, layout, nframes, "seq/raw", SessionOptions())
    out.ok, out.messages, out.folder      # a board on some camera; lines for the user; seq/exp4000us/pose000

The multi-camera dataset (doc/dataset.md): seq/pattern.json and, per pose,
seq/<pose>/camera-<k>/ holding every frame of pattern.json, for every
camera. A recording of the rig (capture.rig.record_rig: one frame per
camera per lockstep step) is split with the same frame boundaries on every
camera (rig_segment.segment_rig), then each camera's averages are checked
and written as a one-camera capture's are (session.process_segmented:
value scale, quick detection, coverage in coverage-camera-<k>.png). A pose
is kept when any camera saw the board; then every camera's folder is
written (a camera that missed the board still holds its frames, so that all
cameras of a pose hold the same files), and the pose is dropped whole when
no camera saw it. The raw recordings go to raw/<pose>[_exp<us>us]/camera-<k>.npy
(+ .json with the sequence numbers and time stamps) and are removed unless
opts.keep_raw; `rotstar-segment raw/<...>/ --out seq/<pose>` splits them again.
"""

from __future__ import annotations

import json
import os
import shutil

import numpy as np

from rotstar_mrcal.atomic import allocated_npy, atomic_write, whole_or_none
from rotstar_mrcal.capture.pose import write_segmented
from rotstar_mrcal.capture.rig import RigSource, record_rig
from rotstar_mrcal.capture.rig_segment import segment_rig
from rotstar_mrcal.capture.motion import difference_signal, screen_pixels
from rotstar_mrcal.capture.segment import SegmentError, threshold
from rotstar_mrcal.capture.source import CaptureError
from rotstar_mrcal.capture.session import OutputDataset, PoseOutcome, SessionOptions, process_segmented


class RigDataset:
    """One output dataset (one exposure) of several cameras: one OutputDataset per camera inside it"""

    def __init__(self, folder: str, exposure: int | None, cameras: int):
        self.folder, self.exposure = folder, exposure
        self.cameras = [OutputDataset(folder, exposure, f"camera-{k}") for k in range(cameras)]
        self.log: list[dict] = []
        self.tau: float | None = None

    def what(self, pose: str) -> str:
        return f"{pose} at {self.exposure} us" if self.exposure else pose

    @property
    def good(self) -> int:
        return sum(1 for e in self.log if e.get("ok"))


def save_raw(folder: str, recs, fps: float, exposure) -> None:
    """The sequence numbers and time stamps of each camera's recording beside its .npy"""
    for k, r in enumerate(recs):
        with atomic_write(os.path.join(folder, f"camera-{k}.json")) as f:
            json.dump({"sequence": [int(v) for v in r.sequence], "t_ns": [int(v) for v in r.t_ns], "fps": fps,
                       "exposure_us": exposure, "frames": len(r.sequence)}, f)
            f.write("\n")


def capture_rig_one(rig: RigSource, ds: RigDataset, pose: str, pattern: dict, layout, nframes: int, raw_dir: str,
                    opts: SessionOptions) -> PoseOutcome:
    """Record nframes lockstep steps of every camera, then process_rig_recording; EOFError when a source ended"""
    tag = f"{pose}_exp{ds.exposure}us" if ds.exposure else pose
    folder = os.path.join(raw_dir, tag)
    os.makedirs(folder, exist_ok=True)
    first = rig.read_views()
    if first is None:
        raise EOFError
    try:
        bufs = [allocated_npy(os.path.join(folder, f"camera-{k}.npy"), f.image.dtype, (nframes,) + f.image.shape)
                for k, f in enumerate(first)]
    except OSError as e:  # a full disk: said before recording, not a SIGBUS half-way
        shutil.rmtree(folder, ignore_errors=True)
        raise CaptureError(str(e)) from None
    try:
        recs = record_rig(rig, nframes, outs=bufs, first=first)
        n = len(recs[0].sequence)
        if opts.keep_raw:
            for b in bufs:
                b.flush()
            save_raw(folder, recs, rig.fps, ds.exposure)
        short = [f"{ds.what(pose)}: the source ended after {n} of {nframes} frames"] if n < nframes else []
        out = process_rig_recording(ds, pose, pattern, layout, recs, opts)
        out.messages[:0] = short
        return out
    finally:
        del bufs
        if not opts.keep_raw:
            shutil.rmtree(folder, ignore_errors=True)


def process_rig_recording(ds: RigDataset, pose: str, pattern: dict, layout, recs, opts: SessionOptions) -> PoseOutcome:
    """Segment every camera with the same boundaries, check and write them; see the module doc"""
    entry = {"pose": pose, "exposure_us": ds.exposure, "frames": len(recs[0].sequence),
             "dropped": [r.dropped for r in recs], "repeated": [int(np.sum(np.diff(r.sequence) == 0)) for r in recs]}
    ds.log.append(entry)
    try:
        rs = segment_rig([r.frames for r in recs], pattern["frames"], layout, [r.full_scale for r in recs],
                         opts.segment)
    except SegmentError as e:
        so, f = opts.segment, recs[0]
        d, _ = difference_signal(f.frames, f.full_scale, so.step, screen_pixels(f.frames, f.full_scale, so.step))
        ds.tau = threshold(d, so.k, so.ratio)  # (for --auto: what segment() would have set)
        entry.update(ok=False, error=str(e))
        return PoseOutcome(False, [f"{ds.what(pose)}: not usable: {e}"])
    ds.tau = rs.cameras[0].tau
    with whole_or_none(os.path.join(ds.folder, pose)):  # an interrupt leaves no pose with some of its cameras
        return write_rig_pose(ds, pose, pattern, layout, recs, rs, entry)


def write_rig_pose(ds: RigDataset, pose: str, pattern: dict, layout, recs, rs, entry: dict) -> PoseOutcome:
    """Check and write every camera of one segmented rig pose (the pose is dropped whole when none saw the board)"""
    messages = [f"{ds.what(pose)}: {n}" for n in rs.notes]
    outs, entry["cameras"] = [], []
    for k, (cam, seg, r) in enumerate(zip(ds.cameras, rs.cameras, recs)):
        sub = {"dropped": r.dropped}
        cam.log.append(sub)
        outs.append(process_segmented(cam, pose, pattern, layout, seg, r.frames.shape, r.full_scale, sub))
        entry["cameras"].append(sub)
        messages += outs[-1].messages
    ok = any(o.ok for o in outs)
    entry.update(ok=ok, reference=rs.reference, summary=rs.summary())
    if not ok:
        return PoseOutcome(False, messages + [f"{ds.what(pose)}: no camera saw the board; pose dropped"])
    for cam, seg, r, o in zip(ds.cameras, rs.cameras, recs, outs):
        if not o.ok:  # every camera of a pose holds the same frames
            write_segmented(cam.folder, cam.pose_folder(pose), seg, pattern, r.full_scale, cam.scale,
                            {"exposure_us": ds.exposure, "quick_check": "no board"})
    return PoseOutcome(True, messages, os.path.join(ds.folder, pose))

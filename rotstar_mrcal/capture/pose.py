"""One pose: the segmented frames as a dataset pose folder, and a quick look at the board

SYNOPSIS

    from rotstar_mrcal.capture.pose import write_segmented, quick_check, value_scale
    scale, note = value_scale(recording.frames.max(), recording.full_scale)
    folder = write_segmented("seq", "pose000", seg, pattern, full_scale, scale)
    r = quick_check(seg, layout, pattern, full_scale / scale)   # detect_pose on the averages
    r.found, r.n_valid

Averages are written as 16-bit PNGs in every case: a 16-bit recording keeps
its units (rounded), an 8-bit one is scaled by 257 (so full scale stays full
scale and the extra precision of the average is kept), and a 16-bit stream
that carries fewer bits in the low end of the word (the D435's Y16 may hold
10-bit values; not verified on hardware) can be scaled up with value_scale.
Scaling changes no geometry: the detector only uses full scale to recognise
dark and saturated frames.

Every frame of pattern.json is written, the identity frames included (a
pattern without them gives a pose without them, as before).

Beside the frames, <pose>/segment.json records which camera frames were
averaged for every file, the threshold, every loop's verdict and the scale.
The dataset's pattern.json is a copy of the one the pattern was made with; a
different one already there is an error (mixing two patterns in one dataset).
"""

from __future__ import annotations

import json
import os

import numpy as np

from rotstar_mrcal import dataset
from rotstar_mrcal.atomic import atomic_folder, atomic_write
from rotstar_mrcal.detect.pipeline import PoseCorners, detect_pose
from rotstar_mrcal.pattern.layout import Layout, layout_from_dict
from rotstar_mrcal.capture.segment import Segmentation


def value_scale(max_value: float, full_scale: float) -> tuple[float, str]:
    """(factor, note): scale 16-bit data that only uses the low bits up to 16 bits

    SYNOPSIS

        >>> value_scale(1000, 65535)
        (64.0, 'values reach only 1000 of 65535: 10-bit data in a 16-bit word? scaled by 64')
        >>> value_scale(50000, 65535), value_scale(200, 255)
        ((1.0, ''), (1.0, ''))
    """
    if full_scale != 65535:
        return 1.0, ""
    for bits in (10, 12):
        if max_value <= (1 << bits) - 1:
            f = float(1 << (16 - bits))
            return f, (f"values reach only {int(max_value)} of 65535: {bits}-bit data in a 16-bit word? "
                       f"scaled by {f:g}")
    return 1.0, ""


def encode_average(img: np.ndarray, full_scale: float, scale: float = 1.0) -> np.ndarray:
    """An averaged frame in recorded units -> uint16 PNG values

    SYNOPSIS

        >>> encode_average(np.array([[0.4, 254.6]]), 255).tolist()
        [[103, 65432]]
    """
    f = (65535.0 / 255.0 if full_scale == 255 else 1.0) * scale
    return np.clip(np.rint(np.asarray(img, np.float64) * f), 0, 65535).astype(np.uint16)


def ensure_pattern(seq: str, pattern: dict) -> str:
    """Copy pattern.json into the dataset folder, or check that the one there is the same pattern"""
    os.makedirs(seq, exist_ok=True)
    fn = os.path.join(seq, "pattern.json")
    if os.path.exists(fn):
        have, _ = dataset.read_pattern(fn)
        if layout_from_dict(have) != layout_from_dict(pattern) or \
                [f["file"] for f in have["frames"]] != [f["file"] for f in pattern["frames"]]:
            raise dataset.DatasetError(f"{fn}: a different pattern is already in this dataset; "
                                       f"use another output folder")
        return fn
    with atomic_write(fn) as f:
        json.dump(pattern, f, indent=2)
        f.write("\n")
    return fn


def write_segmented(seq: str, pose: str, seg: Segmentation, pattern: dict, full_scale: float,
                    scale: float = 1.0, extra: dict | None = None) -> str:
    """Write seq/<pose>/<file>.png for every frame of pattern.json, and segment.json; returns the folder

    The folder is written whole or not at all (atomic.atomic_folder): a
    temporary folder beside it, renamed when complete (replacing one there).
    """
    ensure_pattern(seq, pattern)
    folder = os.path.join(seq, pose)
    try:
        with atomic_folder(folder) as tmp:  # an interrupt leaves no pose folder with some of its frames
            write_into(tmp, seg, full_scale, scale, extra)
    except OSError as e:  # name the pose folder, not the temporary one
        what = os.path.basename(e.filename) if e.filename else "it"
        raise OSError(f"{folder}: cannot write {what} ({e.strerror or e})") from None
    return folder


def write_into(folder: str, seg: Segmentation, full_scale: float, scale: float = 1.0, extra: dict | None = None) -> None:
    """The frames and segment.json of write_segmented, into an existing folder"""
    dataset.write_pose(os.path.dirname(folder), os.path.basename(folder),
                       {f: encode_average(img, full_scale, scale) for f, img in seg.images.items()})
    v = seg.loop
    info = {
        "format": "rotstar-segment/1",
        "summary": seg.summary(),
        "frames_averaged": {f: list(r) for f, r in seg.ranges.items()},
        "threshold": seg.tau,
        "stretches": [[s.start, s.stop] for s in seg.stretches],
        "start_markers": [int(i) for i in np.flatnonzero(seg.markers)],
        "loops": [{"start_frame": seg.stretches[lv.marker].start, "ok": lv.ok, "reason": lv.reason,
                   "correlation": lv.correlation, "drift_px": lv.motion_px} for lv in seg.loops],
        "chosen_loop": seg.chosen,
        "drift_px": v.motion_px,
        "recorded_full_scale": full_scale,
        "value_scale": scale,
        "method": seg.method,
        **({"missing": list(seg.missing)} if seg.missing else {}),
        **({"frames_used": {f: [int(t) for t in u] for f, u in seg.used.items()}} if seg.used else {}),
        **(extra or {}),
    }
    with open(os.path.join(folder, "segment.json"), "w") as f:
        json.dump(info, f, indent=1, default=float)
        f.write("\n")


def quick_check(seg: Segmentation, layout: Layout, pattern: dict, full_scale: float) -> PoseCorners:
    """detect_pose on the segmented averages (with the identity frames, which label a partial board)

    full_scale: of the averages as they are, in recorded units (before
    encode_average's scaling): the recording's full scale / value_scale.
    An identity frame seg.images lacks is read as not recorded
    (dataset.identity_stack), as rotstar-detect reads the pose folder.
    """
    def files(kind):
        return [f["file"] for f in pattern["frames"] if f["kind"] == kind]

    rot = np.stack([seg.images[f] for f in files("rotstar")]).astype(np.float32)
    cb = [seg.images[f] for f in files("checkerboard") if f in seg.images]
    ident = dataset.identity_stack(seg.images, files("identity"), rot.shape[1:])[0] if files("identity") else None
    return detect_pose(rot, layout, full_scale=full_scale, checkerboard=np.asarray(cb[0], np.float32) if cb else None,
                       identity=ident)

"""A dataset's corners by one or more methods, written as corners.vnl files; one dataset split in two

SYNOPSIS

    from rotstar_mrcal.evaluate.detection import detect_dataset, split_interleaved
    vnls = detect_dataset("seq", ["rotstar", "opencv-sb"], "xval", "A", jobs=2)
    vnls["rotstar"]                              # 'xval/rotstar/A.vnl'
    split_interleaved("cal/corners.vnl", "A.vnl", "B.vnl")   # boards 0, 2, 4, ... / 1, 3, 5, ...

detect_dataset runs cornersets.detect_methods on every pose of a dataset
(in `jobs` processes) and writes one corners.vnl per method (a method that
pools a dataset, psf-sim, as rotstar-detect does: registry.pooled),
outdir/<method>/<side>.vnl; rotstar's methods name the first rotating-star
frame of each pose, the checkerboard ones the checkerboard frame.

split_interleaved makes the two groups of mrcal's cross-validation from one
recording (mrcal's docs split a dance into odd and even frames): the boards
of a corners.vnl, in the order they appear, alternately into two files.
Images without a board go to neither.
"""

from __future__ import annotations

import collections
import os

from rotstar_mrcal import dataset
from rotstar_mrcal.atomic import atomic_write
from rotstar_mrcal.detect.display_offsets import MAX_MOTION, dataset_offsets
from rotstar_mrcal.peers.registry import Found, pooled
from rotstar_mrcal.parallel import process_map
from rotstar_mrcal.vnl import write_corners
from rotstar_mrcal.peers.cornersets import detect_methods
from rotstar_mrcal.calibrate.cornerset import SourceError, read_vnl_names


def _detect_pose(seq, pose, layout, methods):
    p = dataset.load_pose(seq, pose, layout)
    found = detect_methods(p.rotstar, layout, p.full_scale, p.checkerboard, methods, identity=p.identity)
    cbfile = os.path.join(seq, pose, next(f["file"] for f in layout.frames() if f["kind"] == "checkerboard"))
    return pose, p.first_file, cbfile, found


def moved_poses(res: dict, max_motion: float = MAX_MOTION) -> list[str]:
    """Poses whose rotating-star frames moved against the dataset's display maps (detect.display_offsets)"""
    shifts = {}
    for p, (_, _, _, found) in res.items():
        f = found.get("rotstar") or found.get("rotstar-weighted")
        if f is not None and f.corners is not None and f.shifts is not None:
            shifts[p] = f.shifts
    return dataset_offsets(shifts).moved(max_motion)


def detect_dataset(seq: str, methods, outdir: str, side: str, jobs: int = 1, progress=None,
                   log=None, folders: dict | None = None) -> dict[str, str]:
    """Detect every method on a dataset; write outdir/<method>/<side>.vnl; {method: vnl}

    folders: {method: folder name} for methods written under another name
    (rotstar-crossval writes rotstar-detect's default, rotstar-psf-sim, as
    its corner set "rotstar").

    progress(pose, message) is called as each pose is done; log(line) for a
    pose dropped afterwards because its camera moved (moved_poses: every
    method loses it, so that all compare the same poses).
    """
    _, layout = dataset.read_pattern(seq)
    poses = dataset.list_poses(seq)
    if not poses:
        raise SourceError(f"{seq}: no pose folders")
    res = {}

    def done(r):
        res[r[0]] = r
        if progress:
            progress(r[0], ", ".join(f"{m} {'ok' if v.corners is not None else 'none'}" for m, v in r[3].items()))

    for r in process_map(_detect_pose, [(seq, p, layout, methods) for p in poses], jobs):
        done(r)
    for p in moved_poses(res):
        res[p] = (*res[p][:3], {m: Found(None, None, "camera moved during the sequence") for m in res[p][3]})
        if log:
            log(f"{p}: skipped: frames do not align: the camera moved during the sequence (beyond the "
                "display's maps over the dataset)")
    out = {}
    for m in methods:
        boards, weights = [], []
        for p, f in zip(poses, pooled(m, layout, [res[p][3][m] for p in poses])):  # psf-sim: the dataset's coma
            _, rfile, cbfile, _ = res[p]
            boards.append((rfile if m.startswith("rotstar") else cbfile, f.corners))
            weights.append(f.weights)
        path = os.path.join(outdir, (folders or {}).get(m, m), f"{side}.vnl")
        os.makedirs(os.path.dirname(path), exist_ok=True)
        with atomic_write(path) as f:
            write_corners(f, boards, weights if m == "rotstar-weighted" else None)
        out[m] = path
    return out


def split_interleaved(vnl: str, path_a: str, path_b: str) -> tuple[int, int]:
    """Boards of a corners.vnl alternately into two files (header copied); (boards in A, boards in B)

    SYNOPSIS

        >>> import os, tempfile
        >>> d = tempfile.mkdtemp(); src = os.path.join(d, "c.vnl")
        >>> _ = open(src, "w").write("# filename x y level\\n" + "".join(
        ...     f"s/p{k}/a.png {k} {k} 1\\ns/p{k}/a.png {k} {k} 1\\n" for k in range(5)) + "s/p5/a.png - - -\\n")
        >>> split_interleaved(src, os.path.join(d, "A.vnl"), os.path.join(d, "B.vnl"))
        (3, 2)
        >>> open(os.path.join(d, "B.vnl")).read().splitlines()[:2]
        ['# filename x y level', 's/p1/a.png 1 1 1']
    """
    names = read_vnl_names(vnl)
    with open(vnl, encoding="ascii") as f:
        lines = f.readlines()
    rows = collections.Counter(line.split()[0] for line in lines if line.split() and not line.startswith("#"))
    board = {n for n in names if rows[n] > 1}
    rank = {n: i % 2 for i, n in enumerate(n for n in names if n in board)}
    header = [line for line in lines if line.startswith("#")]
    for side, path in enumerate((path_a, path_b)):
        os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
        with atomic_write(path) as f:
            f.writelines(header)
            f.writelines(line for line in lines if not line.startswith("#") and line.split()
                         and rank.get(line.split()[0]) == side)
    return sum(1 for r in rank.values() if r == 0), sum(1 for r in rank.values() if r == 1)

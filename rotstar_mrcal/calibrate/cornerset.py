"""A corner set on disk: its corners.vnl, the dataset it came from, the imager size, the truth

SYNOPSIS

    from rotstar_mrcal.calibrate.cornerset import load_corner_set
    cs = load_corner_set("seq/corners.vnl")
    cs.layout.nx, cs.corners.shape, cs.imagersize    # 14, (N, 9, 14, 2), (1280, 800)
    cs.seq, cs.truth                                 # 'seq', a TrueCamera or None

How the pieces are found, in order:

    dataset   the folder two levels above the first image named in the vnl
              (seq/<pose>/<file>), resolved as mrcal resolves it: as written,
              else relative to the vnl's folder; it must hold pattern.json
    layout    `layout` if given (read once by the caller), else `pattern`
              if given, else <dataset>/pattern.json, else
              pattern.json next to the vnl
    imager    `imagersize` if given, else the first image of the vnl that can
              be read, else the dataset's truth.cameramodel (simulated data)
    truth     <dataset>/truth.json and truth.cameramodel (rotstar-simulate)

Only boards mrcal uses are kept (images with a `- - -` row are dropped, and
so are boards with too few corners for mrcal: vnl.mrcal_keeps, for files
that another tool wrote); names are the pose folder names
(seq/<pose>/<file> -> <pose>).
"""

from __future__ import annotations

import dataclasses
import os

import cv2
import mrcal
import numpy as np

from rotstar_mrcal import dataset
from rotstar_mrcal.calibrate.command import resolve_image
from rotstar_mrcal.pattern.layout import Layout
from rotstar_mrcal.vnl import CornersFileError, mrcal_keeps, open_corners, read_corners


@dataclasses.dataclass
class TestSet:
    """The corners of one pose group, to test a model on"""

    corners: np.ndarray  # (N, ny, nx, 2), NaN = missing
    names: list[str]  # pose name of each board
    spacing: float  # board corner spacing, metres


@dataclasses.dataclass
class TrueCamera:
    """The true camera and the true pose of each named pose (simulated data)"""

    model: mrcal.cameramodel
    rt_cam_board: dict  # pose name -> (6,)


class SourceError(ValueError):
    """A corner set whose dataset, pattern or imager size cannot be found"""


@dataclasses.dataclass
class CornerSet:
    vnl: str
    layout: Layout
    files: list[str]  # image names as written in the vnl (boards only)
    corners: np.ndarray  # (N, ny, nx, 2)
    imagersize: tuple[int, int]
    weights: bool  # the vnl has a weight column
    seq: str | None
    truth: TrueCamera | None

    @property
    def names(self) -> list[str]:
        return [pose_name(f) for f in self.files]

    def test_set(self) -> TestSet:
        return TestSet(self.corners, self.names, self.layout.spacing_m)


def pose_name(path: str) -> str:
    """seq/<pose>/<file> -> <pose>"""
    return os.path.basename(os.path.dirname(str(path))) or str(path)


def read_vnl_names(vnl: str) -> list[str]:
    """Image names of a corners.vnl in order of first appearance"""
    out, seen = [], set()
    with open_corners(vnl) as f:
        for line in f:
            s = line.split()
            if s and not s[0].startswith("#") and s[0] not in seen:
                seen.add(s[0])
                out.append(s[0])
    return out


def vnl_has_weights(path: str) -> bool:
    """Does a corners.vnl say (in its `# filename x y ...` header) that column 4 is a weight?"""
    with open_corners(path) as f:
        for line in f:
            s = line.strip()
            if not s:
                continue
            if not s.startswith("#"):
                return False
            fields = s.lstrip("#").split()
            if fields[:3] == ["filename", "x", "y"]:
                return len(fields) > 3 and fields[3] == "weight"
    return False


def find_dataset(vnl: str, names=None) -> str | None:
    names = read_vnl_names(vnl) if names is None else names
    for n in names[:1]:
        seq = os.path.dirname(os.path.dirname(resolve_image(n, vnl)))
        if os.path.exists(os.path.join(seq, "pattern.json")):
            return seq
    return None


def imager_size(files, vnl: str, seq: str | None) -> tuple[int, int] | None:
    for f in files[:3]:
        p = resolve_image(f, vnl)
        if os.path.exists(p):
            img = cv2.imread(p, cv2.IMREAD_UNCHANGED)
            if img is not None:
                return int(img.shape[1]), int(img.shape[0])
    if seq and os.path.exists(os.path.join(seq, "truth.cameramodel")):
        W, H = mrcal.cameramodel(os.path.join(seq, "truth.cameramodel")).imagersize()
        return int(W), int(H)
    return None


def load_corner_set(vnl: str, pattern: str | None = None, imagersize=None, truth: bool = True,
                    layout: Layout | None = None) -> CornerSet:
    """Read a corners.vnl and find what belongs to it (see the module doc); layout: the pattern's, already read"""
    if not os.path.exists(vnl):
        raise SourceError(f"{vnl}: no such file")
    try:
        names = read_vnl_names(vnl)
    except CornersFileError as e:
        raise SourceError(str(e)) from None
    if not names:
        raise SourceError(f"{vnl}: no images in it")
    seq = find_dataset(vnl, names)
    here = os.path.dirname(os.path.abspath(vnl))
    source = pattern or seq or (here if os.path.exists(os.path.join(here, "pattern.json")) else None)
    if layout is None and source is None:
        raise SourceError(f"{vnl}: cannot find the pattern.json of its dataset (give --pattern)")
    try:
        layout = layout or dataset.read_pattern(source)[1]
    except dataset.DatasetError as e:
        raise SourceError(str(e)) from None
    with open_corners(vnl) as f:
        try:
            boards = read_corners(f, layout.nx, layout.ny)
        except ValueError as e:
            raise SourceError(f"{vnl}: {e}") from None
    files = [n for n in names if mrcal_keeps(boards.get(n))]
    if not files:
        raise SourceError(f"{vnl}: no boards in it")
    corners = np.stack([boards[n] for n in files])
    seen = imager_size(files, vnl, seq)
    size = tuple(int(v) for v in imagersize) if imagersize is not None else seen
    if imagersize is not None and seen is not None and seen != size:
        raise SourceError(f"the imager size given, {size[0]}x{size[1]}, is not the size of the images of {vnl} "
                          f"({seen[0]}x{seen[1]}, e.g. {files[0]}): give --imagersize {seen[0]} {seen[1]} or none")
    if size is None:
        raise SourceError(f"{vnl}: cannot read its images for the imager size (give --imagersize W H)")
    t = None
    if truth and seq and os.path.exists(os.path.join(seq, "truth.json")):
        from rotstar_mrcal.simulate.dataset import load_truth  # here: its import costs 0.2 s (python -X importtime)

        tr = load_truth(seq)
        t = TrueCamera(tr.model, tr.rt_cam_board)
    return CornerSet(vnl, layout, files, corners, size, vnl_has_weights(vnl), seq, t)


def load_model(path: str, need_inputs: bool = False):
    """mrcal.cameramodel(path), or a SourceError naming the file and the reason in one line"""
    if not os.path.exists(path):
        raise SourceError(f"{path}: no such file")
    try:
        m = mrcal.cameramodel(path)
    except Exception:  # noqa: BLE001 mrcal raises a plain Exception listing every parser's complaint
        raise SourceError(f"{path}: not a camera model mrcal can parse") from None
    if need_inputs and not m.optimization_inputs():
        raise SourceError(f"{path}: has no optimization_inputs (needed for the uncertainty); "
                          "use a model written by mrcal-calibrate-cameras")
    return m

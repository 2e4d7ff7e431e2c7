"""A recorded dataset: seq/pattern.json and one folder of frames per pose

SYNOPSIS

    >>> import tempfile, numpy as np
    >>> from rotstar_mrcal.pattern.layout import make_layout
    >>> from rotstar_mrcal import dataset
    >>> seq = tempfile.mkdtemp()
    >>> layout = make_layout(screen=(800, 600), pitch=100, band=24)
    >>> _ = dataset.write_pattern(seq, layout)
    >>> frames = {f["file"]: np.zeros((40, 60), np.uint16) for f in layout.frames()}
    >>> _ = dataset.write_pose(seq, "pose000", frames)
    >>> ds = dataset.open_dataset(seq)           # read once, passed on (Dataset)
    >>> ds.poses                                 # per camera; one camera is a rig of one
    {0: ['pose000']}
    >>> pose = ds.load("pose000")
    >>> pose.rotstar.shape, pose.identity.shape, pose.checkerboard.shape, pose.full_scale
    ((8, 40, 60), (10, 40, 60), (40, 60), 65535.0)

Layout on disk:

    seq/pattern.json              a copy of what rotstar-pattern wrote
    seq/<pose>/<file>             one image per entry of pattern.json "frames",
                                  with the same file names; 8- or 16-bit
                                  single-channel PNG

Pose folders are the sub-folders that hold at least one of the frame files;
they are processed in sorted order. Several cameras: seq/poseNNN/camera-K/<file>
(read_rig; doc/dataset.md). Problems are raised as DatasetError with
a one-line message that names the file and the reason.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import stat
import warnings

import cv2
import numpy as np

from rotstar_mrcal.atomic import atomic_folder, atomic_path
from rotstar_mrcal.pattern.layout import SPARE_KINDS, Layout, layout_from_dict, unspared


class DatasetError(Exception):
    """Bad input: the message is one line naming the file and the reason"""


@dataclasses.dataclass
class Pose:
    """The frames of one pose, as recorded"""

    name: str
    folder: str
    rotstar: np.ndarray  # (nframes, H, W) float32, in recorded units
    checkerboard: np.ndarray | None  # (H, W) float32 or None
    full_scale: float  # 255 or 65535
    files: list[str]  # paths of the rotstar frames, in order
    identity: np.ndarray | None = None  # (nidentity, H, W) float32, the identity frames, or None
    phase: np.ndarray | None = None  # (2, 4, H, W) float32: the phase shifts along x, then y, steps 0..3; or None
    star: np.ndarray | None = None  # (H, W) float32, the star frame, or None
    missing: tuple[str, ...] = ()  # the identity frame not recorded (its file name; all NaN in identity), or ()

    @property
    def first_file(self) -> str:
        return self.files[0]


def pattern_file(path: str) -> str:
    """The pattern.json of a dataset folder, or path itself"""
    return os.path.join(path, "pattern.json") if os.path.isdir(path) else path


def read_pattern(path: str) -> tuple[dict, Layout]:
    """Read pattern.json from a dataset folder (or the file itself)"""
    if not os.path.exists(path):
        raise DatasetError(f"{path}: no such {'file' if path.endswith('.json') else 'folder'}")
    fn = pattern_file(path)
    if not os.path.exists(fn):
        raise DatasetError(f"{fn}: no pattern.json (copy the one rotstar-pattern wrote into the dataset folder)")
    _check_regular(fn)
    try:
        with open(fn) as f:
            d = json.load(f)
    except (OSError, json.JSONDecodeError) as e:
        raise DatasetError(f"{fn}: cannot read pattern.json ({e})") from None
    try:
        return d, layout_from_dict(d)
    except ValueError as e:
        raise DatasetError(f"{fn}: {e}") from None


def _check_regular(fn: str) -> None:
    """DatasetError unless fn is a regular file (a FIFO or a device would block the reader)"""
    try:
        mode = os.stat(fn).st_mode
    except OSError as e:
        raise DatasetError(f"{fn}: {e.strerror}") from None
    if not stat.S_ISREG(mode):
        what = "a folder" if stat.S_ISDIR(mode) else "a FIFO" if stat.S_ISFIFO(mode) else "a special file"
        raise DatasetError(f"{fn}: {what}, not a regular file")


def write_pattern(seq: str, layout: Layout) -> str:
    os.makedirs(seq, exist_ok=True)
    fn = os.path.join(seq, "pattern.json")
    with open(fn, "w") as f:
        f.write(layout.to_json())
    return fn


def list_poses(seq: str, frames: list[dict] | None = None) -> list[str]:
    """Sorted names of the pose folders in seq"""
    if frames is None:
        frames = read_pattern(seq)[0]["frames"]
    names = {f["file"] for f in frames}
    try:
        entries = sorted(os.listdir(seq))
    except OSError as e:
        raise DatasetError(f"{seq}: cannot list the dataset folder ({e.strerror})") from None
    return [
        e
        for e in entries
        if os.path.isdir(os.path.join(seq, e)) and names & set(os.listdir(os.path.join(seq, e)))
    ]


IMAGE_EXTENSIONS = (".png", ".pgm", ".tif", ".tiff", ".jpg", ".jpeg", ".bmp")


def unmatched_folders(seq: str, frames: list[dict]) -> dict[str, str]:
    """{folder name: why it is not a pose} for the sub-folders that hold images, none named as in pattern.json

    These are pose folders whose frames were renamed (frame_00.png ...) or a
    different pattern's recording: list_poses leaves them out, the tools say so.
    """
    names = [f["file"] for f in frames]
    out = {}
    for e in sorted(os.listdir(seq)):
        folder = os.path.join(seq, e)
        if not os.path.isdir(folder) or e.startswith("."):
            continue
        try:
            files = sorted(os.listdir(folder))
        except OSError:
            continue
        images = [f for f in files if f.lower().endswith(IMAGE_EXTENSIONS)]
        if images and not set(names) & set(files):
            more = f" and {len(images) - 2} more" if len(images) > 2 else ""
            out[e] = (f"{folder}: no frame named as in pattern.json ({names[0]} ... {names[-1]} missing); "
                      f"holds {', '.join(images[:2])}{more}")
    return out


@contextlib.contextmanager
def _quiet_stderr():
    """Silence the C-level stderr (file descriptor 2) for the duration"""
    try:
        saved = os.dup(2)
    except OSError:
        yield
        return
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
            yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


PNG16_PARAMS = [cv2.IMWRITE_PNG_COMPRESSION, 0] + (
    [cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_NONE] if hasattr(cv2, "IMWRITE_PNG_FILTER") else [])
"""How a 16-bit frame is written: deflate's stored blocks, no row filter. A camera's 16-bit frame holds noise
in its low bits, so zlib saves little: measured on a 1280x800 D435 frame (OpenCV 5.0), OpenCV's default gives
1.75 MB, 42 CPU-ms to encode and 20 to decode; this gives 2.05 MB (17 % more), 8 and 7. Reading the frames is
a third of a pose's detection. 8-bit frames keep the default (half the size of stored ones)."""
MAX_FRAME_PIXELS = 50_000_000  # a frame larger than this (50 Mpx) is a corrupt or foreign file, not a camera's


def header_size(fn: str) -> tuple[int, int] | None:
    """(width, height) an image's header claims, without decoding it; None when the header is not readable

    PNG's IHDR is read directly; the other formats the reader accepts (PGM,
    TIFF, JPEG, BMP) through Pillow, which reads only their headers here.
    DatasetError when the header claims more pixels than Pillow will open.

    >>> import tempfile
    >>> fn = os.path.join(tempfile.mkdtemp(), "a.png"); _ = cv2.imwrite(fn, np.zeros((8, 12), np.uint8))
    >>> header_size(fn)
    (12, 8)
    """
    try:
        with open(fn, "rb") as f:
            head = f.read(24)
    except OSError:
        return None
    if len(head) >= 24 and head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR":
        return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")
    from PIL import Image  # matplotlib's dependency; 0.13 s to import (-X importtime), only for non-PNG frames

    try:
        with warnings.catch_warnings():  # Pillow warns of large images on stderr: check_frame_size judges
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(fn) as im:
                return im.size
    except Image.DecompressionBombError:
        raise DatasetError(f"{fn}: its header claims an absurd frame size (more than "
                           f"{MAX_FRAME_PIXELS // 1_000_000} Mpx): a corrupt or foreign file") from None
    except (OSError, ValueError, SyntaxError):
        return None


def check_frame_size(fn: str, size: tuple[int, int] | None) -> None:
    """DatasetError unless the (width, height) an image's header claims is a plausible frame's

    >>> check_frame_size("a.png", (1280, 800))
    >>> check_frame_size("a.png", (60000, 60000))
    Traceback (most recent call last):
    ...
    rotstar_mrcal.dataset.DatasetError: a.png: its header claims a 60000x60000 frame (3600 Mpx, more than 50): a corrupt or foreign file
    """
    if size is None:
        return
    w, h = size
    if w < 1 or h < 1 or w * h > MAX_FRAME_PIXELS:
        raise DatasetError(f"{fn}: its header claims a {w}x{h} frame ({w * h / 1e6:.0f} Mpx, more than "
                           f"{MAX_FRAME_PIXELS // 1_000_000}): a corrupt or foreign file")


def read_image(fn: str) -> tuple[np.ndarray, float]:
    """A grayscale 8- or 16-bit PNG as float32, and its full scale; its size is checked from its header first"""
    if not os.path.exists(fn):
        raise DatasetError(f"{fn}: missing frame")
    _check_regular(fn)
    check_frame_size(fn, header_size(fn))
    try:
        with _quiet_stderr():  # libpng prints its own error lines; ours is the one that counts
            img = cv2.imread(fn, cv2.IMREAD_UNCHANGED)
    except cv2.error:
        img = None
    if img is None:
        raise DatasetError(f"{fn}: not a readable image (corrupt or not PNG)")
    if img.ndim == 3:
        if img.shape[2] == 4:
            img = img[..., :3]
        if not (np.array_equal(img[..., 0], img[..., 1]) and np.array_equal(img[..., 0], img[..., 2])):
            raise DatasetError(f"{fn}: colour image; frames must be single-channel grayscale")
        img = img[..., 0]
    if img.dtype == np.uint8:
        return img.astype(np.float32), 255.0
    if img.dtype == np.uint16:
        return img.astype(np.float32), 65535.0
    raise DatasetError(f"{fn}: pixel type {img.dtype}; expected 8- or 16-bit grayscale")


MAX_MISSING_IDENTITY = SPARE_KINDS["identity"]
"""Identity frames a pose may lack: IdentityCode.decode reads every element from the others (one erasure;
a short capture may miss one identity frame's display). The rotating-star frames are all needed."""


def identity_stack(images, files: list[str], shape: tuple[int, int] | None = None) -> tuple[np.ndarray, tuple[str, ...]]:
    """((len(files), H, W) float32 of images[f] for f in files, all NaN where images lacks f; the f it lacks)

    images: {file name: (H, W) image}, e.g. a pose folder's frames or a
    capture's segmented averages; shape: (H, W) when images may hold none
    of files. How a pose lacking an identity frame reaches the detector
    (detect.identity reads the code from the other frames).

    >>> img = np.ones((2, 3))
    >>> stack, missing = identity_stack({"identity_00.png": img, "identity_02.png": 2 * img},
    ...                                 ["identity_00.png", "identity_01.png", "identity_02.png"])
    >>> stack.shape, stack.dtype, stack[:, 0, 0].tolist(), missing
    ((3, 2, 3), dtype('float32'), [1.0, nan, 2.0], ('identity_01.png',))
    """
    have = [images[f] for f in files if f in images]
    if shape is None:
        if not have:
            raise ValueError(f"none of {len(files)} identity frames and no frame size")
        shape = np.shape(have[0])
    stack = np.full((len(files), *shape), np.nan, np.float32)
    for k, f in enumerate(files):
        if f in images:
            stack[k] = images[f]
    return stack, tuple(f for f in files if f not in images)


def load_pose(seq: str, pose: str, layout_or_frames) -> Pose:
    """Read one pose's frames; DatasetError on missing, unreadable or mismatched files

    A pose lacking one identity frame (MAX_MISSING_IDENTITY) is read: that
    frame all NaN in Pose.identity, its name in Pose.missing. Lacking more,
    or any rotating-star frame: DatasetError naming the first one missing.
    """
    frames = layout_or_frames.frames() if isinstance(layout_or_frames, Layout) else layout_or_frames
    folder = os.path.join(seq, pose)
    expected = {f["file"] for f in frames}
    present = {e for e in os.listdir(folder) if e.lower().endswith(".png")}
    extra = sorted(present - expected)
    if extra:
        raise DatasetError(f"{os.path.join(folder, extra[0])}: extra frame not in pattern.json")
    rot_files = [os.path.join(folder, f["file"]) for f in frames if f["kind"] == "rotstar"]
    id_files = [os.path.join(folder, f["file"]) for f in frames if f["kind"] == "identity"]
    lacking = [fn for fn in id_files if not os.path.exists(fn)]
    read = [fn for fn in id_files if len(lacking) > MAX_MISSING_IDENTITY or fn not in lacking]
    check_sizes(rot_files + read)
    imgs, scales = [], set()
    for fn in rot_files + read:  # a missing frame beyond what may be: "<file>: missing frame"
        img, fs = read_image(fn)
        imgs.append(img)
        scales.add(fs)
    shapes = [im.shape for im in imgs]
    if len(set(shapes)) > 1:
        common = max(set(shapes), key=shapes.count)  # the size most frames have
        odd = next(k for k, s in enumerate(shapes) if s != common)
        raise DatasetError(
            f"{(rot_files + read)[odd]}: frame size {shapes[odd][1]}x{shapes[odd][0]} differs from the others "
            f"({common[1]}x{common[0]})"
        )
    if len(scales) > 1:
        raise DatasetError(f"{folder}: frames mix 8- and 16-bit PNGs")
    checker = _optional(folder, frames, "checkerboard", imgs[0].shape)
    star = _optional(folder, frames, "star", imgs[0].shape)
    phase = None
    ph = [f for f in frames if f["kind"] == "phase"]
    if ph:
        order = sorted(ph, key=lambda f: (f["axis"], f["step"]))
        stack = []
        for f in order:
            fn = os.path.join(folder, f["file"])
            img, fs = read_image(fn)
            if img.shape != imgs[0].shape or fs not in scales:
                raise DatasetError(f"{fn}: frame size or bit depth differs from the rotating-star frames")
            stack.append(img)
        phase = np.stack(stack).reshape(2, len(stack) // 2, *imgs[0].shape)
    n = len(rot_files)
    identity, missing = identity_stack(dict(zip(read, imgs[n:])), id_files, imgs[0].shape)
    return Pose(
        name=pose,
        folder=folder,
        rotstar=np.stack(imgs[:n]),
        checkerboard=checker,
        full_scale=scales.pop(),
        files=rot_files,
        identity=identity if id_files else None,
        phase=phase,
        star=star,
        missing=tuple(os.path.basename(fn) for fn in missing),
    )


def check_sizes(files: list[str]) -> None:
    """DatasetError, naming the file, when a frame's header claims an absurd size or one the others do not

    Read from the headers before any frame is decoded: a corrupt header
    never reaches the decoder, and the odd frame is named whatever it holds.

    >>> import tempfile
    >>> d = tempfile.mkdtemp(); fns = [os.path.join(d, f"{k}.png") for k in range(3)]
    >>> for fn, w in zip(fns, (12, 12, 10)):
    ...     _ = cv2.imwrite(fn, np.zeros((8, w), np.uint8))
    >>> check_sizes(fns[:2])
    >>> check_sizes(fns)
    Traceback (most recent call last):
    ...
    rotstar_mrcal.dataset.DatasetError: ...2.png: frame size 10x8 differs from the others (12x8)
    """
    sizes = {}
    for fn in files:
        if os.path.isfile(fn):
            sizes[fn] = header_size(fn)
            check_frame_size(fn, sizes[fn])
    known = [s for s in sizes.values() if s is not None]
    if len(set(known)) > 1:
        common = max(set(known), key=known.count)  # the size most frames have
        odd = next(fn for fn, s in sizes.items() if s is not None and s != common)
        raise DatasetError(f"{odd}: frame size {sizes[odd][0]}x{sizes[odd][1]} differs from the others "
                           f"({common[0]}x{common[1]})")


def _optional(folder: str, frames: list[dict], kind: str, shape) -> np.ndarray | None:
    """The one frame of `kind` (checkerboard, star) when pattern.json lists it and the pose holds it, else None"""
    f = [f for f in frames if f["kind"] == kind]
    if not f:
        return None
    fn = os.path.join(folder, f[0]["file"])
    if not os.path.exists(fn):
        return None
    img, _ = read_image(fn)
    if img.shape != shape:
        raise DatasetError(f"{fn}: frame size differs from the rotating-star frames")
    return img


def write_pose(seq: str, pose: str, images: dict[str, np.ndarray]) -> str:
    """Write one pose folder: {file name: uint8 or uint16 image}, whole or not at all

    A new folder is written under a temporary name and renamed when complete
    (atomic.atomic_folder): an interrupted run leaves no pose with some of its
    frames. Into a folder that exists, each image is written through
    atomic.atomic_path: no half-written frame. Encoded in memory and written
    by Python, so that a full disk is an OSError with its reason (errno, the
    file name). 16-bit PNGs are stored uncompressed (PNG16_PARAMS).
    """
    folder = os.path.join(seq, pose)
    if not os.path.isdir(folder):
        try:
            with atomic_folder(folder) as tmp:
                write_pose(os.path.dirname(tmp), os.path.basename(tmp), images)
        except OSError as e:  # name the file in the pose folder, not in the temporary one
            if e.errno is None or not e.filename:
                raise
            raise OSError(e.errno, e.strerror, os.path.join(folder, os.path.basename(e.filename))) from None
        return folder
    for name, img in images.items():
        if img.dtype not in (np.uint8, np.uint16):
            raise ValueError(f"{name}: write uint8 or uint16 images, not {img.dtype}")
        fn = os.path.join(folder, name)
        ext = os.path.splitext(name)[1] or ".png"
        ok, data = cv2.imencode(ext, img, PNG16_PARAMS if ext == ".png" and img.dtype == np.uint16 else [])
        if not ok:
            raise OSError(f"{fn}: cannot encode the image")
        try:
            with atomic_path(fn) as tmp, open(tmp, "wb") as f:
                f.write(data.tobytes())
        except OSError as e:
            raise OSError(e.errno, e.strerror, fn) from None
    return folder


# ---- several cameras: seq/poseNNN/camera-K/<file> ---------------------------------------
CAMERA_PREFIX = "camera-"


def camera_folder(k: int) -> str:
    """The folder name of camera k inside a pose folder

    >>> camera_folder(1)
    'camera-1'
    """
    return f"{CAMERA_PREFIX}{int(k)}"


def camera_index(name: str) -> int | None:
    """k of a folder named camera-k (k digits without a sign), else None

    >>> camera_index("camera-2"), camera_index("camera-x"), camera_index("pose000")
    (2, None, None)
    """
    tail = name[len(CAMERA_PREFIX):] if name.startswith(CAMERA_PREFIX) else ""
    return int(tail) if tail.isdigit() else None


def is_multi_camera(seq: str) -> bool:
    """Is seq a multi-camera dataset: does some sub-folder hold camera-K folders?"""
    try:
        entries = sorted(os.listdir(seq))
    except OSError:
        return False
    for e in entries:
        folder = os.path.join(seq, e)
        if os.path.isdir(folder) and not e.startswith("."):
            try:
                if any(camera_index(c) is not None and os.path.isdir(os.path.join(folder, c))
                       for c in os.listdir(folder)):
                    return True
            except OSError:
                continue
    return False


@dataclasses.dataclass
class Rig:
    """The layout of a multi-camera dataset (read_rig): which camera saw which pose

    poses[k] lists camera k's pose folders relative to seq,
    'poseNNN/camera-k', each readable by load_pose(seq, name, frames) as a
    one-camera pose folder; sizes[k] is camera k's image size (width,
    height); absent[k] names the poses in which camera k has no folder (it
    did not see the board there).
    """

    seq: str
    cameras: list[int]  # 0, 1, ... (every index up to the largest present)
    pose_names: list[str]  # poseNNN, sorted
    poses: dict[int, list[str]]
    sizes: dict[int, tuple[int, int]]
    absent: dict[int, list[str]]


def image_size(fn: str) -> tuple[int, int] | None:
    """(width, height) of an image from its header (PNG) or by reading it; None if unreadable

    >>> import tempfile
    >>> fn = os.path.join(tempfile.mkdtemp(), "a.png"); _ = cv2.imwrite(fn, np.zeros((8, 12), np.uint8))
    >>> image_size(fn)
    (12, 8)
    """
    size = header_size(fn)
    if size is not None:
        return size
    with _quiet_stderr():
        try:
            img = cv2.imread(fn, cv2.IMREAD_UNCHANGED)
        except cv2.error:
            img = None
    return None if img is None else (img.shape[1], img.shape[0])


def as_read(files: set[str], frames: list[dict]) -> set[str]:
    """The file names of a pose folder, with those load_pose does without added (pattern.layout.SPARE_KINDS:
    the checkerboard and star frames, one identity frame)

    >>> frames = [{"file": "rotstar_00.png", "kind": "rotstar"}, {"file": "checkerboard.png", "kind": "checkerboard"}
    ...           ] + [{"file": f"identity_{k:02d}.png", "kind": "identity"} for k in range(3)]
    >>> sorted(as_read({"rotstar_00.png", "identity_00.png", "identity_02.png"}, frames))
    ['checkerboard.png', 'identity_00.png', 'identity_01.png', 'identity_02.png', 'rotstar_00.png']
    >>> sorted(as_read({"rotstar_00.png", "identity_00.png"}, frames))
    ['checkerboard.png', 'identity_00.png', 'rotstar_00.png']
    """
    missing = [f["file"] for f in frames if f["file"] not in files]
    return set(files) | (set(missing) - set(unspared(frames, missing)))


def read_rig(seq: str, frames: list[dict] | None = None) -> Rig:
    """Read the layout of a multi-camera dataset; DatasetError (one line, naming the files) when it is inconsistent

    SYNOPSIS

        >>> import tempfile
        >>> from rotstar_mrcal.pattern.layout import make_layout
        >>> seq = tempfile.mkdtemp()
        >>> layout = make_layout(screen=(800, 600), pitch=100, band=24)
        >>> _ = write_pattern(seq, layout)
        >>> img = lambda w, h: {f["file"]: np.zeros((h, w), np.uint8) for f in layout.frames()}
        >>> for p in ("pose000", "pose001"):
        ...     _ = write_pose(seq, f"{p}/camera-0", img(60, 40))
        >>> _ = write_pose(seq, "pose001/camera-1", img(48, 30))     # camera 1 missed pose000's board
        >>> rig = read_rig(seq)
        >>> rig.cameras, rig.poses[1], rig.sizes, rig.absent
        ([0, 1], ['pose001/camera-1'], {0: (60, 40), 1: (48, 30)}, {0: [], 1: ['pose000']})

    A pose folder is poseNNN (digits: mrcal matches the cameras' images of one
    instant by that number) holding camera-K folders; a camera folder is read
    exactly as a one-camera pose folder (load_pose). A camera folder missing
    in a pose is that camera not seeing the board there, not an error. Errors:
    a pose folder not named poseNNN or holding no camera folder, the camera
    folders of one pose holding different frames (differing frame counts;
    a camera lacking what load_pose does without, as_read, is no difference),
    a camera folder whose number has leading zeros (camera-01: mrcal's
    file names and every tool name it camera-1),
    one camera's images differing in size between poses, a camera with no
    pose at all.
    """
    if frames is None:
        frames = read_pattern(seq)[0]["frames"]
    names = {f["file"] for f in frames}
    first = next(f["file"] for f in frames if f["kind"] == "rotstar")
    try:
        entries = sorted(e for e in os.listdir(seq) if os.path.isdir(os.path.join(seq, e)) and not e.startswith("."))
    except OSError as e:
        raise DatasetError(f"{seq}: cannot list the dataset folder ({e.strerror})") from None
    held: dict[str, dict[int, set]] = {}
    for e in entries:
        folder = os.path.join(seq, e)
        cams = {camera_index(c): c for c in os.listdir(folder)
                if camera_index(c) is not None and os.path.isdir(os.path.join(folder, c))}
        odd = sorted(c for c in os.listdir(folder) if camera_index(c) is not None and c != camera_folder(camera_index(c)))
        if odd:
            raise DatasetError(f"{os.path.join(folder, odd[0])}: a camera folder is named {CAMERA_PREFIX}K without "
                               f"leading zeros; rename it {camera_folder(camera_index(odd[0]))}")
        if not cams:
            if names & set(os.listdir(folder)):
                raise DatasetError(f"{folder}: frames directly in a pose folder of a multi-camera dataset; "
                                   "put them in camera-0/ (one folder per camera)")
            continue
        if not (e.startswith("pose") and e[4:].isdigit()):
            raise DatasetError(f"{folder}: a multi-camera pose folder must be named poseNNN (digits): mrcal matches "
                               "the cameras' images of one instant by that number")
        extra = sorted(set(os.listdir(folder)) - set(cams.values()))
        if extra:
            raise DatasetError(f"{os.path.join(folder, extra[0])}: not a camera-K folder; a multi-camera pose folder "
                               "holds only camera-0/, camera-1/, ...")
        held[e] = {k: {f for f in os.listdir(os.path.join(folder, c)) if f.lower().endswith(IMAGE_EXTENSIONS)}
                   for k, c in sorted(cams.items())}
    if not held:
        raise DatasetError(f"{seq}: no pose folder holds camera-K folders")
    numbers = {}
    for p in held:
        numbers.setdefault(int(p[4:]), []).append(p)
    dup = next((v for v in numbers.values() if len(v) > 1), None)
    if dup:
        raise DatasetError(f"{seq}: pose folders {dup[0]} and {dup[1]} have the same number; mrcal would take them "
                           "for one instant")
    cameras = list(range(max(k for h in held.values() for k in h) + 1))
    for p, h in held.items():  # the cameras of one pose hold the same frames (or lack only what load_pose may)
        h = {k: as_read(files, frames) for k, files in h.items()}
        ks = sorted(h)
        for k in ks[1:]:
            if h[k] != h[ks[0]]:
                diff = sorted(h[k] ^ h[ks[0]])
                has, lacks = (ks[0], k) if diff[0] in h[ks[0]] else (k, ks[0])
                raise DatasetError(
                    f"{os.path.join(seq, p, camera_folder(lacks), diff[0])}: missing, though "
                    f"{os.path.join(seq, p, camera_folder(has))} has it ({len(h[lacks])} vs {len(h[has])} frames): "
                    "the cameras of a pose must hold the same frames")
    poses = {k: [f"{p}/{camera_folder(k)}" for p in held if k in held[p]] for k in cameras}
    absent = {k: [p for p in held if k not in held[p]] for k in cameras}
    sizes = {}
    for k in cameras:
        if not poses[k]:
            raise DatasetError(f"{seq}: no pose holds a {camera_folder(k)} folder, though a higher-numbered camera "
                               "exists; cameras are numbered 0, 1, ... without gaps")
        seen = {}
        for name in poses[k]:
            fn = os.path.join(seq, name, first)
            try:
                s = image_size(fn)
                check_frame_size(fn, s)
            except DatasetError:  # an absurd header: not the camera's size; load_pose skips that pose, naming it
                s = None
            if s is not None:
                seen.setdefault(s, fn)
        if len(seen) > 1:
            (s0, f0), (s1, f1) = list(seen.items())[:2]
            raise DatasetError(f"{f1}: image size {s1[0]}x{s1[1]} differs from {f0} ({s0[0]}x{s0[1]}): every image "
                               f"of one camera ({camera_folder(k)}) must have the same size")
        sizes[k] = next(iter(seen)) if seen else None
    return Rig(seq, cameras, sorted(held), poses, sizes, absent)


# ---- a dataset opened once ---------------------------------------------------------------
@dataclasses.dataclass
class Dataset:
    """A dataset opened once (open_dataset), passed on to every level that reads it

    SYNOPSIS

        >>> import tempfile
        >>> from rotstar_mrcal.pattern.layout import make_layout
        >>> seq = tempfile.mkdtemp()
        >>> _ = write_pattern(seq, make_layout(screen=(800, 600), pitch=100, band=24))
        >>> ds = open_dataset(seq)
        >>> _ = write_pose(seq, "pose000", {f["file"]: np.zeros((40, 60), np.uint8) for f in ds.frames})
        >>> ds = open_dataset(seq)
        >>> ds.cameras, ds.poses, ds.sizes, ds.multi_camera
        ([0], {0: ['pose000']}, {0: (60, 40)}, False)
        >>> ds.load("pose000").rotstar.shape
        (8, 40, 60)

    One camera is a rig of one: cameras [0], its pose folders 'poseNNN'; a
    multi-camera dataset (read_rig) has cameras [0, 1, ...] and pose folders
    'poseNNN/camera-K'. Names are relative to path; load(name) reads one
    (load_pose). sizes[k] is camera k's image size (width, height) from the
    first pose's header (None if unreadable); absent[k] the poses in which
    camera k has no folder; unmatched the folders holding images none of
    which is named as in pattern.json (unmatched_folders; one camera only).
    """

    path: str
    pattern: dict
    layout: Layout
    cameras: list[int]
    poses: dict[int, list[str]]
    sizes: dict[int, tuple[int, int] | None]
    absent: dict[int, list[str]]
    unmatched: dict[str, str]
    rig: Rig | None = None  # the multi-camera layout, or None for one camera

    @property
    def frames(self) -> list[dict]:
        return self.pattern["frames"]

    @property
    def first_frame(self) -> str:
        """The first rotating-star frame's file name: mrcal's filename column"""
        return next(f["file"] for f in self.frames if f["kind"] == "rotstar")

    @property
    def multi_camera(self) -> bool:
        return self.rig is not None

    @property
    def pose_names(self) -> list[str]:
        """The pose folders directly in path, sorted ('poseNNN' whatever the cameras)"""
        return self.rig.pose_names if self.rig else self.poses[0]

    def load(self, name: str) -> Pose:
        """One pose folder (a name from poses) read: DatasetError on missing, unreadable or mismatched files"""
        return load_pose(self.path, name, self.frames)

    def only(self, names: list[str]) -> Dataset:
        """The same dataset restricted to the pose folders `names` (of one camera)"""
        return dataclasses.replace(self, poses={k: [p for p in v if p in names] for k, v in self.poses.items()})


def open_dataset(path: str) -> Dataset:
    """Read pattern.json and list the poses (and cameras) of a dataset; DatasetError, one line, when it cannot"""
    pattern, layout = read_pattern(path)
    frames = pattern["frames"]
    if is_multi_camera(path):
        rig = read_rig(path, frames)
        return Dataset(path, pattern, layout, rig.cameras, rig.poses, rig.sizes, rig.absent, {}, rig)
    poses = list_poses(path, frames)
    unmatched = unmatched_folders(path, frames)
    first = next(f["file"] for f in frames if f["kind"] == "rotstar")
    try:
        size = image_size(os.path.join(path, poses[0], first)) if poses else None
    except DatasetError:  # an absurd header: load_pose skips that pose, naming it
        size = None
    return Dataset(path, pattern, layout, [0], {0: poses}, {0: size}, {0: []}, unmatched)

"""The replay backend: a recording made earlier (or by another tool) as a FrameSource

SYNOPSIS

    >>> import numpy as np, tempfile, os
    >>> from rotstar_mrcal.capture.backend_replay import ReplaySource, save_recording
    >>> fn = os.path.join(tempfile.mkdtemp(), "rec.npy")
    >>> save_recording(fn, np.arange(24, dtype=np.uint16).reshape(4, 2, 3), sequence=[5, 6, 8, 9], fps=25)
    >>> src = ReplaySource(fn)
    >>> len(src), src.fps, src.full_scale
    (4, 25.0, 65535.0)
    >>> [f.sequence for f in iter(src.read, None)]
    [5, 6, 8, 9]

Inputs, by what the path is:

    folder           its image files (PNG, TIFF, PGM; 8- or 16-bit) in natural
                     name order (frame2 before frame10)
    NAME.npy         a (T, H, W) uint8 / uint16 array, memory-mapped, with an
                     optional NAME.json beside it: {"sequence": [...],
                     "fps": ..., "t_ns": [...]} (what rotstar-capture --keep-raw
                     writes)
    NAME.raw         raw frames back to back, as `v4l2-ctl --stream-to` writes
                     them: needs size and fourcc (GREY, Y16, Y8I); a dump of
                     both imagers (Y12I, or Y8I as a pair) is split by
                     stereo_raw() into the left and the right recording
    anything else    a video file through OpenCV (8-bit only, and usually
                     lossy: prefer frames or .npy)

Colour images whose channels are equal are read as grey; other colour
images are converted with OpenCV's BGR->grey (and info() says so).
"""

from __future__ import annotations

import json
import os
import re

import cv2
import numpy as np

from rotstar_mrcal.capture.interleaved import BYTES_PER_PIXEL, InterleavedError, unpack
from rotstar_mrcal.capture.source import CaptureError, Frame, FrameSource
from rotstar_mrcal.capture.v4l2 import PIXEL_FORMATS

IMAGE_EXTENSIONS = (".png", ".tif", ".tiff", ".pgm", ".pnm", ".bmp")


def natural_key(name: str):
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", name)]


def _grey(img: np.ndarray, what: str, notes: list) -> np.ndarray:
    if img.ndim == 2:
        return img
    img = img[..., :3]
    if np.array_equal(img[..., 0], img[..., 1]) and np.array_equal(img[..., 0], img[..., 2]):
        return np.ascontiguousarray(img[..., 0])
    if not notes:
        notes.append(f"{what}: colour frames converted to grey (BGR->GRAY)")
    return cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)


def save_recording(fn: str, frames: np.ndarray, sequence=None, fps: float = 0.0, t_ns=None, **extra) -> None:
    """Write a recording as NAME.npy (+ NAME.json with sequence numbers, fps, time stamps)"""
    np.save(fn, np.asarray(frames))
    meta = {"sequence": [int(s) for s in (np.arange(len(frames)) if sequence is None else sequence)],
            "fps": float(fps), **extra}
    if t_ns is not None:
        meta["t_ns"] = [int(t) for t in t_ns]
    with open(os.path.splitext(fn)[0] + ".json", "w") as f:
        json.dump(meta, f)
        f.write("\n")


class ReplaySource(FrameSource):
    name = "replay"

    def __init__(self, path: str, size: tuple[int, int] | None = None, fourcc: str | None = None,
                 fps: float | None = None):
        self.path = path
        self.notes: list[str] = []
        self.pos = 0
        self.sequence = None
        self.t_ns = None
        self._video = None
        meta_fps = 0.0
        if os.path.exists(path) and not (os.path.isdir(path) or os.path.isfile(path)):
            raise CaptureError(f"{path}: not a regular file or folder")
        if os.path.isdir(path):
            files = sorted((f for f in os.listdir(path) if f.lower().endswith(IMAGE_EXTENSIONS)), key=natural_key)
            if not files:
                raise CaptureError(f"{path}: no image files ({', '.join(IMAGE_EXTENSIONS)})")
            self.files = [os.path.join(path, f) for f in files]
            odd = next((f for f in self.files if not os.path.isfile(f)), None)
            if odd:  # a FIFO would block the reader
                raise CaptureError(f"{odd}: not a regular file")
            first = self._image(0)
            self.n, self.dtype = len(files), first.dtype
        elif path.endswith(".npy"):
            try:
                self.array = np.load(path, mmap_mode="r")
            except (OSError, ValueError) as e:
                raise CaptureError(f"{path}: cannot read ({e})") from None
            if self.array.ndim != 3 or self.array.dtype not in (np.uint8, np.uint16):
                raise CaptureError(f"{path}: expected a (T, H, W) uint8/uint16 array, not {self.array.shape} {self.array.dtype}")
            self.n, self.dtype = len(self.array), self.array.dtype
            side = os.path.splitext(path)[0] + ".json"
            if os.path.exists(side):
                with open(side) as f:
                    meta = json.load(f)
                if "sequence" in meta:
                    self.sequence = np.asarray(meta["sequence"], np.int64)
                    if len(self.sequence) != self.n:
                        raise CaptureError(f"{side}: {len(self.sequence)} sequence numbers for {self.n} frames")
                if "t_ns" in meta:
                    self.t_ns = np.asarray(meta["t_ns"], np.int64)
                meta_fps = float(meta.get("fps", 0.0))
        elif path.endswith(".raw"):
            if size is None or fourcc is None:
                raise CaptureError(f"{path}: a raw dump needs --size WxH and --fourcc (GREY, Y16, Y8I)")
            code = (fourcc + "    ")[:4]
            if code not in PIXEL_FORMATS:
                raise CaptureError(f"{path}: unknown fourcc {fourcc!r}")
            dt, spp, _ = PIXEL_FORMATS[code]
            w, h = size
            raw = np.memmap(path, np.dtype(dt), mode="r")
            per = w * h * spp
            if len(raw) % per:
                raise CaptureError(f"{path}: {raw.nbytes} bytes is not a whole number of {w}x{h} {code.strip()} frames")
            self.array = raw.reshape(-1, h, w, spp)[..., 0]
            self.n, self.dtype = len(self.array), np.dtype(dt)
        else:
            cap = cv2.VideoCapture(path)
            if not cap.isOpened():
                raise CaptureError(f"{path}: neither a folder of frames, a .npy/.raw recording nor a readable video")
            self._video = cap
            self.n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) or 0
            meta_fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0)
            self.dtype = np.dtype(np.uint8)
            self.notes.append(f"{path}: a video file is 8-bit and usually lossy; frames or .npy are better")
        self.fps = float(fps) if fps else meta_fps
        self.full_scale = 255.0 if self.dtype == np.uint8 else 65535.0

    def __len__(self) -> int:
        return self.n

    def _image(self, i: int) -> np.ndarray:
        fn = self.files[i]
        img = cv2.imread(fn, cv2.IMREAD_UNCHANGED)
        if img is None:
            raise CaptureError(f"{fn}: not a readable image")
        img = _grey(img, self.path, self.notes)
        if img.dtype not in (np.uint8, np.uint16):
            raise CaptureError(f"{fn}: pixel type {img.dtype}; expected 8- or 16-bit grey")
        return img

    def read(self, timeout: float = 2.0) -> Frame | None:
        i = self.pos
        if self._video is not None:
            ok, img = self._video.read()
            if not ok:
                return None
            img = _grey(img, self.path, self.notes)
        else:
            if i >= self.n:
                return None
            img = self._image(i) if hasattr(self, "files") else np.array(self.array[i])
        self.pos += 1
        seq = int(self.sequence[i]) if self.sequence is not None else i
        t = int(self.t_ns[i]) if self.t_ns is not None else (int(seq / self.fps * 1e9) if self.fps else 0)
        return Frame(img, seq, t)

    def frames(self):
        """The whole recording, indexable by frame number: an array, a memmap, or a lazy file list"""
        if hasattr(self, "files"):
            return _LazyFrames(self)
        if self._video is not None:
            self._video.set(cv2.CAP_PROP_POS_FRAMES, 0)
            out = []
            while True:
                ok, img = self._video.read()
                if not ok:
                    break
                out.append(_grey(img, self.path, self.notes))
            if not out:
                raise CaptureError(f"{self.path}: no frames")
            self.n = len(out)
            return np.stack(out)
        return self.array

    def sequence_numbers(self) -> np.ndarray:
        return self.sequence if self.sequence is not None else np.arange(self.n)

    def close(self) -> None:
        if self._video is not None:
            self._video.release()
            self._video = None

    def info(self) -> dict:
        return {"backend": self.name, "path": os.path.abspath(self.path), "frames": self.n,
                "dtype": str(np.dtype(self.dtype)), "fps": self.fps, "notes": list(self.notes)}


class _LazyFrames:
    """A folder of frames read on demand, indexable like an array (len, [t], .shape, .dtype)"""

    def __init__(self, src: ReplaySource):
        self.src = src
        first = src._image(0)
        self.shape = (src.n,) + first.shape
        self.dtype = first.dtype

    def __len__(self) -> int:
        return self.src.n

    def __getitem__(self, i: int) -> np.ndarray:
        img = self.src._image(int(i))
        if img.shape != self.shape[1:]:
            raise CaptureError(f"{self.src.files[int(i)]}: {img.shape[1]}x{img.shape[0]}, the recording's first "
                               f"frame is {self.shape[2]}x{self.shape[1]} (every frame of a camera has one size)")
        return img

    def check_sizes(self) -> None:
        """Read every frame once: CaptureError naming the first whose size differs from the first frame's"""
        for i in range(len(self)):
            self[i]


class InterleavedFrames:
    """One imager of a raw dump of both (Y12I / Y8I), unpacked frame by frame on demand (indexable like an array)"""

    def __init__(self, raw: np.ndarray, code: str, width: int, height: int, view: int):
        self.raw, self.code, self.view = raw, code, view
        self.width, self.height = width, height
        self.dtype = np.dtype(np.uint16 if code == "Y12I" else np.uint8)
        self.shape = (len(raw), height, width)

    def __len__(self) -> int:
        return len(self.raw)

    def __getitem__(self, t: int) -> np.ndarray:
        return unpack(self.code, self.raw[int(t)], self.width, self.height)[self.view]


def stereo_raw(path: str, size: tuple[int, int], fourcc: str) -> list[InterleavedFrames]:
    """A raw dump of both imagers (`v4l2-ctl --stream-to` in Y12I or Y8I) -> [left, right] recordings

    SYNOPSIS

        >>> import tempfile, os
        >>> from rotstar_mrcal.capture.interleaved import pack_y12i
        >>> fn = os.path.join(tempfile.mkdtemp(), "pair.raw")
        >>> l, r = np.full((2, 3), 7, np.uint16), np.full((2, 3), 9, np.uint16)
        >>> with open(fn, "wb") as f:
        ...     _ = f.write(pack_y12i(l, r).tobytes() * 4)           # 4 frames of 3x2
        >>> left, right = stereo_raw(fn, (3, 2), "Y12I")
        >>> len(left), left.shape, int(left[3][1, 2]), int(right[0][0, 0])
        (4, (4, 2, 3), 7, 9)
    """
    code = (fourcc + "    ")[:4]
    if code not in BYTES_PER_PIXEL:
        raise CaptureError(f"{path}: {fourcc} is not a format of both imagers (Y12I, Y8I)")
    w, h = size
    per = w * h * BYTES_PER_PIXEL[code]
    try:
        raw = np.memmap(path, np.uint8, mode="r")
    except (OSError, ValueError) as e:
        raise CaptureError(f"{path}: cannot read ({e})") from None
    if len(raw) == 0 or len(raw) % per:
        raise CaptureError(f"{path}: {raw.nbytes} bytes is not a whole number of {w}x{h} {code.strip()} frames "
                           f"({per} bytes each)")
    frames = raw.reshape(-1, per)
    try:
        unpack(code, frames[0], w, h)
    except InterleavedError as e:
        raise CaptureError(f"{path}: {e}") from None
    return [InterleavedFrames(frames, code, w, h, v) for v in (0, 1)]

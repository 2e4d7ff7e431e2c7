"""The libcamera backend: libcamera's `cam` tool as a FrameSource (optional, experimental)

SYNOPSIS

    from rotstar_mrcal.capture.backend_libcamera import LibcameraSource, list_cameras
    print(list_cameras())                       # [(1, "'Intel RealSense ...' (\\_SB_...)"), ...]
    src = LibcameraSource(camera="1", size=(1280, 800), pixelformat="R16", fps=25)
    src.set_exposure_us(4000)                   # sent as a capture script; not read back
    src.start()
    frame = src.read()

Runs `cam -c CAMERA -C N -s width=W,height=H,pixelformat=FMT -F DIR/frame-#.bin
[--script controls.yaml]` for a chunk of N frames at a time and reads the raw
buffers back (one file per frame; `#` becomes "<stream>-<sequence>"). R8 and
R16 (libcamera's names for V4L2 GREY and Y16) are read as uint8 / uint16.
Controls go into the capture script at frame 0: ExposureTime (us),
AeEnable false, AnalogueGain; cam ignores controls a camera lacks, so they
are not verified (info() says so).

Limits (doc/capture.md, section 9): libcamera's uvcvideo
pipeline opens only one "default" video node per UVC function and maps
ExposureTime to the standard 100-us exposure control. On a RealSense D4xx the
default node of the depth function is very likely the depth (Z16) pin, which
libcamera cannot use, so the IR stream is probably unreachable and the
camera may not even be listed (`cam -l`); the D4xx extension-unit controls
(IR exposure, emitter) are never reachable. Use the v4l2 backend for the
D435; this one is for cameras that libcamera does drive.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import tempfile

import numpy as np

from rotstar_mrcal.programs import run_tool
from rotstar_mrcal.capture.source import CaptureError, Frame, FrameSource

PIXELFORMATS = {"R8": np.uint8, "R16": np.dtype("<u2"), "GREY": np.uint8, "Y16": np.dtype("<u2")}
LIBCAMERA_NAMES = {"GREY": "R8", "Y16": "R16", "Y16 ": "R16"}


def _cam(cam: str) -> str:
    exe = shutil.which(cam)
    if exe is None:
        raise CaptureError(f"{cam}: libcamera's cam tool is not installed (Debian: apt-get install libcamera-tools)")
    return exe


def list_cameras(cam: str = "cam") -> list[tuple[int, str]]:
    """(index, description) of every camera `cam -l` lists"""
    r = run_tool([_cam(cam), "-l"], capture_output=True, text=True, timeout=30)
    out = []
    for line in r.stdout.splitlines():
        m = re.match(r"\s*(\d+):\s*(.*)", line)
        if m:
            out.append((int(m.group(1)), m.group(2).strip()))
    return out


class LibcameraSource(FrameSource):
    name = "libcamera"

    def __init__(self, camera: str = "1", size=(1280, 800), pixelformat: str = "R16", fps: float | None = None,
                 chunk: int = 300, cam: str = "cam", timeout: float = 120.0):
        self.exe = _cam(cam)
        self.camera = str(camera)
        self.size = (int(size[0]), int(size[1]))
        self.pixelformat = LIBCAMERA_NAMES.get(pixelformat, pixelformat)
        if self.pixelformat not in ("R8", "R16"):
            raise CaptureError(f"libcamera: pixel format {pixelformat!r}; use R8 (GREY) or R16 (Y16)")
        self.dtype = np.dtype(PIXELFORMATS[self.pixelformat])
        self.full_scale = 255.0 if self.dtype == np.uint8 else 65535.0
        self.fps = float(fps or 0.0)
        self.chunk = int(chunk)
        self.timeout = timeout
        self.controls: dict[str, float | bool] = {}
        self._queue: list[Frame] = []
        self._seq_offset = 0

    def set_exposure_us(self, us: float) -> float:
        self.controls["AeEnable"] = False
        self.controls["ExposureTime"] = int(round(us))
        return float(int(round(us)))

    def set_gain(self, gain: float) -> float:
        self.controls["AnalogueGain"] = float(gain)
        return float(gain)

    def command(self, n: int, folder: str) -> list[str]:
        w, h = self.size
        cmd = [self.exe, "-c", self.camera, f"-C{n}", "-s", f"width={w},height={h},pixelformat={self.pixelformat}",
               f"-F{os.path.join(folder, 'frame-#.bin')}"]
        if self.controls:
            script = os.path.join(folder, "controls.yaml")
            with open(script, "w") as f:
                f.write("frames:\n  - 0:\n")
                for k, v in self.controls.items():
                    f.write(f"      {k}: {str(v).lower() if isinstance(v, bool) else v}\n")
            cmd.append(f"--script={script}")
        return cmd

    def _fetch(self, n: int) -> None:
        with tempfile.TemporaryDirectory(prefix="rotstar-cam-") as d:
            cmd = self.command(n, d)
            try:
                r = run_tool(cmd, capture_output=True, text=True, timeout=self.timeout)
            except subprocess.TimeoutExpired:
                raise CaptureError(f"libcamera: {' '.join(cmd)} did not finish in {self.timeout:g} s") from None
            files = [f for f in os.listdir(d) if f.endswith(".bin")]
            if r.returncode != 0 or not files:
                tail = (r.stderr or r.stdout).strip().splitlines()[-3:]
                raise CaptureError(f"libcamera: `{' '.join(cmd)}` gave no frames (exit {r.returncode}): "
                                   + " | ".join(tail))
            seqs = []
            for f in files:
                m = re.search(r"(\d+)\.bin$", f)
                seqs.append(int(m.group(1)) if m else len(seqs))
            order = np.argsort(seqs)
            base = self._seq_offset
            for i in order:
                data = np.fromfile(os.path.join(d, files[i]), np.uint8)
                self._queue.append(Frame(self.decode(data), base + seqs[i]))
            self._seq_offset = base + max(seqs) + 2  # a gap: cam restarted between chunks

    def decode(self, data: np.ndarray) -> np.ndarray:
        """One raw buffer -> (H, W) image; the stride is the buffer size / height"""
        w, h = self.size
        row = w * self.dtype.itemsize
        if len(data) < row * h:
            raise CaptureError(f"libcamera: a {len(data)}-byte buffer cannot hold {w}x{h} {self.pixelformat}")
        stride = len(data) // h
        return np.ascontiguousarray(data[: stride * h].reshape(h, stride)[:, :row]).view(self.dtype)

    def read(self, timeout: float = 2.0) -> Frame | None:
        if not self._queue:
            self._fetch(self.chunk)
        return self._queue.pop(0)

    def info(self) -> dict:
        return {"backend": self.name, "cam": self.exe, "camera": self.camera, "size": list(self.size),
                "pixelformat": self.pixelformat, "controls": dict(self.controls),
                "notes": ["controls are sent in a cam capture script and not read back"]}

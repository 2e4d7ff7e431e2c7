"""Files written whole or not at all: a temporary file in the same folder, renamed when complete

SYNOPSIS

    >>> import os, tempfile
    >>> from rotstar_mrcal.atomic import atomic_path, atomic_write
    >>> d = tempfile.mkdtemp()
    >>> with atomic_write(os.path.join(d, "a.txt")) as f:
    ...     _ = f.write("whole")
    >>> open(os.path.join(d, "a.txt")).read(), os.listdir(d)
    ('whole', ['a.txt'])
    >>> try:
    ...     with atomic_path(os.path.join(d, "b.png")) as tmp:   # same extension, for cv2.imwrite
    ...         _ = open(tmp, "w").write("half")
    ...         raise KeyboardInterrupt
    ... except KeyboardInterrupt:
    ...     pass
    >>> os.listdir(d)                                 # nothing half-written left behind
    ['a.txt']
    >>> try:                                          # a failed write names the file meant, not the temporary one
    ...     with atomic_write(os.path.join(d, "c.txt")) as f:
    ...         raise OSError(28, "No space left on device")
    ... except OSError as e:
    ...     print(os.path.basename(e.filename), e.strerror, os.listdir(d))
    c.txt No space left on device ['a.txt']

The temporary name is hidden (a leading dot) and unique per process, so
readers that list a folder (dataset.list_poses) never see it.

A whole folder (a pose: its frames and segment.json) is written the same way:

    >>> with atomic_folder(os.path.join(d, "pose000")) as tmp:
    ...     _ = open(os.path.join(tmp, "f.png"), "w").write("frame")
    >>> sorted(os.listdir(d)), os.listdir(os.path.join(d, "pose000"))
    (['a.txt', 'pose000'], ['f.png'])

A recording written through a memory map gets its disk blocks first, so that
a full disk is an OSError naming the file, not a SIGBUS half-way through:

    >>> buf = allocated_npy(os.path.join(d, "rec.npy"), "uint16", (3, 2, 2))
    >>> buf.shape, os.path.getsize(os.path.join(d, "rec.npy"))
    ((3, 2, 2), 152)
"""

from __future__ import annotations

import contextlib
import errno
import os
import secrets
import shutil

import numpy as np


@contextlib.contextmanager
def atomic_path(path: str):
    """Yield a temporary path in path's folder (same extension, for writers that go by it);
    renamed to path when the block ends, removed if it raises or is interrupted"""
    d, base = os.path.split(path)
    stem, ext = os.path.splitext(base)
    tmp = os.path.join(d, f".{stem}.{os.getpid()}-{secrets.token_hex(3)}.part{ext}")
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException as e:
        with contextlib.suppress(OSError):
            os.remove(tmp)
        if isinstance(e, OSError) and e.filename in (None, tmp):  # (a full disk: named by the file meant)
            raise OSError(e.errno, e.strerror or str(e), path) from e
        raise


@contextlib.contextmanager
def atomic_write(path: str, mode: str = "w", **kw):
    """open(path, mode) that writes a temporary file in the same folder, renamed on success"""
    with atomic_path(path) as tmp:
        with open(tmp, mode, **kw) as f:
            yield f


@contextlib.contextmanager
def atomic_folder(path: str):
    """Yield a new temporary folder beside path; renamed to path when the block ends (a folder
    already there is replaced whole), removed with its contents if the block raises or is interrupted"""
    parent, base = os.path.split(os.path.normpath(path))
    os.makedirs(parent or ".", exist_ok=True)
    tmp = os.path.join(parent, f".{base}.{os.getpid()}-{secrets.token_hex(3)}.part")
    try:
        os.mkdir(tmp)  # (inside: an interrupt right after it still removes it)
        yield tmp
        if os.path.isdir(path):
            old = tmp + ".old"
            os.rename(path, old)
            os.rename(tmp, path)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.rename(tmp, path)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


@contextlib.contextmanager
def whole_or_none(path: str):
    """A folder filled by several writers in turn (a rig's pose: camera-0/, camera-1/, ...): if it did not
    exist before the block and the block raises or is interrupted, it is removed with what was written

    >>> import tempfile
    >>> d = tempfile.mkdtemp()
    >>> try:
    ...     with whole_or_none(os.path.join(d, "pose000")):
    ...         os.makedirs(os.path.join(d, "pose000", "camera-0"))
    ...         raise KeyboardInterrupt                  # before camera-1
    ... except KeyboardInterrupt:
    ...     pass
    >>> os.listdir(d)
    []
    """
    existed = os.path.lexists(path)
    try:
        yield path
    except BaseException:
        if not existed:
            shutil.rmtree(path, ignore_errors=True)
        raise


def allocated_npy(path: str, dtype, shape: tuple) -> np.ndarray:
    """np.lib.format.open_memmap(path, "w+") with every disk block allocated up front

    A memory-mapped file is sparse: writing into it on a full disk kills the
    process with SIGBUS. Here the space is taken at once (posix_fallocate), and
    a disk without it raises OSError("path: no space left on device (N MB
    needed)", errno ENOSPC) with the file removed.
    """
    nbytes = int(np.prod(shape)) * np.dtype(dtype).itemsize
    try:
        buf = np.lib.format.open_memmap(path, mode="w+", dtype=dtype, shape=tuple(shape))
        with open(path, "r+b") as f:
            try:
                os.posix_fallocate(f.fileno(), 0, os.fstat(f.fileno()).st_size)
            except OSError as e:  # a file system that cannot allocate: the free space, at least, is checked
                if e.errno not in (errno.EOPNOTSUPP, errno.EINVAL, errno.ENOSYS):
                    raise
                if shutil.disk_usage(os.path.dirname(os.path.abspath(path))).free < nbytes:
                    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC)) from None
    except OSError as e:
        with contextlib.suppress(OSError):
            os.remove(path)
        reason = "no space left on device" if e.errno in (errno.ENOSPC, errno.EDQUOT) else (e.strerror or str(e))
        err = OSError(f"{path}: {reason} ({nbytes / 1e6:.0f} MB needed)")  # str(): the message alone
        err.errno = e.errno
        raise err from None
    return buf

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
"""

from __future__ import annotations

import contextlib
import os
import secrets


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

"""One pool of worker processes: a function mapped over items, results in order

SYNOPSIS

    >>> from rotstar_mrcal.parallel import pool_map
    >>> pool_map(abs, [-3, 1, -2], jobs=1)
    [3, 1, 2]
    >>> seen = []
    >>> pool_map(abs, [-3, 1], jobs=1, progress=lambda i, r: seen.append((i, r)))
    [3, 1]
    >>> seen
    [(0, 3), (1, 1)]

With jobs > 1 the items go to `jobs` spawned processes (never forked: a
fork of a process holding OpenCV or BLAS threads can hang), each set up once
by initializer(*initargs), e.g. to build a large read-only state (a screen,
a PSF) that every item uses. fn, the items and the results must pickle;
progress(index, result) is called in the parent as each item finishes, in
the order they finish. With jobs <= 1 (or a single item) everything runs in
this process: initializer first, finalizer at the end (to drop that state).

Ctrl-C or SIGTERM while the pool runs terminates the workers and raises
KeyboardInterrupt (SIGTERM: SystemExit) in the caller; no worker is left
behind.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import multiprocessing
import signal
import threading


@contextlib.contextmanager
def _sigterm_exits():
    """While inside: SIGTERM raises SystemExit(143) in the main thread (so `finally` blocks run)"""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        raise SystemExit(128 + signum)

    old = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


def _terminate(ex: cf.ProcessPoolExecutor) -> None:
    for p in list((getattr(ex, "_processes", None) or {}).values()):
        p.terminate()
    ex.shutdown(wait=False, cancel_futures=True)


def pool_map(fn, items, jobs: int = 1, initializer=None, initargs=(), progress=None, finalizer=None) -> list:
    """[fn(item) for item in items], in `jobs` spawned processes; see the module doc"""
    items = list(items)
    out = [None] * len(items)
    if jobs <= 1 or len(items) <= 1:
        if initializer is not None:
            initializer(*initargs)
        try:
            for i, x in enumerate(items):
                out[i] = fn(x)
                if progress is not None:
                    progress(i, out[i])
        finally:
            if finalizer is not None:
                finalizer()
        return out
    ex = cf.ProcessPoolExecutor(min(jobs, len(items)), mp_context=multiprocessing.get_context("spawn"),
                                initializer=initializer, initargs=initargs)
    with _sigterm_exits():
        try:
            futs = {ex.submit(fn, x): i for i, x in enumerate(items)}
            for f in cf.as_completed(futs):
                i = futs[f]
                out[i] = f.result()
                if progress is not None:
                    progress(i, out[i])
        except BaseException:
            _terminate(ex)
            raise
    ex.shutdown()
    return out

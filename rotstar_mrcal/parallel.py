"""Work over processes that never outlive their parent

SYNOPSIS

    >>> from rotstar_mrcal.parallel import process_map
    >>> sorted(process_map(pow, [(2, 3), (3, 2)], jobs=2))
    [8, 9]

process_map yields fn(*a) for every a in args in the order they finish, from
min(jobs, len(args)) worker processes. The workers ignore Ctrl-C (a terminal
sends it to the whole process group; the parent handles it) and die at once
on SIGTERM; on any exit from the loop (an error, Ctrl-C, SIGTERM in the
parent, a consumer that stops early) they are terminated, none is left
running. With jobs <= 1 everything runs in this process.
"""

from __future__ import annotations

import multiprocessing
import signal
import threading


def _worker_init(init=None, initargs=()) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    try:
        import cv2

        cv2.setNumThreads(1)
    except ImportError:  # pragma: no cover - OpenCV is a dependency
        pass
    if init is not None:
        init(*initargs)


def _pool(ctx, processes: int, **kw):
    """ctx.Pool(processes, **kw), its processes started with Ctrl-C ignored

    A terminal's Ctrl-C goes to the whole process group. A worker (or the
    forkserver, on first use) that gets it while it starts, before
    _worker_init, ended in a KeyboardInterrupt traceback. An ignored SIGINT
    is inherited across fork and exec, and Python keeps it ignored at start-up,
    so the processes started here never see one; this process gets its own
    handler back once the pool is made (the parent stops the workers itself).
    """
    if threading.current_thread() is not threading.main_thread():
        return ctx.Pool(processes, **kw)
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        return ctx.Pool(processes, **kw)
    finally:
        signal.signal(signal.SIGINT, old)


def _star(fa):
    fn, a = fa
    return fn(*a)


def process_map(fn, args: list[tuple], jobs: int, initializer=None, initargs=()):
    """Yield fn(*a) for a in args as they finish; see the module doc"""
    args = list(args)
    if jobs <= 1 or len(args) <= 1:
        if initializer is not None:
            initializer(*initargs)
        for a in args:
            yield fn(*a)
        return
    ctx = multiprocessing.get_context("forkserver")  # no fork of a threaded parent (OpenCV, BLAS): it can deadlock
    with _pool(ctx, min(jobs, len(args)), initializer=_worker_init, initargs=(initializer, initargs)) as pool:  # __exit__ terminates
        yield from pool.imap_unordered(_star, [(fn, a) for a in args])

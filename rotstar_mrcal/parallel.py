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
    with ctx.Pool(min(jobs, len(args)), initializer=_worker_init, initargs=(initializer, initargs)) as pool:  # __exit__ terminates
        yield from pool.imap_unordered(_star, [(fn, a) for a in args])

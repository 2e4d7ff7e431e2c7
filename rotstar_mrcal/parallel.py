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
from multiprocessing import resource_tracker
import threading


def _worker_init(init=None, initargs=()) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})  # blocked by _pool; ignored here, as it was
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    try:
        import cv2

        cv2.setNumThreads(1)
    except ImportError:  # pragma: no cover - OpenCV is a dependency
        pass
    if init is not None:
        init(*initargs)


def _pool(ctx, processes: int, **kw):
    """ctx.Pool(processes, **kw), its processes started with Ctrl-C blocked

    A terminal's Ctrl-C goes to the whole process group. A worker (or the
    forkserver, on first use) that got it while it started, before
    _worker_init, ended in a KeyboardInterrupt traceback. A blocked signal
    stays blocked across fork and exec, so the processes started here never
    see one (_worker_init ignores it, then unblocks it).

    In this process a Ctrl-C while the pool starts (the forkserver's first
    start takes a second) is noted, not raised: raised half-way, it left
    workers starting with no pool to stop them. It is raised once the pool is
    whole, and the pool terminated. (Ignoring SIGINT here instead loses it.)
    """
    if threading.current_thread() is not threading.main_thread():
        return ctx.Pool(processes, **kw)
    resource_tracker.ensure_running()  # first: its own start unblocks SIGINT when done
    noted = []
    old = signal.signal(signal.SIGINT, lambda signum, frame: noted.append(signum))
    if old == signal.SIG_IGN:  # started ignoring Ctrl-C (`cmd &`): so be it
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})  # (a thread's mask, inherited by fork)
    try:
        pool = ctx.Pool(processes, **kw)
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        signal.signal(signal.SIGINT, old)
    if noted:
        pool.terminate()
        signal.raise_signal(signal.SIGINT)  # as if it came now: the caller's own handler
    return pool


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

"""rotstar_mrcal.parallel.pool_map: order, initializer, progress, and no worker left behind"""

from __future__ import annotations

import multiprocessing
import os
import signal
import threading
import time

import pytest

from rotstar_mrcal.parallel import pool_map

_STATE: dict = {}


def _init(offset):
    _STATE["offset"] = offset


def _add(x):
    time.sleep(0.05 * (x % 3))  # finish out of order
    return x + _STATE["offset"], os.getpid()


def test_in_order_in_processes():
    seen = []
    out = pool_map(_add, range(6), jobs=2, initializer=_init, initargs=(10,), progress=lambda i, r: seen.append(i))
    assert [r[0] for r in out] == list(range(10, 16))
    assert sorted(seen) == list(range(6))
    assert {pid for _, pid in out} != {os.getpid()}


def test_inline_runs_initializer_and_finalizer():
    out = pool_map(_add, [1, 2], jobs=1, initializer=_init, initargs=(5,), finalizer=_STATE.clear)
    assert [r[0] for r in out] == [6, 7] and {pid for _, pid in out} == {os.getpid()}
    assert _STATE == {}


def test_a_worker_error_reaches_the_caller():
    with pytest.raises(ValueError):
        pool_map(int, ["1", "x", "3"], jobs=2)


def test_sigterm_stops_the_workers():
    timer = threading.Timer(1.0, os.kill, (os.getpid(), signal.SIGTERM))
    timer.start()
    t0 = time.monotonic()
    with pytest.raises(SystemExit):
        pool_map(time.sleep, [30, 30, 30], jobs=2)
    assert time.monotonic() - t0 < 10
    deadline = time.monotonic() + 5
    while multiprocessing.active_children() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not multiprocessing.active_children()
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL or callable(signal.getsignal(signal.SIGTERM))

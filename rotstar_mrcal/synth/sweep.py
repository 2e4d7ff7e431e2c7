"""Run the experiment's configurations in parallel, cached so that an interrupted sweep resumes

SYNOPSIS

    >>> import tempfile
    >>> from rotstar_mrcal.synth.experiment import quick_protocol
    >>> from rotstar_mrcal.synth.sweep import run_sweep, pending_tasks
    >>> p = quick_protocol(aberrations=("spherical",), noises=(0.0,), phis_deg=(30,), alphas_deg=(0, 90),
    ...                    repeats=2, refiners=("symmetric",), patterns=("checkerboard",))
    >>> cache = tempfile.mkdtemp()
    >>> len(pending_tasks(p, cache))
    1
    >>> res = run_sweep(p, cache, jobs=1)
    >>> sorted(res), len(pending_tasks(p, cache))       # (aberration, noise, phi) -> result; all cached
    ([('spherical', 0.0, 30)], 0)

A configuration is (aberration, noise, phi); its result (experiment.run_task)
is stored in cache_dir/<Protocol.config_key>.npz, a key that changes with
every setting the numbers depend on, so a cache is never reused for a
different protocol and a sweep that was interrupted (or extended by a noise
level or a tilt) computes only what is missing.

A task is (aberration, phi, the noise levels still missing): the noise levels
of one tilt share the rendered frames. Tasks run

- in this process (jobs=1),
- on `jobs` local processes (concurrent.futures, spawn), or
- on a Dask cluster: scheduler="tcp://host:8786" (dask.distributed.Client;
  the workers need this package importable, e.g. the same environment).

Results come back to this process, which writes the cache; the longest
tasks (coma, large tilts) are submitted first. `progress(done, total,
label)` is called after each task (the CLI draws the bar).
"""

from __future__ import annotations

import concurrent.futures
import multiprocessing
import os
import signal
import tempfile

import cv2
import numpy as np

from rotstar_mrcal.synth.experiment import SYMMETRIC, Protocol, run_task


def cache_path(protocol: Protocol, cache_dir: str, aberration: str, noise: float, phi) -> str:
    return os.path.join(cache_dir, protocol.config_key(aberration, noise, phi) + ".npz")


def load_result(path: str) -> dict:
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


def save_result(path: str, result: dict) -> None:
    """Write atomically (a partial file never looks like a result)"""
    d = os.path.dirname(path) or "."
    fd, tmp = tempfile.mkstemp(dir=d, suffix=".tmp.npz")
    os.close(fd)
    np.savez(tmp, **result)
    os.replace(tmp, path)


def pending_tasks(protocol: Protocol, cache_dir: str) -> list[tuple[str, float, tuple]]:
    """(aberration, phi, noises) still missing from the cache, longest first"""
    out = []
    for a in protocol.aberrations:
        for phi in protocol.phis_deg:
            todo = tuple(n for n in protocol.noises if not os.path.exists(cache_path(protocol, cache_dir, a, n, phi)))
            if todo:
                out.append((a, phi, todo))
    return sorted(out, key=lambda t: (SYMMETRIC.get(t[0], False), -t[1]))


def _run(protocol: Protocol, task):
    cv2.setNumThreads(1)
    a, phi, noises = task
    return task, run_task(protocol, a, phi, noises)


def _ignore_sigint() -> None:
    """Workers: Ctrl-C (sent to the whole process group) is the parent's to handle"""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def run_sweep(protocol: Protocol, cache_dir: str, jobs: int = 1, scheduler: str | None = None,
              progress=None) -> dict:
    """Compute what is missing, then return {(aberration, noise, phi): result} for the whole protocol"""
    os.makedirs(cache_dir, exist_ok=True)
    tasks = pending_tasks(protocol, cache_dir)
    total = len(tasks)

    def store(task, out, done):
        a, phi, _ = task
        for n, res in out.items():
            save_result(cache_path(protocol, cache_dir, a, n, phi), res)
        if progress is not None:
            progress(done, total, f"{a} phi={phi:g}")

    if tasks and scheduler:
        # (here, not at the top: dask.distributed costs 0.8-1.2 s of start-up, python -X importtime,
        # and only --dask needs it)
        from dask.distributed import Client, as_completed

        with Client(scheduler) as client:
            futures = client.map(_run, [protocol] * total, tasks, pure=False)
            for done, fut in enumerate(as_completed(futures), 1):
                store(*fut.result(), done)
    elif tasks and jobs > 1:
        ctx = multiprocessing.get_context("spawn")
        with concurrent.futures.ProcessPoolExecutor(max_workers=min(jobs, total), mp_context=ctx,
                                                    initializer=_ignore_sigint) as ex:
            futures = [ex.submit(_run, protocol, t) for t in tasks]
            try:
                for done, fut in enumerate(concurrent.futures.as_completed(futures), 1):
                    store(*fut.result(), done)
            except BaseException:  # Ctrl-C, SIGTERM, an error: stop now, not after the queued tasks
                ex.shutdown(wait=False, cancel_futures=True)
                for proc in list((getattr(ex, "_processes", None) or {}).values()):
                    proc.terminate()
                raise
    else:
        for done, t in enumerate(tasks, 1):
            store(*_run(protocol, t), done)

    return {
        (a, float(n), phi): load_result(cache_path(protocol, cache_dir, a, n, phi))
        for a in protocol.aberrations
        for n in protocol.noises
        for phi in protocol.phis_deg
    }

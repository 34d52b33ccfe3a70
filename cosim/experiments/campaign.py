"""Run campaign tasks in parallel: local processes (default), dask, or serially.

A campaign is a list of independent, picklable ``(function, kwargs)`` tasks; random streams
come from :func:`realisation_seeds` per (task, realisation), so results do not depend on the
order, the partition into tasks or the backend. Ctrl-C (and SIGTERM, which the command line
turns into the same) stops a campaign at once: :func:`run_tasks` terminates the workers and
raises :class:`~fmu_models.errors.Interrupted` whose ``partial`` holds the finished results
(None for the others).
"""
from __future__ import annotations

import contextlib
import logging
import multiprocessing
import os
import signal
import sys
from collections.abc import Callable, Sequence
from multiprocessing import resource_tracker

import numpy as np

from fmu_models.errors import ConfigurationError, Interrupted, UnknownNameError

__all__ = ["BACKENDS", "realisation_seeds", "run_tasks"]

BACKENDS = ("processes", "serial", "dask")


def realisation_seeds(seed: int, *key: int, n: int = 2) -> list[int]:
    """``n`` independent 32-bit seeds for the realisation identified by ``key`` (integers,
    e.g. scenario and run index), from ``numpy.random.SeedSequence(seed, spawn_key=key)``."""
    ss = np.random.SeedSequence(seed, spawn_key=tuple(int(k) for k in key))
    return [int(s) for s in ss.generate_state(n)]


def _worker_init() -> None:
    """In each worker: leave Ctrl-C to the parent, and die with the parent."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if sys.platform.startswith("linux"):
        import ctypes

        with contextlib.suppress(OSError, AttributeError):
            ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)   # PR_SET_PDEATHSIG


@contextlib.contextmanager
def _sigint_blocked():
    """SIGINT blocked in this thread for the duration: a process started meanwhile begins
    with it blocked (a signal mask survives exec, a handler does not), so a Ctrl-C while a
    worker still imports the package prints no traceback of the worker's. The caller loses
    no Ctrl-C: its other threads take it, or this one once unblocked. (Multiprocessing starts
    its resource tracker so.)"""
    if not hasattr(signal, "pthread_sigmask"):      # Windows: no signal masks, no SIGINT to hold
        yield
        return
    resource_tracker.ensure_running()               # its first start unblocks SIGINT: before, not during
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def _indexed(item):
    i, (fn, kw) = item
    return i, fn(**kw)


@contextlib.contextmanager
def _quiet(logger_name: str):
    """Silence a library's logger for the duration (restored after)."""
    log = logging.getLogger(logger_name)
    level = log.level
    log.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        log.setLevel(level)


def run_tasks(tasks: Sequence[tuple[Callable, dict]], backend: str = "processes",
              n_jobs: int | None = None, progress: bool = True, desc: str = "tasks") -> list:
    """Run ``fn(**kwargs)`` for each of the ``tasks`` (module-level, picklable functions and
    their keyword arguments); returns the results in task order. ``backend``: local worker
    processes (``"processes"``), one process (``"serial"``) or a dask.distributed cluster
    (``"dask"``, the ``dask`` extra: the scheduler dask's configuration names as
    ``scheduler-address``, else the current client, else a local one); the tasks share no file
    with the caller. ``n_jobs``: worker processes of ``"processes"`` and of a local dask
    cluster (default: the cores). ``progress``: a tqdm progress bar, labelled ``desc``.

    Raises
    ------
    Interrupted
        Ctrl-C or SIGTERM; ``partial`` holds the finished results (None elsewhere).
    """
    from tqdm.auto import tqdm

    if backend not in BACKENDS:
        raise UnknownNameError(f"backend must be one of {BACKENDS}, got {backend!r}")
    results: list = [None] * len(tasks)
    bar = tqdm(total=len(tasks), desc=desc, disable=not progress, leave=False)
    try:
        if backend == "serial" or len(tasks) <= 1 or (n_jobs == 1 and backend == "processes"):
            for i, (fn, kw) in enumerate(tasks):
                results[i] = fn(**kw)
                bar.update()
        elif backend == "processes":
            _run_processes(tasks, results, n_jobs, bar)
        else:
            _run_dask(tasks, results, n_jobs, bar)
    except KeyboardInterrupt:
        done = sum(r is not None for r in results)
        raise Interrupted(f"interrupted after {done} of {len(tasks)} tasks", results) from None
    finally:
        bar.close()
    return results


def _run_processes(tasks, results, n_jobs, bar) -> None:
    # spawned, never forked: a forked child would inherit the caller's threads (numpy's,
    # tqdm's, a user's) in whatever state they were; a worker imports the package once
    workers = min(n_jobs or os.cpu_count() or 1, len(tasks))
    pool = None
    try:
        with _sigint_blocked():     # a Ctrl-C it held back raises as it ends, the pool there to terminate
            pool = multiprocessing.get_context("spawn").Pool(workers, initializer=_worker_init)
        for i, res in pool.imap_unordered(_indexed, list(enumerate(tasks))):
            results[i] = res
            bar.update()
        pool.close()
    except BaseException:
        if pool is not None:
            pool.terminate()        # kill the workers at once (Ctrl-C, SIGTERM, a task's error)
        raise
    finally:
        if pool is not None:
            pool.join()


def _dask_client(client_type, get_client, n_jobs):
    """``(client, own)``: a client of the scheduler that dask's configuration names
    (``scheduler-address``: ``DASK_SCHEDULER_ADDRESS``, a dask config file, or ``--scheduler``
    on the command line), else the current client, else a new local cluster (``own``: close
    the client after the campaign; a cluster started apart from it is left running)."""
    import dask

    address = dask.config.get("scheduler-address", None)
    if address:
        try:
            with _quiet("distributed"):
                return client_type(address, timeout="20s"), True
        except (OSError, TimeoutError, ValueError) as e:
            raise ConfigurationError(f"cannot reach the dask scheduler at {address!r}: {e}") from None
    try:
        return get_client(), False
    except ValueError:
        with _quiet("distributed"):
            # silence_logs: the workers' own loggers (a cancelled task is a WARNING there)
            return client_type(processes=True, n_workers=n_jobs, dashboard_address=None,
                               silence_logs=logging.ERROR), True


def _run_dask(tasks, results, n_jobs, bar) -> None:
    try:
        from dask.distributed import Client, get_client
        from dask.distributed import as_completed as dask_completed
    except ImportError:
        raise ImportError("the dask backend needs dask.distributed: pip install 'pendulum-cosim[dask]'") from None
    client, own = _dask_client(Client, get_client, n_jobs)
    futures = [client.submit(fn, **kw, pure=False) for fn, kw in tasks]
    index = {f.key: i for i, f in enumerate(futures)}
    try:
        for fut in dask_completed(futures):
            results[index[fut.key]] = fut.result()
            bar.update()
    except BaseException:
        with _quiet("distributed"), contextlib.suppress(Exception):
            client.cancel(futures)
        raise
    finally:
        if own:
            with _quiet("distributed"), contextlib.suppress(Exception):
                client.close(timeout=5)

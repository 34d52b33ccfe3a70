"""Run campaign tasks in parallel: local processes (default), dask, or serially.

A campaign is a list of independent tasks (e.g. one per scenario and noise reading), each
a picklable ``(function, kwargs)``. Random streams are derived per (task, realisation)
with :func:`realisation_seeds`, never from a shared generator, so results do not depend
on the order, the partition into tasks or the backend.
"""
from __future__ import annotations

import os
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Callable, Sequence

import numpy as np

BACKENDS = ("processes", "serial", "dask")


def realisation_seeds(seed: int, *key: int, n: int = 2) -> list[int]:
    """``n`` independent 32-bit seeds for the realisation identified by ``key`` (integers,
    e.g. scenario and run index), from ``numpy.random.SeedSequence(seed, spawn_key=key)``."""
    ss = np.random.SeedSequence(seed, spawn_key=tuple(int(k) for k in key))
    return [int(s) for s in ss.generate_state(n)]


def run_tasks(tasks: Sequence[tuple[Callable, dict]], backend: str = "processes",
              n_jobs: int | None = None, progress: bool = True, desc: str = "tasks") -> list:
    """Run ``fn(**kwargs)`` for each task; returns the results in task order.

    Parameters
    ----------
    tasks : sequence of (callable, dict)
        Module-level functions (picklable) and their keyword arguments.
    backend : {"processes", "serial", "dask"}
        Local worker processes (``n_jobs``, default: the machine's cores), one process,
        or a dask.distributed cluster (the current client, or a local one; needs the
        ``dask`` extra).
    n_jobs : int, optional
        Worker processes for ``"processes"``.
    progress : bool
        Show a tqdm progress bar.
    desc : str
        Label of the progress bar.
    """
    from tqdm.auto import tqdm

    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    results: list = [None] * len(tasks)
    bar = tqdm(total=len(tasks), desc=desc, disable=not progress, leave=False)
    try:
        if backend == "serial" or len(tasks) == 1 or (n_jobs == 1 and backend == "processes"):
            for i, (fn, kw) in enumerate(tasks):
                results[i] = fn(**kw)
                bar.update()
        elif backend == "processes":
            workers = min(n_jobs or os.cpu_count() or 1, len(tasks))
            with ProcessPoolExecutor(max_workers=workers) as pool:
                futures = {pool.submit(fn, **kw): i for i, (fn, kw) in enumerate(tasks)}
                for fut in as_completed(futures):
                    results[futures[fut]] = fut.result()
                    bar.update()
        else:
            try:
                from dask.distributed import Client, as_completed as dask_completed, get_client
            except ImportError:
                raise ImportError("the dask backend needs dask.distributed: "
                                  "pip install 'pendulum-cosim[dask]'") from None
            try:
                client, own = get_client(), False
            except ValueError:
                client, own = Client(processes=True, n_workers=n_jobs), True
            try:
                futures = [client.submit(fn, **kw, pure=False) for fn, kw in tasks]
                index = {f.key: i for i, f in enumerate(futures)}
                for fut in dask_completed(futures):
                    results[index[fut.key]] = fut.result()
                    bar.update()
            finally:
                if own:
                    client.close()
    finally:
        bar.close()
    return results

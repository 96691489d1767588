"""The candidates' fits and tests in worker processes: the diagnosis' one parallel step.

Each candidate effect is fitted on all frames and then scored on the held-out folds on its own; nothing one
candidate computes is read by another until the decision. So :func:`map_candidates` runs them in up to
``workers`` forked processes, in order, and hands back exactly what the serial loop would (each worker runs the
same deterministic code on a copy of the same inputs; a test checks the two give the same diagnosis).

Serial (the library default, ``workers=1``) inside a daemonic process (a Dask or multiprocessing worker, which
may not fork), for one item, or on a platform without ``fork``. The command line asks for
:func:`default_workers` (at most 2: the machines this runs on have 2 cores, and the figure worker of ``rce run``
runs beside it at a lower priority).
"""

from __future__ import annotations

import multiprocessing as mp
import os
from concurrent.futures import ProcessPoolExecutor
from typing import Callable, Iterable

#: the most worker processes :func:`default_workers` asks for
MAX_WORKERS = 2


def default_workers() -> int:
    """min(:data:`MAX_WORKERS`, the cores this process may run on)."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        cores = os.cpu_count() or 1
    return max(1, min(MAX_WORKERS, cores))


def _one_blas_thread() -> None:
    """Each worker's BLAS on one thread: the workers already fill the cores (two workers with a two-thread BLAS
    each ran slower than the serial loop's one BLAS on two threads)."""
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=1, user_api="blas")


def _call(task):
    fn, args = task
    return fn(*args)


def map_candidates(fn: Callable, args: Iterable[tuple], workers: int = 1) -> list:
    """[fn(*a) for a in args], in ``workers`` forked processes where that is allowed (module docstring)."""
    args = list(args)
    n = min(int(workers), len(args))
    if n <= 1 or mp.current_process().daemon or "fork" not in mp.get_all_start_methods():
        return [fn(*a) for a in args]
    with ProcessPoolExecutor(max_workers=n, mp_context=mp.get_context("fork"), initializer=_one_blas_thread) as pool:
        return list(pool.map(_call, [(fn, a) for a in args], chunksize=1))

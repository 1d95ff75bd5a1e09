"""One executor abstraction for the package's embarrassingly parallel jobs (no ROS import).

:func:`map_tasks` runs ``fn`` over a list of independent tasks (design sweeps, robustness
studies), results in the order of the tasks, on local worker processes (default), a Dask
distributed cluster (imported only when asked, :data:`DASK_HINT`) or any
:class:`concurrent.futures.Executor` the caller made.  Tasks and ``fn`` must be picklable.

See doc/developing.md, section "Parallel jobs".
"""
from __future__ import annotations

import multiprocessing
import os
import threading
from concurrent.futures import Executor, ProcessPoolExecutor
from contextlib import contextmanager
from typing import Any, Callable, Iterator, Sequence, TypeVar

from .errors import InputError

__all__ = ['EXECUTORS', 'DASK_HINT', 'default_workers', 'map_tasks', 'open_executor']

#: Executor names accepted by :func:`map_tasks` (and the commands' ``--executor``).
EXECUTORS = ('local', 'dask')
#: How to get the optional Dask dependency (pinned in requirements.txt).
DASK_HINT = 'pip install dask==2026.8.0 distributed==2026.8.0'

T = TypeVar('T')
R = TypeVar('R')


def default_workers() -> int:
    """Cores this process may use (``os.sched_getaffinity``)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:                     # not Linux
        return max(1, os.cpu_count() or 1)


def _check_workers(workers: Any) -> int:
    if workers is None:
        return default_workers()
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise InputError(f'workers must be an integer >= 1, got {workers!r}')
    return int(workers)


@contextmanager
def open_executor(executor: str | Executor = 'local', *, workers: int | None = None,
                  scheduler: str | None = None) -> Iterator[Executor | None]:
    """The executor named by ``executor`` for a ``with`` block (None: run in-process).

    Parameters
    ----------
    executor : {'local', 'dask'} or concurrent.futures.Executor
        Engine (see the module docstring); an Executor instance is yielded as is and
        not shut down.
    workers : int, optional
        Local worker processes, or the size of the LocalCluster started for ``'dask'``
        without ``scheduler`` (default: the cores available).  ``'local'`` with one
        worker yields None (in-process).
    scheduler : str, optional
        Address of a running Dask scheduler (``'dask'`` only).

    Raises
    ------
    InputError
        Unknown executor, bad ``workers``, ``scheduler`` without ``'dask'``, or Dask
        not installed / the scheduler not reachable.
    """
    if isinstance(executor, Executor):
        yield executor
        return
    if executor not in EXECUTORS:
        raise InputError(f'executor must be one of {EXECUTORS} (or a concurrent.futures '
                         f'Executor), got {executor!r}')
    n = _check_workers(workers)
    if executor == 'local':
        if scheduler is not None:
            raise InputError('--scheduler applies to --executor dask only')
        if n == 1:
            yield None
            return
        # fork is fastest; with threads running in this process fork is unsafe: spawn
        method = 'fork' if threading.active_count() == 1 and os.name == 'posix' else 'spawn'
        with ProcessPoolExecutor(max_workers=n,
                                 mp_context=multiprocessing.get_context(method)) as pool:
            yield pool
        return
    try:
        import distributed
    except ImportError:
        raise InputError(f'--executor dask needs Dask distributed, which is not installed: '
                         f'{DASK_HINT}') from None
    cluster = None
    try:
        if scheduler is None:
            cluster = distributed.LocalCluster(n_workers=n, threads_per_worker=1,
                                               processes=True, dashboard_address=None)
            client = distributed.Client(cluster)
        else:
            client = distributed.Client(scheduler, timeout='10s')
    except (OSError, TimeoutError) as exc:
        if cluster is not None:
            cluster.close()
        raise InputError(f'cannot reach the Dask scheduler {scheduler!r}: {exc}. Start one '
                         '(`dask scheduler`, then `dask worker ADDRESS`) or drop --scheduler '
                         'for a local cluster.') from None
    try:
        yield client.get_executor()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def map_tasks(fn: Callable[[T], R], tasks: Sequence[T], *,
              executor: str | Executor = 'local', workers: int | None = None,
              scheduler: str | None = None,
              cost: Callable[[T], float] | None = None) -> list[R]:
    """``[fn(t) for t in tasks]``, computed on ``executor`` (module docstring).

    With ``cost``, the tasks are handed to the engine most costly first (a stable sort:
    equal costs keep their order), so that the last tasks to start are short ones and
    the workers finish together (longest-processing-time first); the results are still
    returned in the order of ``tasks``.

    Parameters
    ----------
    fn : callable
        A module-level (picklable) function of one task.
    tasks : sequence
        Picklable tasks.
    executor, workers, scheduler
        As in :func:`open_executor`; one task, or ``'local'`` with one worker, runs
        in this process.
    cost : callable, optional
        An estimate of a task's run time (any scale; called here, not on the workers).

    Returns
    -------
    list
        The results, in the order of ``tasks`` (whatever the engine's completion order).
    """
    tasks = list(tasks)
    if not tasks:
        return []
    if isinstance(executor, str) and executor == 'local':
        workers = min(_check_workers(workers), len(tasks))
    with open_executor(executor, workers=workers, scheduler=scheduler) as ex:
        if ex is None:
            return [fn(t) for t in tasks]
        if cost is None:
            return list(ex.map(fn, tasks))
        order = sorted(range(len(tasks)), key=lambda i: -float(cost(tasks[i])))
        out: list[Any] = [None] * len(tasks)
        for i, r in zip(order, ex.map(fn, [tasks[i] for i in order])):
            out[i] = r
        return out

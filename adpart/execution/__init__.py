"""Where independent work runs: in this process, or on a pool of worker processes.

An executor maps a function over items and returns the results *in order*; it knows nothing of
what the work is. The Ray executor of a later issue implements the same interface.
"""

from __future__ import annotations

import multiprocessing
import os
import sys
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable
from concurrent.futures import ProcessPoolExecutor
from typing import Any, TypeVar

from adpart.params import Param, build_settings, setting, settings, settings_params

T = TypeVar("T")
R = TypeVar("R")


class Executor(ABC):
    """The executor contract: ``with Executor(**params) as ex: results = ex.map(fn, items)``.

    ``fn`` must be a module-level function and ``items`` plain data, so that process-based
    executors can send them to workers. Results come back in the order of ``items``.
    """

    name: str = ""
    description: str = ""
    params: tuple[Param, ...] = ()
    #: whether items may run at once in other processes (work is then split into chunks)
    parallel: bool = True

    @abstractmethod
    def map(self, fn: Callable[[T], R], items: Iterable[T]) -> list[R]:
        """``[fn(item) for item in items]``, possibly computed in parallel, in order."""

    def close(self) -> None:
        """Release workers (idempotent); executors without workers have nothing to release."""
        self._closed = True

    def __enter__(self) -> Executor:  # noqa: PYI034 (Self needs Python 3.11)
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class SerialExecutor(Executor):
    name = "serial"
    description = "runs every item in this process, one after another (debugging, small jobs)"
    parallel = False

    def map(self, fn: Callable[[T], R], items: Iterable[T]) -> list[R]:
        return [fn(item) for item in items]


@settings
class PoolSettings:
    """The local executor's process pool."""

    workers: int = setting(0, min=0, max=4096)
    """Worker processes (0: one per core)."""


class LocalExecutor(Executor):
    name = "local"
    description = "a pool of worker processes on this machine, one per core by default"
    params = settings_params(PoolSettings)

    def __init__(self, **values: Any) -> None:
        self.settings = build_settings(PoolSettings, values)
        self.workers = self.settings.workers or os.cpu_count() or 1
        self._pool: ProcessPoolExecutor | None = None

    def _get_pool(self) -> ProcessPoolExecutor:
        if self._pool is None:
            # forkserver: workers fork from a clean server process, not from a parent that may
            # hold threads (BLAS, numba), and still start far faster than with spawn.
            method = (
                "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"
            )
            context = multiprocessing.get_context(method)
            self._pool = ProcessPoolExecutor(
                max_workers=self.workers, mp_context=context, initializer=one_thread_per_worker)
        return self._pool

    def map(self, fn: Callable[[T], R], items: Iterable[T]) -> list[R]:
        batch = list(items)
        if len(batch) <= 1 or self.workers == 1:
            return [fn(item) for item in batch]
        return list(self._get_pool().map(fn, batch))

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None


#: Thread settings of every worker process (the local pool's and Ray's): the workers already
#: fill the cores, so a worker's numba / OpenMP / BLAS threads would only compete with the other
#: workers (on Ray a cell measured 0.28 s with numba's default of one thread per core, 0.09 s
#: with one).
WORKER_THREAD_ENV: dict[str, str] = {
    "NUMBA_NUM_THREADS": "1",
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
}


def one_thread_per_worker() -> None:
    """Give this worker process one numba, OpenMP and BLAS thread: the workers fill the cores.

    The environment (:data:`WORKER_THREAD_ENV`) covers the libraries the worker has not loaded
    yet. Those it has loaded read it too early: a forkserver preloads the driver's ``__main__``,
    so a script that imports adpart (and with it numba and numpy) at the top hands every worker
    numba with one thread per core and BLAS's own pool (a sweep cell measured 3-10x slower under
    load). For them the limits are set in place: ``numba.set_num_threads(1)`` (numba's thread
    count of this thread, the one the pool runs tasks on; ``NUMBA_NUM_THREADS`` then stays what
    numba read, its pool's size) and threadpoolctl's limit on every loaded BLAS and OpenMP
    library.
    """
    os.environ.update(WORKER_THREAD_ENV)
    numba = sys.modules.get("numba")
    if numba is not None:
        # numba re-reads its variables whenever it compiles and refuses a thread count other
        # than the one its pool was sized by: keep the one it read at import
        os.environ["NUMBA_NUM_THREADS"] = str(numba.config.NUMBA_NUM_THREADS)
        numba.set_num_threads(1)
    if "numpy" in sys.modules or "scipy" in sys.modules:
        from threadpoolctl import threadpool_limits

        threadpool_limits(1)


def worker_threads(_item: object = None) -> dict[str, object]:
    """This process's thread settings: numba's count, each loaded BLAS/OpenMP library's, and
    the environment's (what :func:`one_thread_per_worker` sets). Takes (and ignores) an item,
    so that ``executor.map(worker_threads, range(n))`` asks n tasks (tests, benchmarks)."""
    import numba
    from threadpoolctl import threadpool_info

    return {"numba": numba.get_num_threads(),
            "pools": sorted({int(p["num_threads"]) for p in threadpool_info()}),
            "env": {k: os.environ.get(k) for k in WORKER_THREAD_ENV}}


def run_with(executor: Executor, fn: Callable[[Any], Any], items: Iterable[Any]) -> list[Any]:
    """Map on ``executor`` and close it afterwards."""
    with executor:
        return executor.map(fn, items)

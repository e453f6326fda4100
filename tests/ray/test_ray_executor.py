"""The Ray executor on a local 2-CPU cluster: order, shared arrays, errors, addresses."""

from __future__ import annotations

import time

import numpy as np
import pytest

pytest.importorskip("ray")

from adpart.execution.ray import ClusterError, RayExecutor


def _slow_square(x: int) -> int:
    time.sleep(0.05 * (4 - x))  # later items finish first
    return x * x


def _inspect(item: dict) -> tuple[int, bool, float]:
    a = item["a"]
    return item["i"], bool(a.flags.writeable), float(a.sum())


def _fail(x: int) -> int:
    if x == 2:
        raise ValueError(f"bad item {x}")
    return x


def test_ray_executor_passes_the_executor_conformance_check(ray_cluster):
    from adpart.testing import check_executor

    check_executor(RayExecutor)


def test_ray_map_returns_results_in_order(ray_cluster):
    with RayExecutor() as ex:
        assert ex.map(_slow_square, range(5)) == [0, 1, 4, 9, 16]
        assert sorted(ex.imap_unordered(_slow_square, range(4))) == [(0, 0), (1, 1), (2, 4), (3, 9)]
    assert ray_cluster.is_initialized(), "an executor must not shut down a Ray it did not start"


def test_ray_shared_array_is_put_once_and_read_zero_copy(ray_cluster, monkeypatch):
    puts = []
    real_put = ray_cluster.put
    monkeypatch.setattr(ray_cluster, "put", lambda v: puts.append(v.nbytes) or real_put(v))
    big = np.arange(100_000, dtype=np.float64)  # 800 kB: shared through the object store
    with RayExecutor() as ex:
        out = ex.map(_inspect, [{"a": big, "i": i} for i in range(4)])
    assert puts == [big.nbytes]
    assert [o[0] for o in out] == [0, 1, 2, 3]
    # read-only in the worker: a zero-copy view of the object store, not a per-task copy
    assert not any(o[1] for o in out)
    assert all(o[2] == float(big.sum()) for o in out)


def test_ray_task_exception_keeps_its_type(ray_cluster):
    with RayExecutor() as ex, pytest.raises(ValueError, match="bad item 2"):
        ex.map(_fail, range(4))


def test_ray_unreachable_address_names_address_and_fix():
    with pytest.raises(ClusterError, match=r"127\.0\.0\.1:1'.*ray start --head"):
        RayExecutor(address="127.0.0.1:1").connect()


def test_ray_malformed_address_is_explained():
    with pytest.raises(ClusterError, match="not host:port"):
        RayExecutor(address="no-port-here").connect()


def _thread_settings(_: int) -> tuple[str | None, int]:
    import os

    import numba

    return os.environ.get("NUMBA_NUM_THREADS"), numba.config.NUMBA_NUM_THREADS


def test_ray_workers_get_the_local_pools_thread_settings(ray_cluster):
    from adpart.execution import WORKER_THREAD_ENV

    with RayExecutor() as ex:
        results = ex.map(_thread_settings, [0, 1])
    assert results == [(WORKER_THREAD_ENV["NUMBA_NUM_THREADS"], 1)] * 2

"""A 40-cell sweep on the ``local`` process pool and on ``ray``: wall times and overhead ratio.

The grid is 2 environments (two-rooms, four-rooms) x 4 step sizes x 5 seeds, 4 runs of 300
episodes per cell, each stored in a fresh knowledge base by the driver. Measured in one process:

* **serial**: the sweep in this process - the per-cell compute time ``t_cell`` and the driver's
  per-cell knowledge-base write time ``t_store`` (wall minus compute), for docs/scale-out.md;
* **cold**: executor created, sweep run, executor closed - includes starting the pool or the
  local Ray and each worker's first import of adpart (and numba's cache load);
* **warm**: the same sweep again into a fresh knowledge base on the already-running executor
  (best of two).

The target is Ray within 1.3x of the local pool (warm, on this machine's cores). Ray is started
with ``num_cpus`` = the local pool's worker count so both use the same cores.
"""

from __future__ import annotations

import os
import tempfile
import time
from dataclasses import asdict
from pathlib import Path

from adpart.execution import Executor, LocalExecutor
from adpart.store import KnowledgeBase
from adpart.workflows.sweep import parse_config, plan_cells, run_cell, run_sweep

CONFIG = {
    "name": "bench",
    "runs": 4,
    "episodes": 300,
    "eval_every": 10,
    "seeds": 5,
    "environments": ["two-rooms", "four-rooms"],
    "params": {"alpha": ["0.1", "0.3", "0.5", "1/n^0.8"]},
}
TARGET_RATIO = 1.3
N_NOOP = 500
WARM_REPEATS = 2


class StreamingLocalExecutor(LocalExecutor):
    """The local pool with ``imap_unordered`` (results as they finish), as proposed for
    :class:`~adpart.execution.LocalExecutor`: the sweep driver then stores each cell while the
    workers go on, as it does with Ray, instead of waiting for chunks of ``map``."""

    def imap_unordered(self, fn, items):  # type: ignore[no-untyped-def]
        from concurrent.futures import as_completed

        futures = {self._get_pool().submit(fn, item): i for i, item in enumerate(items)}
        try:
            for future in as_completed(futures):
                yield futures[future], future.result()
        finally:
            for future in futures:
                future.cancel()


def _noop(x: int) -> int:
    return x


def _sweep(cells: list, executor: Executor | None, root: Path, label: str) -> float:
    start = time.perf_counter()
    with KnowledgeBase.open(root / label) as kb:
        report = run_sweep(cells, kb, executor)
    if report.count("stored") != len(cells):
        raise RuntimeError(f"{label}: only {report.count('stored')} of {len(cells)} stored")
    return time.perf_counter() - start


def _timed(executor_factory, cells: list, root: Path, label: str) -> tuple[float, float]:
    """(cold, warm) wall seconds of the sweep on a fresh executor; warm is the best of
    :data:`WARM_REPEATS` (the machine may be shared)."""
    start = time.perf_counter()
    executor = executor_factory()
    with executor:
        _sweep(cells, executor, root, f"{label}-cold")
        cold = time.perf_counter() - start
        warm = min(_sweep(cells, executor, root, f"{label}-warm{i}") for i in range(WARM_REPEATS))
    return cold, warm


def main() -> dict[str, float]:
    """Run the benchmark, print the figures and return them (seconds and ratios)."""
    cells = plan_cells(parse_config(CONFIG))
    workers = os.cpu_count() or 1
    figures: dict[str, float] = {"cells": len(cells), "workers": workers}
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        run_cell({"key": cells[0].key, "request": asdict(cells[0].request)})  # numba warm-up
        start = time.perf_counter()
        with KnowledgeBase.open(root / "serial") as kb:
            report = run_sweep(cells, kb)
        serial = time.perf_counter() - start
        figures.update(
            serial=serial,
            t_cell=sum(r.seconds or 0.0 for r in report.results) / len(cells),
            t_store=sum(r.store_seconds or 0.0 for r in report.results) / len(cells),
        )
        figures["local_cold"], figures["local_warm"] = _timed(
            lambda: LocalExecutor(workers=workers), cells, root, "local"
        )
        figures["stream_cold"], figures["stream_warm"] = _timed(
            lambda: StreamingLocalExecutor(workers=workers), cells, root, "stream"
        )
        try:
            from adpart.execution.ray import RayExecutor, import_ray

            import_ray()
        except ImportError:
            print("ray is not installed: pip install 'adpart[ray]'; skipping the ray figures")
        else:
            figures["ray_cold"], figures["ray_warm"] = _timed(
                lambda: RayExecutor(num_cpus=workers), cells, root, "ray"
            )
            with RayExecutor(num_cpus=workers) as ex:
                ex.map(_noop, range(10))
                start = time.perf_counter()
                ex.map(_noop, range(N_NOOP))
                figures["ray_task_ms"] = (time.perf_counter() - start) / N_NOOP * 1e3
            figures["ratio_warm"] = figures["ray_warm"] / figures["local_warm"]
            figures["ratio_cold"] = figures["ray_cold"] / figures["local_cold"]
            figures["ratio_stream_warm"] = figures["ray_warm"] / figures["stream_warm"]
            figures["ratio_stream_cold"] = figures["ray_cold"] / figures["stream_cold"]
    load = os.getloadavg()[0]
    figures["load"] = load
    print(f"{len(cells)} cells (4 runs x 300 episodes each), {workers} workers, "
          f"load average {load:.1f} at the end (above {workers} means a shared, noisy machine)")
    print(f"serial in-process : {figures['serial']:7.2f} s   per cell: compute "
          f"{figures['t_cell'] * 1e3:.0f} ms, driver KB write {figures['t_store'] * 1e3:.0f} ms")
    print(f"local pool        : cold {figures['local_cold']:7.2f} s   warm "
          f"{figures['local_warm']:7.2f} s")
    print(f"local, streaming  : cold {figures['stream_cold']:7.2f} s   warm "
          f"{figures['stream_warm']:7.2f} s   (proposed LocalExecutor.imap_unordered)")
    if "ray_warm" in figures:
        print(f"ray (local)       : cold {figures['ray_cold']:7.2f} s   warm "
              f"{figures['ray_warm']:7.2f} s   ({figures['ray_task_ms']:.2f} ms per no-op task)")
        for key, label in (("ratio", "ray / local"), ("ratio_stream", "ray / streaming")):
            verdict = "within" if figures[f"{key}_warm"] <= TARGET_RATIO else "OVER"
            print(f"{label:<18}: cold {figures[f'{key}_cold']:.2f}x   warm "
                  f"{figures[f'{key}_warm']:.2f}x ({verdict} the {TARGET_RATIO}x target warm)")
    return figures


if __name__ == "__main__":
    main()

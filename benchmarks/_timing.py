"""Timing shared by the benchmarks."""

from __future__ import annotations

import time
from collections.abc import Callable


def interleaved_best(fns: dict[str, Callable[[], object]], repeats: int) -> dict[str, float]:
    """Best wall time of each function, running them in turn ``repeats`` times (so that a
    slow moment of a shared machine hits every contender alike)."""
    best = dict.fromkeys(fns, float("inf"))
    for _ in range(repeats):
        for name, fn in fns.items():
            start = time.perf_counter()
            fn()
            best[name] = min(best[name], time.perf_counter() - start)
    return best


def interleaved_best_both(fns: dict[str, Callable[[], object]], repeats: int
                          ) -> dict[str, tuple[float, float]]:
    """Best (wall, CPU) time of each function, run in turn ``repeats`` times as
    :func:`interleaved_best` does. The CPU time (``time.process_time``: this process only) is the
    steadier measure of single-threaded work on a machine shared with other jobs, whose load
    adds waiting to the wall time of one contender and not the other."""
    best = {name: (float("inf"), float("inf")) for name in fns}
    for _ in range(repeats):
        for name, fn in fns.items():
            wall, cpu = time.perf_counter(), time.process_time()
            fn()
            wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
            best[name] = (min(best[name][0], wall), min(best[name][1], cpu))
    return best

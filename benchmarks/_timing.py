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


def interleaved_times(fns: dict[str, Callable[[], object]], repeats: int
                      ) -> dict[str, list[tuple[float, float]]]:
    """Every (wall, CPU) time of each function, run in turn ``repeats`` times as
    :func:`interleaved_best` does. The CPU time (``time.process_time``: this process only) is the
    steadier measure of single-threaded work on a machine shared with other jobs, whose load
    adds waiting to the wall time of one contender and not the other."""
    times: dict[str, list[tuple[float, float]]] = {name: [] for name in fns}
    for _ in range(repeats):
        for name, fn in fns.items():
            wall, cpu = time.perf_counter(), time.process_time()
            fn()
            times[name].append((time.perf_counter() - wall, time.process_time() - cpu))
    return times


def interleaved_best_both(fns: dict[str, Callable[[], object]], repeats: int
                          ) -> dict[str, tuple[float, float]]:
    """Best (wall, CPU) time of each function over :func:`interleaved_times`."""
    return {name: (min(w for w, _ in got), min(c for _, c in got))
            for name, got in interleaved_times(fns, repeats).items()}

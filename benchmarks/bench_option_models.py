"""Exact option models (one sparse LU per option) against iterating the option's Bellman equations.

Workloads:

* ``three-floor-arm`` (3,600 states, 10 actions, task ``deliver``): an option to every
  non-terminal doorway and stair state (the hand-designed subgoals, basin initiation sets).
* ``random_grid_mdp(100_000, gamma=0.95, slip=0.2, seed=0)``: options to 4 subgoal cells (the
  centres of the grid's quadrants), basin initiation sets (each basin is a large part of the grid).

Figures: time to build the options (pseudo-reward value iteration, not part of the comparison);
time for the exact models of all options (``option_models``: LU of ``I - gamma P_pi C`` for R and
F, serial, duration off, as the reference computes no duration), the same through a
``LocalExecutor`` of 2 workers - cold (the first call starts the pool: forkserver, each worker's
import of adpart and the model shipped to it) and warm (a second call on the running pool) - and
the reference ``option_model_by_iteration`` (``R`` and ``F``
iterated from zero until the contraction bound ``gamma/(1-gamma) * change < 1e-10``); the ratio
reference / exact; and the largest difference between the two models.
"""

from __future__ import annotations

import time

import numpy as np

from adpart.envs.registry import get_domain
from adpart.execution import LocalExecutor
from adpart.mdp.generate import grid_shape, random_grid_mdp
from adpart.mdp.model import FiniteMDP
from adpart.options import (
    Option,
    option_model_by_iteration,
    option_models,
    subgoal_options,
)


def _timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def compare(label: str, mdp: FiniteMDP, options: list[Option], build_s: float) -> None:
    exact, t_exact = _timed(lambda: option_models(mdp, options, duration=False))
    with LocalExecutor(workers=2) as ex:
        _, t_par = _timed(lambda: option_models(mdp, options, executor=ex, duration=False))
        _, t_warm = _timed(lambda: option_models(mdp, options, executor=ex, duration=False))
    t0 = time.perf_counter()
    iters, diff = [], 0.0
    for o, m in zip(options, exact, strict=True):
        ref, it = option_model_by_iteration(mdp, o, tol=1e-10)
        iters.append(it)
        diff = max(diff, float(np.abs(ref.R - m.R).max()), float(abs(ref.F - m.F).max()))
    t_iter = time.perf_counter() - t0
    sizes = [int(o.initiation.sum()) for o in options]
    print(f"{label}: {mdp.n_states} states, {len(options)} options, |I| {min(sizes)}-{max(sizes)} "
          f"(mean {np.mean(sizes):.0f}); building the options {build_s:.2f} s")
    print(f"  exact (LU, serial)        {t_exact:8.3f} s")
    print(f"  exact (LU, 2 workers)     {t_par:8.3f} s cold (x{t_par / t_exact:.2f} serial: "
          f"includes starting the pool), {t_warm:8.3f} s warm (x{t_warm / t_exact:.2f} serial)")
    print(f"  Bellman iteration         {t_iter:8.3f} s  ({int(np.mean(iters))} iterations on "
          f"average)")
    print(f"  ratio iteration / LU      {t_iter / t_exact:8.1f}x   max |difference| {diff:.1e}")


def main() -> None:
    mdp = get_domain("three-floor-arm").mdp()
    hubs = ((mdp.features["door"] == 1) | (mdp.features["stair"] == 1)) & ~mdp.terminal
    options, t_build = _timed(lambda: subgoal_options(mdp, np.flatnonzero(hubs)))
    compare("three-floor-arm", mdp, options, t_build)

    n = 100_000
    grid = random_grid_mdp(n, gamma=0.95, slip=0.2, seed=0)
    h, w = grid_shape(n)
    centres = [(r * h // 4) * w + (c * w // 4) for r in (1, 3) for c in (1, 3)]
    options, t_build = _timed(lambda: subgoal_options(grid, np.array(centres)))
    compare("random grid 10^5", grid, options, t_build)


if __name__ == "__main__":
    main()

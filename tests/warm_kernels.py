"""Fill numba's on-disk cache before the suite: ``python -m tests.warm_kernels [PART...]``.

Every kernel is compiled with ``cache=True``; its machine code is written to the ``__pycache__``
folder beside its source and every later process - each test worker, each subprocess a test
starts, each ``adpart`` command a user runs - loads it instead of compiling. In a fresh clone the
cache is empty, and the two pytest workers would each compile the same kernels at the same time
(about a minute of CPU each). ``make test`` runs this module first, its two halves in parallel
(one per core), so every kernel is compiled once. It calls the library's own entry points on small
problems, so the cache holds what the library compiles anyway; a kernel or signature it misses is
simply compiled by the first test that needs it, as before.

``learning``: flat and SMDP Q-learning (interpreted and compiled, both kernels' signatures), the
exact solvers they evaluate with. ``structure``: the exact solvers, subgoal discovery (exhaustive
and Monte Carlo walkers), exact lumping and delta refinement, on models with int64 and int32
sparse indices, then hierarchical learning on its decision layer.
"""

from __future__ import annotations

import sys
import time


def learning() -> None:
    from tests.learning.reference_cases import CASES

    for name, (learn, kernels) in CASES.items():
        if name == "hierarchical_goal_grid":
            continue
        for kernel in kernels:
            learn(kernel)
    from adpart.learning.model_based import known_dynamics_learning
    from adpart.learning.settings import Run
    from adpart.mdp.generate import random_grid_mdp

    known_dynamics_learning(random_grid_mdp(9, seed=0), Run(runs=1, episodes=1, kernel="numba"))
    from adpart.learning.sf_gpi import sf_gpi_learning

    sf_gpi_learning(random_grid_mdp(9, seed=0), Run(runs=1, episodes=1, kernel="numba"))


def structure() -> None:
    import numpy as np

    from adpart.envs.registry import get_domain
    from adpart.mdp.evaluation import GREEDY_COMPILED_ROWS, greedy_policy, policy_evaluation
    from adpart.mdp.solvers import modified_policy_iteration, solve, value_iteration
    from adpart.options import doorway_options, option_models
    from adpart.partition import Partition, exact_lumping, refine
    from adpart.subgoals import discover_exhaustive, discover_monte_carlo, sample_arrivals
    from tests.learning.conftest import slippery_grid
    from tests.learning.reference_cases import CASES

    # registry domains index their sparse rows with int64, scipy-built models with int32
    for mdp in (get_domain("two-rooms").mdp(), slippery_grid()):
        policy = solve(mdp).policy
        value_iteration(mdp, 1e-4)
        modified_policy_iteration(mdp, 1e-4, evaluation_sweeps=5)
        policy_evaluation(mdp, policy)
        discover_exhaustive(mdp, policy, np.random.default_rng(0))  # truncates a looping policy
        discover_monte_carlo(mdp, policy, np.random.default_rng(0))
        sample_arrivals(mdp, policy, 100, np.random.default_rng(0))
        smdp = mdp.as_smdp()
        exact_lumping(smdp)
        refine(Partition.trivial(smdp.admissible), smdp, delta=0.1)
    greedy_policy(np.zeros((GREEDY_COMPILED_ROWS, 4)))
    three_floor = get_domain("three-floor").mdp()
    option_models(three_floor, doorway_options(three_floor)[:2])
    # last: by now the learning half has usually cached the SMDP kernel this shares
    CASES["hierarchical_goal_grid"][0]("numba")


PARTS = {"learning": learning, "structure": structure}


def main(argv: list[str]) -> int:
    for name in argv or list(PARTS):
        start = time.perf_counter()
        PARTS[name]()
        print(f"numba cache: {name} kernels ready in {time.perf_counter() - start:.1f} s",
              flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

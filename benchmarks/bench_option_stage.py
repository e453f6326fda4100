"""The option stage with local initiation sets against the whole basins, in one run.

Builds options to the same subgoals (the count metric's on the source task's optimal policy) with
``initiation="local"`` (the default) and ``"basin"`` (the default before), computes their exact
models, and prints the time of each and the ratio local / basin. Issue target: the option stage
stays within 1.2x of the basin version.
"""

from __future__ import annotations

import time

import numpy as np


def _stage(mdp, subgoals, initiation: str) -> tuple[float, float, list[int]]:
    from adpart.options.models import option_models
    from adpart.options.subgoal_options import subgoal_options

    t0 = time.perf_counter()
    options = subgoal_options(mdp, subgoals, initiation=initiation)
    t1 = time.perf_counter()
    option_models(mdp, options, duration=False)
    t2 = time.perf_counter()
    return t1 - t0, t2 - t1, [int(o.initiation.sum()) for o in options]


def main() -> None:
    from adpart.envs.registry import get_domain
    from adpart.mdp.solvers import solve
    from adpart.subgoals import discover_exhaustive

    cases = [("three-floor", "reach-goal", "reach-top-west"),
             ("three-floor-arm", None, None),
             ("urban", None, None)]
    print(f"{'domain':<16} {'options':>7} {'|I| local':>14} {'|I| basin':>14} "
          f"{'local s':>8} {'basin s':>8} {'local/basin':>11}")
    for name, first, new in cases:
        domain = get_domain(name)
        src, mdp = domain.mdp(first), domain.mdp(new)
        found = discover_exhaustive(src, solve(src).policy, np.random.default_rng(0))
        subgoals = found.subgoals[~mdp.terminal[found.subgoals]]
        _stage(mdp, subgoals[:1], "local")  # warm caches and compiled kernels
        times, sizes = {}, {}
        for init in ("local", "basin"):
            build, models, size = _stage(mdp, subgoals, init)
            times[init], sizes[init] = build + models, size
        print(f"{name:<16} {subgoals.size:>7} "
              f"{min(sizes['local']):>6}-{max(sizes['local']):<7} "
              f"{min(sizes['basin']):>6}-{max(sizes['basin']):<7} "
              f"{times['local']:>8.2f} {times['basin']:>8.2f} "
              f"{times['local'] / times['basin']:>11.2f}")


if __name__ == "__main__":
    main()

"""Scoring inside the option learners: the warm-started start-value solver against one LU each.

The layer learner (``hierarchical_learning``) and SMDP Q score each evaluation's greedy policies
exactly. They used to solve one sparse LU per distinct policy per evaluation
(``curves.start_values``); they now use ``curves.StartValues``, Q-learning's scorer: a policy
seen before is a look-up, a new one is solved on the states it reaches from the start, warm-started
from the last policy solved, within 1e-10 (docs/learning.md, "Scoring by what is asked").

Workload: three-floor ``reach-top-west`` on ``bench_hierarchical``'s eight-doorway layer, 20 runs x
200 episodes, alpha = 1, scored every episode (the pipeline's ``--eval-every 1``, as ``make demo``
and the comparisons run), seed 0. Reference: the same call with the scorer replaced by one LU per
distinct policy, alternated in the same rounds; the learned Q must be identical and the curves
agree within 1e-9. Printed: best wall seconds of each, the ratio, the largest value difference.

Run with ``python -m benchmarks layer_scoring``.
"""

from __future__ import annotations

import time

import numpy as np

from adpart.learning import hierarchical
from adpart.learning.curves import StartValues, start_values
from adpart.learning.hierarchical_settings import HierarchicalSettings
from adpart.learning.settings import Run
from adpart.params import build_settings
from benchmarks.bench_hierarchical import workload

RUNS, EPISODES, REPEATS = 20, 200, 2


class LUPerPolicy:
    """The former scorer: one sparse LU per distinct policy at every evaluation."""

    def __init__(self, smdp, mu, runs) -> None:
        self.smdp, self.mu = smdp, mu

    def __call__(self, policies, changed):
        return start_values(self.smdp, policies, self.mu)


def main(runs: int = RUNS, episodes: int = EPISODES, repeats: int = REPEATS) -> dict[str, float]:
    """Run the benchmark, print the figures and return them."""
    mdp, opts, models, part = workload()
    settings = build_settings(HierarchicalSettings, {"delta": 0.3, "partition_epsilon": 10.0})
    run = Run(runs=runs, episodes=episodes, seed=0, eval_every=1, alpha=1.0,
              max_steps_per_episode=5800)
    best: dict[str, float] = {}
    results = {}
    for _ in range(repeats):
        for name, scorer in (("StartValues", StartValues), ("LU per policy", LUPerPolicy)):
            hierarchical.StartValues = scorer
            try:
                start = time.perf_counter()
                results[name] = hierarchical.hierarchical_learning(mdp, opts, part, settings,
                                                                   run, models)
                best[name] = min(best.get(name, np.inf), time.perf_counter() - start)
            finally:
                hierarchical.StartValues = StartValues
    fast, slow = results["StartValues"], results["LU per policy"]
    assert np.array_equal(fast.Q, slow.Q), "scoring changed what was learned"
    diff = float(np.nanmax(np.abs(fast.curve["eval_value"] - slow.curve["eval_value"])))
    ratio = best["StartValues"] / best["LU per policy"]
    print(f"bench_layer_scoring: three-floor reach-top-west, {part.n_blocks}-block doorway "
          f"layer, {runs} runs x {episodes} episodes, scored every episode; best of {repeats}")
    print(f"  StartValues {best['StartValues']:.2f} s, LU per policy "
          f"{best['LU per policy']:.2f} s: ratio {ratio:.3f}; largest |eval_value difference| "
          f"{diff:.1e} (must be <= 1e-9: {diff <= 1e-9})")
    return {"start_values_s": best["StartValues"], "lu_s": best["LU per policy"],
            "ratio": ratio, "max_difference": diff}


if __name__ == "__main__":
    main()

"""Throughput of the hierarchical learner: the refinement rules against each other, same run.

The workload is three-floor ``reach-top-west`` (-1 a step) on the decision layer of eight doorway
options (δ = 0.3, ε = 10, the layer ``tests/learning/test_hierarchical.py`` measures soundness on),
20 runs x 300 episodes, α = 1, step cap 5,800, seed 0, after one warm-up call per rule that
compiles the kernel. The rules:

* ``state`` + ``until-reward`` - the defaults: an added action joins the firing state alone,
  epsilon-exploration over the primitives until the first reward;
* ``block`` + ``never`` - the former defaults (the same kernel path as before that change: the
  pinned reference curves check it bit for bit);
* ``reward-variation+inconsistency`` - the pipeline's default mode: the learner builds its own
  layer from the doorway options plus the task's reward states, and tests against the
  ``offered`` reference. That layer's construction (``decision_layer`` over the extended option
  set, exact models included) is timed alone too and taken out of its rates, since the other
  rules get their layer ready-made.

The rules run interleaved, ``REPEATS`` rounds, so a change of load on a shared machine hits every
rule of a round alike. Printed per rule: wall seconds of its best round (learning, refinements and
the exact scoring every 50 episodes), primitive steps and decisions per second, firings, final
blocks; then the ratios to the former rule per round, as median [min, max]. Steps per second is
the issue's throughput figure; a rule that needs fewer steps to learn may still take longer per
step, since every firing re-partitions a block.

Run with ``python -m benchmarks hierarchical``.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from adpart.envs.registry import get_domain
from adpart.learning.decision_layer import reward_options
from adpart.learning.hierarchical import decision_layer, hierarchical_learning
from adpart.learning.hierarchical_settings import HierarchicalSettings
from adpart.learning.settings import Run
from adpart.options import option_models, subgoal_options
from adpart.params import build_settings

RUNS, EPISODES, REPEATS = 20, 300, 5
DOORWAYS = [187, 545, 843, 1262, 1495, 2146, 2508, 2846]
RULES = {"defaults (state, until-reward)": {},
         "former (block, never)": {"refine": "block", "primitive_exploration": "never"},
         "pipeline (reward-var.+incons.)": {"mode": "reward-variation+inconsistency"}}


def workload():
    mdp = get_domain("three-floor").mdp("reach-top-west")
    opts = subgoal_options(mdp, DOORWAYS, cover=True)
    models = option_models(mdp, opts, duration=False)
    part, _, _ = decision_layer(mdp, opts, delta=0.3, epsilon=10.0, models=models)
    return mdp, opts, models, part


def _layer_seconds(mdp, opts, models) -> float:
    """Best-of-``REPEATS`` time of the reward-variation mode's own layer build."""
    best = np.inf
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        extra = reward_options(mdp)
        decision_layer(mdp, [*opts, *extra], delta=0.3, epsilon=10.0,
                       models=[*models, *option_models(mdp, extra, duration=False)])
        best = min(best, time.perf_counter() - t0)
    return best


def measure(mdp, opts, models, part, rules: dict[str, dict], *, runs: int = RUNS,
            episodes: int = EPISODES) -> dict[str, dict[str, object]]:
    """Each rule's learning call timed ``REPEATS`` times, the rules interleaved (a load change
    on the shared machine then hits every rule of a round alike), with its counts."""
    calls = {}
    for name, rule in rules.items():
        settings = build_settings(HierarchicalSettings,
                                  {"delta": 0.3, "partition_epsilon": 10.0, **rule})
        run = Run(runs=runs, episodes=episodes, seed=0, eval_every=50, alpha=1.0,
                  max_steps_per_episode=5800)
        # the reward-variation modes build their own layer, inside the call as the pipeline runs it
        layer = None if settings.reward_options else part
        hierarchical_learning(mdp, opts, layer, settings,  # compile
                              replace(run, runs=1, episodes=2), models)
        calls[name] = (layer, settings, run)
    times: dict[str, list[float]] = {name: [] for name in rules}
    results = {}
    for _ in range(REPEATS):
        for name, (layer, settings, run) in calls.items():
            t0 = time.perf_counter()
            results[name] = hierarchical_learning(mdp, opts, layer, settings, run, models)
            times[name].append(time.perf_counter() - t0)
    build = _layer_seconds(mdp, opts, models)
    rows = {}
    for name, (layer, _, _) in calls.items():
        res = results[name]
        own = build if layer is None else 0.0  # taken out: the other rules get theirs ready-made
        learn = np.asarray(times[name]) - own
        steps = float(res.curve.matrix("steps").sum())
        decisions = float(res.curve.matrix("decisions").sum())
        rows[name] = {"seconds": min(times[name]), "layer_seconds": own,
                      "steps_per_s": steps / learn.min(),
                      "decisions_per_s": decisions / learn.min(),
                      "round_steps_per_s": steps / learn,
                      "round_decisions_per_s": decisions / learn,
                      "firings": float(len(res.refinements)),
                      "final_blocks": float(np.median(res.blocks[:, -1]))}
    return rows


def main() -> dict[str, dict[str, object]]:
    mdp, opts, models, part = workload()
    print(f"three-floor reach-top-west, {part.n_blocks}-block doorway layer, {RUNS} runs x "
          f"{EPISODES} episodes ({REPEATS} interleaved rounds; rates of the best round)")
    rows = measure(mdp, opts, models, part, RULES)
    for name, r in rows.items():
        print(f"{name:32s} {r['seconds']:7.2f} s  (layer {r['layer_seconds']:.2f} s)  "
              f"{r['steps_per_s'] / 1e6:6.2f} M steps/s  "
              f"{r['decisions_per_s'] / 1e6:6.2f} M decisions/s  {r['firings']:6.0f} firings  "
              f"{r['final_blocks']:6.0f} blocks (median)")
    new, old, pipeline = rows.values()
    for name, r in (("defaults", new), ("pipeline", pipeline)):
        steps = r["round_steps_per_s"] / old["round_steps_per_s"]
        decisions = r["round_decisions_per_s"] / old["round_decisions_per_s"]
        print(f"ratio {name} / former, per round (median [min, max]): steps/s "
              f"{np.median(steps):.2f} [{steps.min():.2f}, {steps.max():.2f}], decisions/s "
              f"{np.median(decisions):.2f} [{decisions.min():.2f}, {decisions.max():.2f}], wall "
              f"{r['seconds'] / old['seconds']:.2f} (best rounds)")
    return rows


if __name__ == "__main__":
    main()

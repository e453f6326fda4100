"""The partition stage before and after partition hygiene, in the same run (issue 15, item 3).

Workloads (the transfer setting of section 5.1: options learned under a first task, the layer
built for a new one). Each has subgoal options with basin initiation sets, built and modelled on
the first task's MDP, as the pipeline stores them:

* ``three-floor`` reach-goal -> reach-top-west, subgoals = the count metric's (exhaustive) on the
  first task's optimal policy;
* ``three-floor-doorways``: the same tasks over the 65 hand-designed subgoals (every doorway and
  stair cell, Fig. 5.1), where the phases, not the option models, take most of the time;
* ``three-floor-arm`` navigate -> deliver, subgoals as for three-floor;
* ``urban`` navigate-2 -> navigate-pickup, the three subgoals (8853, 9402, 15618) that ``count-mc``
  found in a flat-learned navigate-2 policy (seed 0), the setting of the issue's measurement.

Both settings time the same numeric stage: the option models recomputed on the new task's MDP,
phases 1-3 (delta 0.3, epsilon 10) and nothing else (no store, no checker, no value gap):

* **old** - phases 1-2 on the first task's model (stored models; no terminal block, every state
  in), phase 3 on the new task's model with ``R(s, o)`` itself;
* **new** - every phase on the new task's model with its terminal block, the states the task
  cannot reach left out, and eq. 4.7 on the rewards beyond the step reward most pairs pay
  (:mod:`adpart.partition.layer`).

The ratio ``new / old`` of the best of ``repeats`` wall times is printed with the block counts
(the new ones split into reachable / terminal / unreachable).
"""

from __future__ import annotations

import time

import numpy as np

from adpart.envs.registry import get_domain
from adpart.mdp.model import FiniteMDP
from adpart.mdp.solvers import solve
from adpart.options.models import option_models
from adpart.options.smdp import stack_models
from adpart.options.subgoal_options import subgoal_options
from adpart.partition.layer import resolve_baseline
from adpart.partition.multiphase import MultiPhasePartitioner, phase1, phase2, phase3
from adpart.subgoals import discover_exhaustive

DELTA = 0.3
EPSILON = 10.0
WORKLOADS = {
    "three-floor": ("reach-goal", "reach-top-west", None),
    "three-floor-doorways": ("reach-goal", "reach-top-west", "doorways"),
    "three-floor-arm": ("navigate", "deliver", None),
    "urban": ("navigate-2", "navigate-pickup", (8853, 9402, 15618)),
}


def _stack(mdp: FiniteMDP, models: list, options: list) -> tuple:
    """Stacked model and termination mask, primitives offered where no option starts."""
    smdp = stack_models(mdp, models, include_primitives="uncovered")
    A = mdp.n_actions
    term = np.concatenate([np.ones((mdp.n_states, A), dtype=bool),
                           np.stack([o.beta >= 1.0 for o in options], axis=1)], axis=1)
    return smdp, term


def old_stage(source: FiniteMDP, task: FiniteMDP, options: list, models: list) -> dict:
    smdp, term = _stack(source, models, options)
    cols = np.arange(smdp.n_actions)
    p1 = {int(o): phase1(smdp, int(o), term[:, o], delta=DELTA) for o in cols}
    p2 = phase2(smdp, p1, cols, delta=DELTA)
    task_model, _ = _stack(task, option_models(task, options, duration=False), options)
    p3 = phase3(task_model, p2, cols, epsilon=EPSILON, delta=DELTA)
    return {"phase2": p2.n_blocks, "phase3": p3.n_blocks}


def new_stage(task: FiniteMDP, options: list) -> dict:
    task_model, term = _stack(task, option_models(task, options, duration=False), options)
    mp = MultiPhasePartitioner(task_model, term, delta=DELTA, terminal=task.terminal)
    start = (task.initial > 0) & ~task.terminal
    baseline = resolve_baseline("mode", task.R, task.admissible, task.terminal)
    res = mp.run(np.arange(task_model.n_actions), epsilon=EPSILON, start=start, through=task,
                 reward_baseline=baseline, gamma=task.gamma)
    counts = res.layer_counts()
    return {"phase2": counts["phase2"], "phase3": counts["phase3"]}


def _best(fn, repeats: int) -> tuple[float, dict]:
    best, out = np.inf, {}
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def _split(c: dict) -> str:
    return f"{c['blocks']} ({c['reachable']}+{c['terminal']}+{c['unreachable']})"


def main(workloads: tuple[str, ...] = tuple(WORKLOADS), repeats: int = 3) -> dict[str, object]:
    """Print and return old and new seconds, their ratio and the block counts per workload."""
    rows = {}
    print(f"partition stage (option models on the new task + phases 1-3, delta {DELTA}, "
          f"epsilon {EPSILON}); blocks new = total (reachable+terminal+unreachable)")
    print(f"{'workload':>20} {'options':>7} {'old s':>7} {'new s':>7} {'new/old':>7} "
          f"{'old p2':>6} {'old p3':>6} {'new p2':>16} {'new p3':>16}")
    for name in workloads:
        first, new, fixed = WORKLOADS[name]
        domain = get_domain(name.removesuffix("-doorways"))
        source, task = domain.mdp(first), domain.mdp(new)
        if fixed == "doorways":
            feats = source.features
            subgoals = np.flatnonzero((np.asarray(feats["door"]) == 1)
                                      | (np.asarray(feats["stair"]) == 1))
        elif fixed is None:
            found = discover_exhaustive(source, solve(source).policy, np.random.default_rng(0))
            subgoals = found.subgoals
        else:
            subgoals = np.asarray(fixed)
        options = subgoal_options(source, subgoals, initiation="basin")
        models = option_models(source, options, duration=False)
        t_old, old = _best(lambda s=source, t=task, o=options, m=models: old_stage(s, t, o, m),
                           repeats)
        t_new, cur = _best(lambda t=task, o=options: new_stage(t, o), repeats)
        rows[name] = {"options": len(options), "old_s": t_old, "new_s": t_new,
                      "ratio": t_new / t_old, "old": old, "new": cur}
        print(f"{name:>20} {len(options):>7} {t_old:>7.2f} {t_new:>7.2f} {t_new / t_old:>7.2f} "
              f"{old['phase2']:>6} {old['phase3']:>6} {_split(cur['phase2']):>16} "
              f"{_split(cur['phase3']):>16}", flush=True)
    return rows


if __name__ == "__main__":
    main()

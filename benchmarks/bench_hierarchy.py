"""Autonomous hierarchy construction (Algorithm 3, section 4.4) on ``urban`` (20,004 states).

Workload: the five tasks of section 5.2 plus navigation tasks to random cells (``GoalSpec`` goals
``{"x": .., "y": ..}`` from navigate's start, seed 0) up to 20 tasks, each solved exactly; up to
100 options to random non-terminal subgoal cells (``subgoal_options``, initiation ``reachable``).
For every (tasks, options) cell of the grid the table prints:

* ``inputs s`` - building the estimator's inputs: each task's occupancy plus the option values of
  the options used (each measured once per task and option, summed for the cell);
* ``splits s`` - each option's own delta-stable partition (delta 0.3), how "refined with ``o``"
  splits a block (:func:`adpart.hierarchy.layers.stable_option_splits`, measured once per
  option on the first task's model, summed for the cell);
* ``greedy s`` - Algorithm 3 itself (:func:`adpart.hierarchy.greedy_hierarchy`, best of 1);
* ``blocks`` / ``steps`` / ``E0 / E`` - the layer and how far the estimate fell;
* ``naive s`` and ``speed-up`` - the reference measured in the same run: one call of the
  estimator (:func:`adpart.hierarchy.expected_time`, which re-evaluates a whole layer) timed on
  the final layer, times the candidates Algorithm 3 scored - what scoring every candidate by a
  full re-evaluation would cost.
"""

from __future__ import annotations

import time

import numpy as np

from adpart.envs.base import GoalSpec
from adpart.envs.registry import get_domain
from adpart.hierarchy import (
    LearnedTask,
    discounted_occupancy,
    expected_time,
    greedy_hierarchy,
    option_values,
)
from adpart.hierarchy.layers import stable_option_splits
from adpart.hierarchy.settings import EstimateSettings
from adpart.mdp.solvers import q_from_v, solve
from adpart.options import subgoal_options


def _tasks(domain, n: int, rng: np.random.Generator) -> list:
    names: list = list(domain.tasks())[:n]
    base = domain.tasks()["navigate"]
    dyn = domain.dynamics()
    xs, ys = dyn.features["x"], dyn.features["y"]
    cells = np.unique(np.stack([xs, ys], axis=1), axis=0)
    while len(names) < n:
        x, y = cells[rng.integers(len(cells))]
        spec = GoalSpec(goal={"x": int(x), "y": int(y)}, start=base.start, gamma=base.gamma,
                        goal_reward=base.goal_reward, name=f"goal-{x}-{y}")
        names.append(spec)
    return names


def main(task_counts: tuple[int, ...] = (1, 5, 10, 20),
         option_counts: tuple[int, ...] = (10, 50, 100), seed: int = 0) -> list[dict]:
    rng = np.random.default_rng(seed)
    domain = get_domain("urban")
    specs = _tasks(domain, max(task_counts), rng)
    first = domain.mdp(specs[0])
    S, A = first.n_states, first.n_actions
    t0 = time.perf_counter()
    goals = rng.choice(np.flatnonzero(~first.terminal), max(option_counts), replace=False)
    options = subgoal_options(first, goals, initiation="reachable")
    print(f"urban: {S:,} states, {A} actions; {len(options)} options built in "
          f"{time.perf_counter() - t0:.1f} s")
    Qs, occ, opt_s, occ_s, thresholds = [], [], [], [], []
    t0 = time.perf_counter()
    for spec in specs:
        mdp = domain.mdp(spec)
        Q = q_from_v(mdp, solve(mdp).V)
        V = np.where(mdp.terminal, 0.0, Q.max(axis=1))
        t = time.perf_counter()
        d = discounted_occupancy(mdp, np.argmax(Q, axis=1))
        occ_s.append(time.perf_counter() - t)
        per_opt, cols = [], []
        for opt in options:
            t = time.perf_counter()
            cols.append(option_values(mdp, [opt], V)[:, 0])
            per_opt.append(time.perf_counter() - t)
        Qp = np.where(mdp.admissible, Q, -np.inf)
        Qp[mdp.terminal] = -np.inf
        Qo = np.stack(cols, axis=1)
        Qs.append(np.concatenate([Qp, Qo], axis=1))
        occ.append(d)
        opt_s.append(np.asarray(per_opt))
        live = V[~mdp.terminal]
        thresholds.append(0.01 * float(live.max() - live.min()))
    print(f"{len(specs)} tasks solved and their inputs built in {time.perf_counter() - t0:.1f} s")
    adm_all = np.concatenate([first.admissible] + [o.initiation[:, None] for o in options], axis=1)
    term_all = np.concatenate([np.ones((S, A), dtype=bool)]
                              + [(o.beta >= 1.0)[:, None] for o in options], axis=1)
    splits = np.zeros((A + len(options), S), dtype=np.int64)
    split_s = np.zeros(len(options))
    for k, opt in enumerate(options):  # one option at a time, to time each
        cols = [*range(A), A + k]
        t = time.perf_counter()
        one = stable_option_splits(first, [opt], adm_all[:, cols], term_all[:, cols],
                                   delta=EstimateSettings().delta)
        split_s[k] = time.perf_counter() - t
        splits[:A], splits[A + k] = one[:A], one[A]
    print(f"{'tasks':>5} {'options':>7} {'inputs s':>9} {'splits s':>9} {'greedy s':>9} "
          f"{'blocks':>7} "
          f"{'steps':>6} {'E0 / E':>9} {'candidates':>11} {'naive s':>9} {'speed-up':>9}")
    rows = []
    for T in task_counts:
        for n_opt in option_counts:
            K = A + n_opt
            tasks = [LearnedTask(f"t{i}", Qs[i][:, :K], occ[i], thresholds[i])
                     for i in range(T)]
            adm = adm_all[:, :K]
            inputs_s = float(sum(occ_s[:T]) + sum(opt_s[i][:n_opt].sum() for i in range(T)))
            t = time.perf_counter()
            res = greedy_hierarchy(tasks, adm, splits=splits[:K], n_primitives=A, c=1.0)
            greedy_s = time.perf_counter() - t
            t = time.perf_counter()
            expected_time(tasks, res.partition, n_primitives=A, c=1.0)
            one = time.perf_counter() - t
            naive = one * res.candidates_evaluated
            row = {"tasks": T, "options": n_opt, "inputs_s": inputs_s,
                   "splits_s": float(split_s[:n_opt].sum()), "greedy_s": greedy_s,
                   "blocks": res.partition.n_blocks, "steps": len(res.steps),
                   "reduction": res.trace[0] / res.trace[-1],
                   "candidates": res.candidates_evaluated, "naive_s": naive,
                   "speedup": naive / greedy_s}
            rows.append(row)
            print(f"{T:>5} {n_opt:>7} {inputs_s:>9.2f} {row['splits_s']:>9.2f} {greedy_s:>9.2f} "
                  f"{row['blocks']:>7} "
                  f"{row['steps']:>6} {row['reduction']:>9.3g} {row['candidates']:>11,} "
                  f"{naive:>9.1f} {row['speedup']:>9.0f}")
    return rows


if __name__ == "__main__":
    main()

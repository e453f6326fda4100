"""The expected learning time of a decision layer over previously learned tasks (section 4.4).

The dissertation's formulas, with the interpretations adpart commits to (docs/hierarchy.md):

* ``T_conv(P, O) = c |P|^2 |O|`` (the DP-based Q-learning bound it cites). A layer offers a
  different option set ``O_B`` in each block, so adpart counts block-action pairs:
  ``T_conv(P) = c |P| sum_{B in P} max(1, |O_B|)``, which is ``c |P|^2 |O|`` exactly when every
  block offers the same ``|O|`` options. A block offering nothing counts as one action (the
  refinement that is bound to happen there adds one).
* ``E[t_Ti | P] = T_conv(P) + sum_{B_j} P_refine(B_j | T_i) t_conv({B_ik : B_ik meets B_j}, O)``
  with the refinement cost ``c n_ij^2 (|O_Bj| + 1)``: ``n_ij`` task blocks meet ``B_j`` and the
  refinement learns over the block's options plus the action it adds (section 4.3.3).
* ``P_refine(B_j | T_i) = sum_{k: B_ik meets B_j} 1[max_a Q_i(B_ik, a) > max_{a in O_Bj}
  Q_i(B_ik, a) + L] P(B_ik | T_i)``. ``max_a`` runs over every column (primitives and options),
  ``max`` over an empty set is ``-inf`` (a block without options always needs refinement where the
  task goes). ``Q_i(B_ik, a)`` is the occupancy-weighted mean of the task's per-state values
  over ``B_ik`` (the state's own value at the per-state resolution), ``P(B_ik | T_i)`` the
  occupancy of ``B_ik``.
* ``E[t_learn | P] = sum_i U(T_i) / sum_i U(T_i) E[t_Ti | P]``.

``L`` is per task (:attr:`LearnedTask.threshold`); the default built by :mod:`adpart.hierarchy.kb`
is the hierarchical learner's scale-aware threshold, so the estimator predicts the refinements the
learner would make. This module is pure numpy over in-memory inputs: it knows nothing of the store.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from adpart.errors import TaskError
from adpart.hierarchy.tasks import LearnedTask
from adpart.partition.partition import Partition


@dataclass(frozen=True)
class Estimate:
    """``E[t_learn | P]`` with its parts.

    Attributes:
        total: the importance-weighted expected learning time.
        t_conv: ``T_conv(P)``, the same for every task.
        per_task: ``(T,)`` ``E[t_Ti | P]``.
        p_refine: ``(T, B)`` ``P_refine(B_j | T_i)``.
        refine_cost: ``(T, B)`` ``P_refine(B_j | T_i) c n_ij^2 (|O_Bj| + 1)``.
    """

    total: float
    t_conv: float
    per_task: np.ndarray
    p_refine: np.ndarray
    refine_cost: np.ndarray


def check_tasks(tasks: Sequence[LearnedTask], n_states: int, n_columns: int) -> np.ndarray:
    """Validate a task list against a layer's shape; return the normalised weights ``(T,)``."""
    if not tasks:
        raise TaskError("the expected learning time needs at least one learned task")
    for t in tasks:
        if t.Q.shape != (n_states, n_columns):
            raise TaskError(
                f"task {t.name!r} has Q of shape {t.Q.shape}, but the layer covers "
                f"({n_states}, {n_columns}) (states, primitive actions + options); build every "
                "task over the same columns"
            )
    w = np.array([t.weight for t in tasks], dtype=np.float64)
    if w.sum() <= 0:
        raise TaskError("the importance weights U(T_i) sum to 0; give some task a positive weight")
    return w / w.sum()


def t_conv(partition: Partition, c: float = 1.0) -> float:
    """``c |P| sum_B max(1, |O_B|)`` (``= c |P|^2 |O|`` for uniform option sets)."""
    per_block = np.maximum(partition.admissible.sum(axis=1), 1)
    return float(c * partition.n_blocks * per_block.sum())


def good_columns(task: LearnedTask) -> np.ndarray:
    """``(S, K)`` bool: column ``a`` is within ``L`` of the best column (no refinement needed).

    At the per-state resolution ``P_refine(B | {s}, T_i) = 0`` exactly when ``B`` offers a column
    that is good in ``s``; states without any finite value (terminal) count every column as good.
    """
    Q = task.Q
    best = Q.max(axis=1, keepdims=True)
    return (Q >= best - task.threshold) | ~np.isfinite(best)


def _block_values(task: LearnedTask) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Task blocks: ``(labels, Q_blocks (Kb, K), P(B_ik | T_i) (Kb,))``."""
    if task.labels is None:
        S = task.n_states
        return np.arange(S, dtype=np.int64), task.Q, task.occupancy
    lab = np.unique(task.labels, return_inverse=True)[1].reshape(-1)
    n = int(lab.max()) + 1
    d = task.occupancy
    mass = np.bincount(lab, weights=d, minlength=n)
    live = d > 0
    Q = task.Q[live]
    finite = np.isfinite(Q)
    num = np.zeros((n, Q.shape[1]))
    np.add.at(num, lab[live], np.where(finite, Q, 0.0) * d[live, None])
    bad = np.zeros((n, Q.shape[1]), dtype=bool)
    np.logical_or.at(bad, lab[live], ~finite)
    with np.errstate(invalid="ignore", divide="ignore"):
        Qb = num / mass[:, None]
    Qb = np.where(bad | (mass[:, None] <= 0), -np.inf, Qb)
    return lab, Qb, mass


def expected_time(
    tasks: Sequence[LearnedTask], partition: Partition, *, c: float = 1.0
) -> Estimate:
    """``E[t_learn | P]`` of ``partition`` (blocks and per-block columns) over ``tasks``.

    The partition's ``admissible`` table has one column per candidate action, in the tasks'
    column order (primitive actions first, then options). Vectorised over states and blocks; the
    loop runs over tasks.
    """
    if not (np.isfinite(c) and c > 0):
        raise TaskError(f"the constant c = {c!r} of T_conv must be a positive number")
    w = check_tasks(tasks, partition.n_states, partition.n_options)
    B = partition.n_blocks
    n_opts = partition.admissible.sum(axis=1)
    tc = t_conv(partition, c)
    p_ref = np.zeros((len(tasks), B))
    cost = np.zeros((len(tasks), B))
    for i, task in enumerate(tasks):  # loop over tasks; each vectorised over states
        lab, Qb, mass = _block_values(task)
        nb = Qb.shape[0]
        pairs = np.unique(partition.labels * nb + lab)
        blk, tb = pairs // nb, pairs % nb
        offered = partition.admissible[blk]
        best_all = Qb[tb].max(axis=1)
        best_in = np.where(offered, Qb[tb], -np.inf).max(axis=1)
        need = np.isfinite(best_all) & ~(best_in >= best_all - task.threshold)
        p_ref[i] = np.bincount(blk, weights=np.where(need, mass[tb], 0.0), minlength=B)
        n_ij = np.bincount(blk, minlength=B).astype(np.float64)
        cost[i] = p_ref[i] * c * n_ij**2 * (n_opts + 1)
    per_task = tc + cost.sum(axis=1)
    return Estimate(float(w @ per_task), tc, per_task, p_ref, cost)

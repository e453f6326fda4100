"""The expected learning time of a decision layer over previously learned tasks (section 4.4).

The dissertation's formulas, with the interpretations adpart commits to (docs/hierarchy.md):

* ``T_conv(P, O) = c |P|^2 |O|`` (the DP-based Q-learning bound it cites). A layer offers a
  different column set ``O_B`` in each block, so adpart counts block-action pairs:
  ``T_conv(P) = c |P| sum_{B in P} max(1, |O_B|)``, which is ``c |P|^2 |O|`` exactly when every
  block offers the same ``|O|`` columns. A block offering nothing counts as one action.
* ``E[t_Ti | P] = T_conv(P) + sum_{B_j} P_refine(B_j | T_i) t_conv({B_ik : B_ik meets B_j}, O)``.
  The refinement term is ``c n_ij^2 (|O_Bj| + A)``: ``n_ij`` task blocks meet ``B_j`` and the
  refinement learns them over the block's options plus the ``A`` primitive actions the
  hierarchical learner may add there (the dissertation writes the layer's whole action set ``O``;
  primitives join a layer only by refinement, so a refined block may need all of them). With
  this term an inconsistent block costs at least what learning its states flat costs, so a layer
  whose options do not fit the tasks cannot look cheaper than the flat MDP.
* **Commitment.** A block of a decision layer is one abstract state: the policy learned on it
  takes *one* column in all its states. ``P_refine(B_j | B_ik, T_i) = 1`` when
  ``max_a Q_i(B_ik, a) > Q_i(B_ik, o*_ij) + L`` for the block's committed column
  ``o*_ij = argmax_{o in O_Bj} Q_i(B_j, o)``, ``Q_i(B_j, o) = sum_{s in B_j} d_i(s) Q_i(s, o)``
  (the occupancy-weighted value of the block, which is what SMDP Q-learning on the block
  estimates). The seed's ``max_{a in O_Bik}`` (any offered column) made one block offering every
  column as cheap as a split layer; this is the departure. Ties: any column within ``1e-9``
  relative of the block's best counts as committed (the learner may settle on either).
* ``P_refine(B_j | T_i) = sum_k P_refine(B_j | B_ik, T_i) P(B_ik | T_i)``, where ``P(B_ik | T_i)``
  is read as the probability that *learning* ``T_i`` meets ``B_ik``: exploration from the task's
  start distribution meets every state the occupancy reaches (:mod:`adpart.hierarchy.tasks`
  spreads it over all states reachable from the starts), so the probability is 1 for an occupied
  task block and the sum is capped at 1 (a block is refined once). So ``P_refine(B_j | T_i)`` is
  1 when the committed column is not within ``L`` in some occupied state of ``B_j`` (or ``B_j``
  offers nothing where the task goes), else 0.
* ``E[t_learn | P] = sum_i U(T_i) / sum_i U(T_i) E[t_Ti | P]``.
* **No abstraction** is a candidate: the flat MDP (every state a block offering its admissible
  primitive actions) never needs refinement, so ``E[t_learn | flat] = T_conv(flat) = c S
  sum_s |A(s)|`` (:func:`flat_time`).

``L`` is per task (:attr:`LearnedTask.threshold`). This module is pure numpy over in-memory
inputs: it knows nothing of the store.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from adpart.errors import TaskError
from adpart.hierarchy.tasks import LearnedTask
from adpart.partition.partition import Partition

#: Columns whose block value is within this relative margin of the best count as committed.
TIE_RTOL = 1e-9


@dataclass(frozen=True)
class Estimate:
    """``E[t_learn | P]`` with its parts.

    Attributes:
        total: the importance-weighted expected learning time.
        t_conv: ``T_conv(P)``, the same for every task.
        per_task: ``(T,)`` ``E[t_Ti | P]``.
        p_refine: ``(T, B)`` ``P_refine(B_j | T_i)`` (0 or 1).
        refine_cost: ``(T, B)`` ``P_refine(B_j | T_i) c n_ij^2 (|O_Bj| + A)``.
        committed: ``(T, B)`` the committed column of each block per task (-1: none offered or
            the block is unoccupied).
    """

    total: float
    t_conv: float
    per_task: np.ndarray
    p_refine: np.ndarray
    refine_cost: np.ndarray
    committed: np.ndarray


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


def t_conv(partition: Partition, c: float) -> float:
    """``c |P| sum_B max(1, |O_B|)`` (``= c |P|^2 |O|`` for uniform option sets)."""
    per_block = np.maximum(partition.admissible.sum(axis=1), 1)
    return float(c * partition.n_blocks * per_block.sum())


def flat_time(primitive_admissible: np.ndarray, c: float) -> float:
    """``E[t_learn | flat] = c S sum_s max(1, |A(s)|)``: the flat MDP needs no refinement."""
    adm = np.asarray(primitive_admissible, dtype=bool)
    if adm.ndim != 2:
        raise TaskError(f"primitive admissibility must be (S, A); got shape {adm.shape}")
    return float(c * adm.shape[0] * np.maximum(adm.sum(axis=1), 1).sum())


def good_columns(task: LearnedTask) -> np.ndarray:
    """``(S, K)`` bool: column ``a`` is within ``L`` of the best column in the state.

    States without any finite value (terminal) count every column as good.
    """
    Q = task.Q
    best = Q.max(axis=1, keepdims=True)
    return (Q >= best - task.threshold) | ~np.isfinite(best)


def _task_blocks(task: LearnedTask) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Task blocks: ``(labels (S,), Q_blocks (Kb, K), occupancy (S,))``."""
    if task.labels is None:
        return np.arange(task.n_states, dtype=np.int64), task.Q, task.occupancy
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
    return lab, Qb, d


def committed_columns(values: np.ndarray, offered: np.ndarray) -> np.ndarray:
    """``(..., K)`` bool: offered columns whose block value is (within ``TIE_RTOL`` of) the best.

    ``values`` are the blocks' occupancy-weighted column values (``-inf`` where some occupied
    state cannot start the column); a block whose best offered value is ``-inf`` commits to
    nothing.
    """
    v = np.where(offered, values, -np.inf)
    if v.shape[-1] == 0:
        return np.zeros(v.shape, dtype=bool)
    best = v.max(axis=-1, keepdims=True)
    with np.errstate(invalid="ignore"):
        tie = v >= best - TIE_RTOL * (1.0 + np.abs(best))
    return tie & np.isfinite(v) & offered


def expected_time(
    tasks: Sequence[LearnedTask], partition: Partition, *, n_primitives: int, c: float
) -> Estimate:
    """``E[t_learn | P]`` of ``partition`` (blocks and per-block columns) over ``tasks``.

    The partition's ``admissible`` table has one column per candidate action, in the tasks'
    column order (the ``n_primitives`` primitive actions first, then options). Vectorised over
    states and blocks; the loop runs over tasks.
    """
    if not (np.isfinite(c) and c > 0):
        raise TaskError(f"the constant c = {c!r} of T_conv must be a positive number")
    w = check_tasks(tasks, partition.n_states, partition.n_options)
    if not 0 <= n_primitives <= partition.n_options:
        raise TaskError(f"n_primitives = {n_primitives} must be in 0..{partition.n_options}")
    B, K = partition.n_blocks, partition.n_options
    n_cols = partition.admissible.sum(axis=1)
    tc = t_conv(partition, c)
    p_ref = np.zeros((len(tasks), B))
    cost = np.zeros((len(tasks), B))
    committed = np.full((len(tasks), B), -1, dtype=np.int64)
    blocks = partition.labels
    for i, task in enumerate(tasks):  # loop over tasks; each vectorised over states
        lab, Qb, d = _task_blocks(task)
        occ = d > 0
        # Q_i(B_j, o): occupancy-weighted column values of each layer block
        qs = np.where(occ[:, None], Qb[lab], 0.0)
        inf = occ[:, None] & ~np.isfinite(qs)
        vals = np.zeros((B, K))
        np.add.at(vals, blocks[occ], np.where(inf, 0.0, qs)[occ] * d[occ, None])
        blocked = np.zeros((B, K), dtype=bool)
        np.logical_or.at(blocked, blocks[occ], inf[occ])
        vals = np.where(blocked, -np.inf, vals)
        tie = committed_columns(vals, partition.admissible)  # (B, K)
        # a committed column is consistent when it is within L in every occupied task block
        best_k = Qb.max(axis=1)
        good_k = (Qb >= best_k[:, None] - task.threshold) | ~np.isfinite(best_k)[:, None]
        pairs = np.unique(blocks[occ] * Qb.shape[0] + lab[occ])
        pb, pk = pairs // Qb.shape[0], pairs % Qb.shape[0]
        bad = np.zeros((B, K), dtype=bool)
        np.logical_or.at(bad, pb, ~good_k[pk])
        consistent = (tie & ~bad).any(axis=1)
        occupied = np.bincount(blocks[occ], minlength=B) > 0
        p_ref[i] = (occupied & ~consistent).astype(np.float64)
        committed[i] = np.where(tie.any(axis=1) & occupied, np.argmax(tie, axis=1), -1)
        all_pairs = np.unique(blocks * Qb.shape[0] + lab)
        n_ij = np.bincount(all_pairs // Qb.shape[0], minlength=B).astype(np.float64)
        cost[i] = p_ref[i] * c * n_ij**2 * (n_cols + n_primitives)
    per_task = tc + cost.sum(axis=1)
    return Estimate(float(w @ per_task), tc, per_task, p_ref, cost, committed)

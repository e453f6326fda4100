"""Algorithm 3: greedy autonomous hierarchy construction (section 4.4).

From ``P_0`` = one block offering no option (``O_0 = {}``), every step considers every pair
(block ``B_j``, *option* ``o`` not yet offered in ``B_j``), forms ``P_{n+1,(o,j)}`` = ``P_n`` with
``B_j`` *refined with* ``o``, and keeps the pair with the smallest ``E[t_learn | P_{n+1}]``
(:func:`adpart.hierarchy.estimator.expected_time`: a block commits to one column, and must be
refined when that column is not within ``L`` in some occupied state); it stops as soon as the
best candidate does not lower ``E[t_learn]`` and returns the last layer that did (``P_{n-1}`` of
the algorithm), so the result never costs more than the start.

Only options are candidate columns, as the algorithm is written (``o_i in O - O_{n,B_j}`` with
``O`` the option set): primitive actions join a layer only through the hierarchical learner's
refinement, which the refinement term of the estimate prices.

"``B_j`` refined with ``o``" is, in adpart (docs/hierarchy.md):

1. ``B_j`` is split by the column's *split labels*: the estimator passes each option's own
   delta-stable partition (:func:`adpart.hierarchy.layers.stable_option_splits`, eq. 4.6 for
   that option alone); without ``splits``, phase 1's initial blocks of section 4.2.1.2 (the
   option's termination states, the rest of its initiation set, the states outside it). Only
   ``B_j`` changes, the "splitting the blocks separately" variant the dissertation calls the
   more nuanced one.
2. ``o`` joins the option set of every sub-block in which every state may start it (the
   algorithm's ``O_{n+1,B} = O_{n,B} u {o}`` restricted to initiation-consistent blocks, as the
   decision layer requires); the other sub-blocks keep ``O_{n,B_j}``.

Candidates must add ``o`` to at least one sub-block. Each accepted step adds at least one
(state, option) pair, so the loop ends after at most ``S O`` steps (``max_steps`` caps it).

**Evaluation.** ``E = c (|P| D + R)`` with ``D = sum_B max(1, |O_B|)`` and ``R = sum_B n_B^2
(|O_B| + A) sum_i w_i P_refine(B | T_i)``. A candidate changes only its block's term of ``R`` and
the scalars ``|P|`` and ``D``, so the run keeps, per block, the change ``(d|P|, dD, dR)`` of every
candidate option; after a step only the refined block's sub-blocks are scored again. Scoring a
block is a handful of ``bincount`` calls over (candidate, split group) keys per task and offered
column - no Python loop over states or candidates.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from adpart.errors import TaskError
from adpart.hierarchy.estimator import check_tasks, committed_columns, good_columns
from adpart.hierarchy.tasks import LearnedTask
from adpart.partition.multiphase import initial_termination_labels
from adpart.partition.partition import Partition, canonical_labels

#: A candidate must lower E[t_learn] by more than this fraction of its current value.
DEFAULT_RTOL = 1e-12


@dataclass(frozen=True)
class Step:
    """One accepted refinement: the block (working id), the column and the estimate after it."""

    block: int
    column: int
    n_blocks: int
    estimate: float


@dataclass(frozen=True, eq=False)
class GreedyResult:
    """The layer Algorithm 3 returns and how it got there.

    Attributes:
        partition: the layer (canonical labels; ``admissible`` ``(B, K)`` per-block columns).
        trace: ``E[t_learn]`` of ``P_0, P_1, ...`` (non-increasing).
        steps: the accepted refinements, in order.
        stopped: ``"no-improvement"`` or ``"max-steps"``.
        candidates_evaluated: total number of (block, column) candidates scored.
    """

    partition: Partition
    trace: list[float]
    steps: list[Step] = field(default_factory=list)
    stopped: str = "no-improvement"
    candidates_evaluated: int = 0


def column_splits(admissible: np.ndarray, termination: np.ndarray | None = None) -> np.ndarray:
    """``(K, S)`` int8 split labels: phase 1's {beta = 1, rest of I, outside I} per column.

    Args:
        admissible: ``(S, K)`` bool, where each column may be started (initiation sets).
        termination: ``(S, K)`` bool, where each column's option terminates for sure (beta = 1);
            None or all-False columns (primitive actions) split by admissibility alone.
    """
    adm = np.asarray(admissible, dtype=bool)
    term = np.zeros_like(adm) if termination is None else np.asarray(termination, dtype=bool)
    if term.shape != adm.shape:
        raise TaskError(f"termination has shape {term.shape}; expected {adm.shape}")
    term = term & ~term.all(axis=0, keepdims=True)  # one-step options: beta = 1 everywhere
    return initial_termination_labels(term, adm).T.astype(np.int8)


class _Greedy:
    """The mutable state of one run (working block ids never renumber during the run)."""

    def __init__(self, tasks: Sequence[LearnedTask], admissible: np.ndarray, splits: np.ndarray,
                 candidates: np.ndarray, n_primitives: int, c: float) -> None:
        S, K = admissible.shape
        self.S, self.K, self.c, self.A = S, K, c, n_primitives
        self.w = check_tasks(tasks, S, K)
        self.adm = admissible
        self.cand = candidates
        self.splits = splits.astype(np.int64)
        self.G = int(self.splits.max()) + 1 if self.splits.size else 1
        occ = np.stack([t.occupancy > 0 for t in tasks])  # (T, S)
        self.occ = occ
        Q = np.stack([t.Q for t in tasks])  # (T, S, K)
        fin = np.isfinite(Q)
        self.qw = np.where(occ[:, :, None] & fin,
                           np.stack([t.occupancy for t in tasks])[:, :, None] * np.where(fin, Q, 0),
                           0.0)
        self.blocked = occ[:, :, None] & ~fin
        self.bad = occ[:, :, None] & ~np.stack([good_columns(t) for t in tasks])
        self.labels = np.zeros(S, dtype=np.int64)
        cap = 64
        self.offered = np.zeros((cap, K), dtype=bool)
        self.n = np.zeros(cap)
        self.term = np.zeros(cap)
        self.dP = np.zeros((cap, K))
        self.dD = np.zeros((cap, K))
        self.dR = np.full((cap, K), np.inf)
        self.n_blocks = 1
        self.evaluated = 0
        self._score_blocks([0])

    def _grow(self, need: int) -> None:
        cap = self.offered.shape[0]
        if need <= cap:
            return
        new = max(need, 2 * cap)
        for name, fill in (("offered", False), ("n", 0.0), ("term", 0.0), ("dP", 0.0),
                           ("dD", 0.0), ("dR", np.inf)):
            old = getattr(self, name)
            arr = np.full((new, *old.shape[1:]), fill, dtype=old.dtype)
            arr[:cap] = old
            setattr(self, name, arr)

    def _refine_weight(self, vals: np.ndarray, blocked: np.ndarray, bad: np.ndarray,
                       offered: np.ndarray, occupied: np.ndarray) -> np.ndarray:
        """``sum_i w_i P_refine`` per (sub-)block from per-task column sums ``(T, ..., K')``."""
        v = np.where(blocked > 0, -np.inf, vals)
        tie = committed_columns(v, offered[None])
        consistent = (tie & (bad == 0)).any(axis=-1)
        need = (occupied > 0) & ~consistent
        return np.tensordot(self.w, need.astype(np.float64), axes=1)

    def _score_blocks(self, blocks: Sequence[int]) -> None:
        """The block terms and candidate rows of ``blocks``."""
        for j in blocks:  # a handful of blocks per step; each vectorised over its states
            members = np.flatnonzero(self.labels == j)
            self._score_block(int(j), members)

    def _score_block(self, j: int, M: np.ndarray) -> None:
        A, G = self.A, self.G
        own = np.flatnonzero(self.offered[j])
        n_j = float(M.size)
        self.n[j] = n_j
        occ_j = self.occ[:, M].sum(axis=1)  # (T,)
        T = self.w.size
        sel = np.ix_(np.arange(T), M, own)
        w_j = self._refine_weight(
            self.qw[sel].sum(axis=1), self.blocked[sel].sum(axis=1),
            self.bad[sel].sum(axis=1), np.ones(own.size, dtype=bool), occ_j)
        k_j = float(own.size)
        self.term[j] = n_j**2 * (k_j + A) * w_j
        self.dP[j], self.dD[j], self.dR[j] = 0.0, 0.0, np.inf
        cols = np.flatnonzero(self.cand & ~self.offered[j] & self.adm[M].any(axis=0))
        if cols.size == 0:
            return
        C = cols.size
        grp = self.splits[cols][:, M].T  # (n, C)
        key = (np.arange(C)[None, :] * G + grp).ravel()
        size = C * G

        def sums(weights: np.ndarray) -> np.ndarray:  # (n, C) -> (C, G)
            return np.bincount(key, weights=weights.ravel(), minlength=size).reshape(C, G)

        ones = np.ones((M.size, C))
        n_g = sums(ones)
        a_g = sums(self.adm[np.ix_(M, cols)].astype(np.float64))
        gets = (n_g > 0) & (a_g == n_g)
        cells = np.ix_(M, cols)
        # per task: (C, G, |own| + 1) sums of the offered columns and of the candidate
        vals = np.zeros((T, C, G, own.size + 1))
        blocked = np.zeros_like(vals)
        bad = np.zeros_like(vals)
        occupied = np.zeros((T, C, G))
        for i in range(T):  # loop over tasks and offered columns; bincount over states
            occupied[i] = sums(np.broadcast_to(self.occ[i, M][:, None], (M.size, C)))
            for slot, k in enumerate(own):
                for arr, src in ((vals, self.qw), (blocked, self.blocked), (bad, self.bad)):
                    arr[i, :, :, slot] = sums(np.broadcast_to(
                        src[i, M, k][:, None].astype(np.float64), (M.size, C)))
            for arr, src in ((vals, self.qw), (blocked, self.blocked), (bad, self.bad)):
                arr[i, :, :, -1] = sums(src[i][cells].astype(np.float64))
        offered = np.concatenate(
            [np.ones((C, G, own.size), dtype=bool), gets[:, :, None]], axis=2)
        w_g = self._refine_weight(vals, blocked, bad, offered, occupied)  # (C, G)
        k_g = k_j + gets
        nonempty = n_g > 0
        r_new = (n_g**2 * (k_g + A) * w_g).sum(axis=1)
        valid = gets.any(axis=1)
        self.dP[j, cols] = nonempty.sum(axis=1) - 1.0
        self.dD[j, cols] = (np.where(nonempty, np.maximum(k_g, 1.0), 0.0).sum(axis=1)
                            - max(k_j, 1.0))
        self.dR[j, cols] = np.where(valid, r_new - self.term[j], np.inf)
        self.evaluated += int(valid.sum())

    def totals(self) -> tuple[float, float, float]:
        live = slice(0, self.n_blocks)
        k = self.offered[live].sum(axis=1).astype(np.float64)
        D = float(np.maximum(k, 1.0).sum())
        return float(self.n_blocks), D, float(self.term[live].sum())

    def estimate(self) -> float:
        P, D, R = self.totals()
        return self.c * (P * D + R)

    def best(self) -> tuple[int, int, float]:
        P, D, R = self.totals()
        live = slice(0, self.n_blocks)
        with np.errstate(invalid="ignore"):
            score = self.c * ((P + self.dP[live]) * (D + self.dD[live]) + R + self.dR[live])
        flat = int(np.argmin(score))
        j, o = divmod(flat, self.K)
        return j, o, float(score[j, o])

    def apply(self, j: int, o: int) -> None:
        members = np.flatnonzero(self.labels == j)
        groups = self.splits[o, members]
        present = np.unique(groups)
        new_ids = np.full(self.G, -1, dtype=np.int64)
        new_ids[present[0]] = j
        new_ids[present[1:]] = self.n_blocks + np.arange(present.size - 1)
        self._grow(self.n_blocks + present.size - 1)
        touched = new_ids[present]
        self.offered[touched] = self.offered[j]
        self.n_blocks += present.size - 1
        self.labels[members] = new_ids[groups]
        for g in present:  # at most G (3) split groups
            if self.adm[members[groups == g], o].all():
                self.offered[new_ids[g], o] = True
        self._score_blocks(touched)

    def partition(self) -> Partition:
        canon = canonical_labels(self.labels)
        old = np.empty(int(canon.max()) + 1, dtype=np.int64)
        old[canon] = self.labels
        return Partition(canon, self.offered[old].copy())


def greedy_hierarchy(
    tasks: Sequence[LearnedTask],
    admissible: np.ndarray,
    *,
    n_primitives: int,
    splits: np.ndarray | None = None,
    c: float,
    max_steps: int | None = None,
    rtol: float = DEFAULT_RTOL,
) -> GreedyResult:
    """Run Algorithm 3 over ``tasks`` (module docstring).

    Args:
        tasks: the learned tasks, all over the same ``K`` columns (the ``n_primitives``
            primitive actions first, then the options).
        admissible: ``(S, K)`` bool, where each column may be started.
        n_primitives: ``A``; columns ``A..K-1`` are the candidate options, and the estimate's
            refinement term counts the ``A`` primitive actions a refinement may add.
        splits: ``(K, S)`` small non-negative ints, how "refined with column k" splits a block
            (default :func:`column_splits` of ``admissible``: by admissibility alone).
        c: the constant of ``T_conv`` (it scales ``E`` and does not change the choices).
        max_steps: stop after this many accepted refinements (None: until no improvement).
        rtol: a step must lower ``E`` by more than ``rtol * E``.

    Returns:
        The layer with its estimate trace; the tasks must be at the per-state resolution.
    """
    adm = np.asarray(admissible)
    if adm.ndim != 2 or adm.dtype != bool:
        raise TaskError(f"admissible must be a boolean (S, K) array; got {adm.dtype} {adm.shape}")
    if not (isinstance(n_primitives, int | np.integer) and 0 <= n_primitives <= adm.shape[1]):
        raise TaskError(f"n_primitives = {n_primitives!r} must be an int in 0..{adm.shape[1]}")
    if any(t.labels is not None for t in tasks):
        raise TaskError(
            "greedy construction works at the per-state resolution of the stored tasks; build "
            "the LearnedTask objects without labels (the estimator accepts task partitions)"
        )
    if not (np.isfinite(c) and c > 0):
        raise TaskError(f"the constant c = {c!r} of T_conv must be a positive number")
    if max_steps is not None and max_steps < 0:
        raise TaskError(f"max_steps = {max_steps} must be >= 0 (or None)")
    spl = column_splits(adm) if splits is None else np.asarray(splits)
    if spl.shape != adm.T.shape or not np.issubdtype(spl.dtype, np.integer) or spl.min() < 0:
        raise TaskError(
            f"splits must be non-negative integers of shape {adm.T.shape} (columns, states)"
        )
    spl = np.stack([canonical_labels(row) for row in spl]) if spl.size else spl
    cand = np.arange(adm.shape[1]) >= n_primitives
    run = _Greedy(tasks, adm, spl, cand, int(n_primitives), float(c))
    trace = [run.estimate()]
    steps: list[Step] = []
    stopped = "no-improvement"
    while True:  # one iteration per accepted refinement (Algorithm 3's repeat loop)
        if max_steps is not None and len(steps) >= max_steps:
            stopped = "max-steps"
            break
        j, o, score = run.best()
        if not np.isfinite(score) or score >= trace[-1] - rtol * abs(trace[-1]):
            break
        run.apply(j, o)
        now = run.estimate()
        trace.append(now)
        steps.append(Step(j, o, run.n_blocks, now))
    return GreedyResult(run.partition(), trace, steps, stopped, run.evaluated)

"""Algorithm 3: greedy autonomous hierarchy construction (section 4.4).

From ``P_0`` = one block offering no option, every step considers every pair (block ``B_j``,
column ``o`` not yet offered in ``B_j``), forms ``P_{n+1,(o,j)}`` = ``P_n`` with ``B_j`` *refined
with* ``o``, and keeps the pair with the smallest ``E[t_learn | P_{n+1}]``; it stops as soon as the
best candidate does not lower ``E[t_learn]`` and returns the last layer that did (``P_{n-1}`` of
the algorithm), so the result never costs more than the start.

"``B_j`` refined with ``o``" is, in adpart (docs/hierarchy.md):

1. ``B_j`` is split by the column's *split labels* (default: phase 1's initial blocks of section
   4.2.1.2 - the option's termination states, the rest of its initiation set, the states outside
   it; for a primitive action: where it is admissible or not). Only ``B_j`` changes, the "splitting
   the blocks separately" variant the dissertation calls the more nuanced one.
2. ``o`` joins the option set of every sub-block in which every state may start it (the
   algorithm's ``O_{n+1,B} = O_{n,B} u {o}`` restricted to initiation-consistent blocks, as the
   decision layer requires); the other sub-blocks keep ``O_{n,B_j}``.

Candidates must add ``o`` to at least one sub-block. Each accepted step adds at least one
(state, column) pair, so the loop ends after at most ``S K`` steps (``max_steps`` caps it).

**Vectorised evaluation.** At the per-state resolution of the stored tasks, ``E[t_learn]``
decomposes over blocks: with ``U_0(s) = sum_i w_i d_i(s) uncov_i(s)`` (the weighted occupancy of
``s`` where the block's options are all worse than the best by more than ``L``) and
``U(s, o) = sum_i w_i d_i(s) uncov_i(s) [o not good in s for T_i]``,

    E = c (|P| D + sum_B n_B^2 (|O_B| + 1) sum_{s in B} U_0(s)),  D = sum_B max(1, |O_B|).

A candidate changes only its block's term and the scalars ``|P|`` and ``D``, so the table of all
candidates is three ``(B, K)`` arrays (``d|P|``, ``dD``, ``dR``) built by ``bincount`` over
(block, column, split group) keys - no Python loop over states. After a step only the refined
block's rows of ``U`` and of the candidate table are recomputed.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from adpart.errors import TaskError
from adpart.hierarchy.estimator import check_tasks, good_columns
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
                 c: float) -> None:
        S, K = admissible.shape
        self.S, self.K, self.c = S, K, c
        w = check_tasks(tasks, S, K)
        self.adm = admissible
        self.splits = splits.astype(np.int64)
        self.G = int(self.splits.max()) + 1 if self.splits.size else 1
        self.good = np.stack([good_columns(t) for t in tasks])  # (T, S, K)
        self.m = np.stack([wi * t.occupancy for wi, t in zip(w, tasks, strict=True)])  # (T, S)
        self.uncov = np.ones((len(tasks), S), dtype=bool)
        self.U0 = np.zeros(S)
        self.U = np.zeros((S, K))
        self.labels = np.zeros(S, dtype=np.int64)
        cap = 64
        self.offered = np.zeros((cap, K), dtype=bool)
        self.n = np.zeros(cap)
        self.mass = np.zeros(cap)
        self.dP = np.zeros((cap, K))
        self.dD = np.zeros((cap, K))
        self.dR = np.full((cap, K), np.inf)
        self.n_blocks = 1
        self.evaluated = 0
        self._refresh_states(np.arange(S))
        self._refresh_blocks(np.array([0]))

    # ------------------------------------------------------------------ bookkeeping
    def _grow(self, need: int) -> None:
        cap = self.offered.shape[0]
        if need <= cap:
            return
        new = max(need, 2 * cap)
        for name, fill in (("offered", False), ("n", 0.0), ("mass", 0.0), ("dP", 0.0),
                           ("dD", 0.0), ("dR", np.inf)):
            old = getattr(self, name)
            arr = np.full((new, *old.shape[1:]), fill, dtype=old.dtype)
            arr[:cap] = old
            setattr(self, name, arr)

    def _refresh_states(self, states: np.ndarray) -> None:
        """Recompute ``U_0`` and ``U`` on ``states`` (a loop over tasks, vectorised inside)."""
        mu = self.m[:, states] * self.uncov[:, states]  # (T, n)
        self.U0[states] = mu.sum(axis=0)
        acc = np.zeros((states.size, self.K))
        for i in range(mu.shape[0]):
            acc += mu[i][:, None] * ~self.good[i][states]
        self.U[states] = acc

    def _refresh_blocks(self, blocks: np.ndarray) -> None:
        """Block totals and candidate rows of ``blocks`` (all their states at once)."""
        K, G = self.K, self.G
        pos = np.full(self.n_blocks, -1, dtype=np.int64)
        pos[blocks] = np.arange(blocks.size)
        states = np.flatnonzero(pos[self.labels] >= 0)
        bp = pos[self.labels[states]]
        nb = blocks.size
        self.n[blocks] = np.bincount(bp, minlength=nb)
        self.mass[blocks] = np.bincount(bp, weights=self.U0[states], minlength=nb)
        key = ((bp[:, None] * K + np.arange(K)[None, :]) * G + self.splits[:, states].T).ravel()
        size = nb * K * G
        n_g = np.bincount(key, minlength=size).reshape(nb, K, G)
        a_g = np.bincount(key, weights=self.adm[states].ravel().astype(np.float64),
                          minlength=size).reshape(nb, K, G)
        with_o = np.bincount(key, weights=self.U[states].ravel(), minlength=size).reshape(nb, K, G)
        u0 = np.broadcast_to(self.U0[states][:, None], (states.size, K)).ravel()
        without = np.bincount(key, weights=u0, minlength=size).reshape(nb, K, G)
        nonempty = n_g > 0
        gets = nonempty & (a_g == n_g)
        k_opts = self.offered[blocks].sum(axis=1).astype(np.float64)[:, None, None]
        mass_g = np.where(gets, with_o, without)
        new_opts = k_opts + gets
        n_j = self.n[blocks][:, None]
        kj = k_opts[:, :, 0]
        self.dP[blocks] = nonempty.sum(axis=2) - 1.0
        self.dD[blocks] = (np.where(nonempty, np.maximum(new_opts, 1.0), 0.0).sum(axis=2)
                           - np.maximum(kj, 1.0))
        r_new = (n_g.astype(np.float64) ** 2 * (new_opts + 1.0) * mass_g).sum(axis=2)
        r_old = n_j**2 * (kj + 1.0) * self.mass[blocks][:, None]
        valid = gets.any(axis=2) & ~self.offered[blocks]
        self.dR[blocks] = np.where(valid, r_new - r_old, np.inf)
        self.evaluated += int(valid.sum())

    def totals(self) -> tuple[float, float, float]:
        live = slice(0, self.n_blocks)
        k = self.offered[live].sum(axis=1).astype(np.float64)
        D = float(np.maximum(k, 1.0).sum())
        R = float((self.n[live] ** 2 * (k + 1.0) * self.mass[live]).sum())
        return float(self.n_blocks), D, R

    def estimate(self) -> float:
        P, D, R = self.totals()
        return self.c * (P * D + R)

    # ------------------------------------------------------------------ one step
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
        gets = []
        for g in present:  # at most G (3) split groups
            sub = members[groups == g]
            if self.adm[sub, o].all():
                self.offered[new_ids[g], o] = True
                gets.append(sub)
        if gets:
            states = np.concatenate(gets)
            self.uncov[:, states] &= ~self.good[:, states, o]
            self._refresh_states(states)
        self._refresh_blocks(touched)

    def partition(self) -> Partition:
        canon = canonical_labels(self.labels)
        old = np.empty(int(canon.max()) + 1, dtype=np.int64)
        old[canon] = self.labels
        return Partition(canon, self.offered[old].copy())


def greedy_hierarchy(
    tasks: Sequence[LearnedTask],
    admissible: np.ndarray,
    *,
    splits: np.ndarray | None = None,
    c: float = 1.0,
    max_steps: int | None = None,
    rtol: float = DEFAULT_RTOL,
) -> GreedyResult:
    """Run Algorithm 3 over ``tasks`` (module docstring).

    Args:
        tasks: the learned tasks, all over the same ``K`` columns (primitive actions, options).
        admissible: ``(S, K)`` bool, where each column may be started.
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
    run = _Greedy(tasks, adm, spl, float(c))
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

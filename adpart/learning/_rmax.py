"""Directed exploration by R-max: an optimistic model learned from counts, planned incrementally.

R-max (Brafman & Tennenholtz 2002) treats a state-action pair as *known* once it has been tried
``m`` times; its model is then frozen at those ``m`` samples (the empirical successor
distribution; the reward is the one paid on each try, the task's rewards being deterministic).
An unknown pair is worth ``v_max``, a value no return can exceed. The agent acts greedily on the
optimum ``Q_x`` of that optimistic model, so it is drawn to the nearest unknown pairs until it
knows every pair it can reach, and then follows the empirical model's optimum. This is what
finds a goal that is no subgoal when no option and no one-step optimism does
(docs/hierarchical-learning.md, three-floor-arm ``deliver``).

Planning is incremental (prioritized sweeping without priorities, Moore & Atkeson 1993): the model
changes only when a pair becomes known, and then :func:`sweep` re-backs-up that pair's
state and, while a state's value moves by more than ``tol``, its predecessors, in FIFO order.
The predecessor lists (:func:`predecessors`) are read from the task's transition support: they
only say which states to back up again (a state whose known pairs never led to ``x`` gets the
same value back), so a superset of the observed predecessors changes the work, not the values.

Arrays, per run ``k``: ``xc[k, j]`` counts the samples of CSR entry ``j`` (successor
``indices[j]`` of row ``a*S + s``), ``xm[k, j]`` those taken while the pair was unknown (R-max's
frozen model); the grounded values plan on ``xc``, the grounded model of every sample;
``Qx`` (K, S, A) and ``Vx`` (K, S) the optimistic model's values; ``Ql`` and ``Vl`` the grounded
one's; ``queue`` (K, S) and ``inq`` (K, S) the sweeps' FIFO.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp

from adpart.mdp._sampling import compiled
from adpart.mdp.model import FiniteMDP, SMDPModel

#: The sweep's tolerance, as a fraction of ``max(1, v_max)``: a value that moves by less is
#: not propagated to its predecessors.
SWEEP_TOL = 1e-7


def reward_ceiling(top: float, gamma: float, horizon: int) -> float:
    """``v_max`` of rewards at most ``top``: ``max(top, 0) / (1 - gamma)``, or
    ``max(top, 0) * horizon`` (the episode's step limit) when ``gamma = 1``."""
    top = max(float(top), 0.0)
    return top / (1.0 - gamma) if gamma < 1.0 else top * horizon


def termination_ceiling(R: np.ndarray, pT: np.ndarray, live: np.ndarray) -> float | None:
    """``v_max`` of a task whose positive rewards all come with a chance of ending the episode:
    ``max R(s, a) / P(terminal | s, a)`` over the ``live`` pairs that pay more than 0, or None
    when one of them cannot end it (then only :func:`reward_ceiling` bounds the value).

    Why it bounds ``V``: every positive reward ``R(s, a) <= G P(terminal | s, a)`` with ``G`` that
    maximum, so the expected discounted sum of positive rewards is at most ``G`` times the
    expected number of terminations, which is at most 1; the other rewards are <= 0. A goal
    task pays its reward once, on arrival, so ``G`` is that reward instead of
    ``G / (1 - gamma)``, a reward paid at every step forever.

    Args:
        R, pT: ``(S, A)`` rewards and probabilities of arriving in a terminal state.
        live: ``(S, A)`` bool, the pairs to bound over (admissible, from live states).
    """
    positive = live & (R > 0)
    if not positive.any():
        return 0.0
    if np.any(pT[positive] <= 0.0):
        return None
    return float(np.max(R[positive] / pT[positive]))


def episodic_ceiling(mdp: FiniteMDP, horizon: int, live: np.ndarray | None = None,
                     gamma: float | None = None) -> float:
    """:func:`termination_ceiling` of ``mdp`` over its ``live`` pairs (default: the admissible
    pairs of its live states), or where a positive reward cannot end an episode the looser
    :func:`reward_ceiling` of the largest of those rewards, at ``gamma`` (default the MDP's)."""
    S, A = mdp.n_states, mdp.n_actions
    if live is None:
        live = mdp.admissible & ~mdp.terminal[:, None]
    arrive = np.asarray(mdp.P @ mdp.terminal.astype(np.float64)).reshape(A, S).T
    tight = termination_ceiling(mdp.R, arrive, live)
    if tight is not None:
        return tight
    return reward_ceiling(float(np.max(mdp.R[live])) if live.any() else 0.0,
                          mdp.gamma if gamma is None else gamma, horizon)


def value_ceiling(mdp: FiniteMDP, horizon: int) -> float:
    """:func:`reward_ceiling` of ``mdp``'s own largest admissible reward."""
    return reward_ceiling(float(np.max(np.where(mdp.admissible, mdp.R, -np.inf))), mdp.gamma,
                          horizon)


def predecessors(mdp: FiniteMDP) -> tuple[np.ndarray, np.ndarray]:
    """CSR ``(ptr, idx)`` of each state's predecessors in the transition support (sorted)."""
    _, indptr, indices = mdp.sampler_arrays
    S = mdp.n_states
    rows = np.repeat(np.arange(indptr.size - 1), np.diff(indptr))
    pairs = np.unique(indices.astype(np.int64) * S + rows % S)
    dst, src = np.divmod(pairs, S)
    ptr = np.zeros(S + 1, dtype=np.int64)
    np.cumsum(np.bincount(dst, minlength=S), out=ptr[1:])
    return ptr, src.astype(np.int64)


def counted_smdp(smdp: SMDPModel, mdp: FiniteMDP, xc: np.ndarray, floor: float) -> SMDPModel:
    """``smdp`` (primitive columns first, as stacked by the learner) with its primitive columns
    replaced by one run's grounded model: a tried pair pays its reward and moves by the
    frequencies of its samples (``xc``, counts of the CSR entries of ``mdp.P``); an untried pair
    is worth ``floor`` and has no successor. The option columns keep the models given. Planning
    on it is what the grounded values do for the flat pairs, done for the whole layer."""
    S, A = mdp.n_states, mdp.n_actions
    indptr, indices = mdp.P.indptr, mdp.P.indices
    row = np.repeat(np.arange(A * S), np.diff(indptr))
    total = np.bincount(row, weights=xc, minlength=A * S)
    live = np.tile(~mdp.terminal, A)
    data = np.where(live[row], mdp.gamma * xc / np.maximum(total[row], 1.0), 0.0)
    F_prim = sp.csr_array((data, indices.copy(), indptr.copy()), shape=(A * S, S))
    F_prim.eliminate_zeros()
    tried = (total > 0).reshape(A, S).T
    R_prim = np.where(mdp.terminal[:, None], 0.0, np.where(tried, mdp.R, floor))
    F = sp.csr_array(sp.vstack([F_prim, smdp.F[A * S:]], format="csr"))
    return SMDPModel(R=np.hstack([R_prim, smdp.R[:, A:]]), F=F, admissible=smdp.admissible)


@compiled
def model_backup(k, x, a, n, gamma, R, terminal, indptr, indices, xc, V):  # pragma: no cover
    """``R(x, a) + gamma sum_s' p^(s' | x, a) V[k, s']`` on run ``k``'s empirical model, whose
    ``n`` samples of ``(x, a)`` are counted in ``xc[k]``."""
    S = R.shape[0]
    row = a * S + x
    tot = 0.0
    for j in range(indptr[row], indptr[row + 1]):
        c = xc[k, j]
        if c > 0 and not terminal[indices[j]]:
            tot += c * V[k, indices[j]]
    return R[x, a] + gamma * tot / n


@compiled
def model_spread(k, x, a, terminal, indptr, indices, nf, xc, V):  # pragma: no cover
    """The standard error of ``V[k, s']`` over run ``k``'s samples of ``(x, a)`` (0 below 2)."""
    S = V.shape[1]
    n = nf[k, x, a]
    if n < 2:
        return 0.0
    row = a * S + x
    mean = 0.0
    for j in range(indptr[row], indptr[row + 1]):
        if xc[k, j] > 0 and not terminal[indices[j]]:
            mean += xc[k, j] * V[k, indices[j]]
    mean /= n
    var = 0.0
    for j in range(indptr[row], indptr[row + 1]):
        if xc[k, j] > 0:
            v = 0.0 if terminal[indices[j]] else V[k, indices[j]]
            var += xc[k, j] * (v - mean) * (v - mean)
    return math.sqrt(var / (n - 1) / n)


@compiled
def sweep(k, x0, m, unknown, frozen, tol, gamma, R, terminal, indptr, indices, prim_adm, nf, xc,
          Q, V, pred_ptr, pred_idx, queue, inq):  # pragma: no cover - compiled
    """Re-plan run ``k``'s values ``Q``/``V`` of a count model after the model of a pair of
    ``x0`` changed (module docstring). A pair tried fewer than ``m`` times is worth ``unknown``;
    a known one its backup on the successor counts ``xc``, over its first ``m`` samples when
    ``frozen`` (R-max: ``m``, ``v_max``, ``xm``), over all of them otherwise (the grounded values:
    ``m = 1``, the floor, ``xc``)."""
    S = R.shape[0]
    A = R.shape[1]
    head = 0
    size = 1
    queue[k, 0] = x0
    inq[k, x0] = True
    while size > 0:
        x = queue[k, head]
        head = (head + 1) % S
        size -= 1
        inq[k, x] = False
        best = -math.inf
        for a in range(A):
            if not prim_adm[x, a]:
                continue
            n = nf[k, x, a]
            q = unknown
            if n >= m:
                q = model_backup(k, x, a, m if frozen else n, gamma, R, terminal, indptr, indices,
                                 xc, V)
            Q[k, x, a] = q
            best = max(best, q)
        if abs(best - V[k, x]) > tol:
            V[k, x] = best
            for i in range(pred_ptr[x], pred_ptr[x + 1]):
                p = pred_idx[i]
                if not inq[k, p] and not terminal[p]:
                    queue[k, (head + size) % S] = p
                    inq[k, p] = True
                    size += 1


@compiled
def observe(k, s, a, s2, m, v_max, tol, gamma, task, counts, plan, fifo):  # pragma: no cover
    """Record the step ``(s, a) -> s2`` of run ``k`` (``nf`` already counts it): count the
    successor in ``xc``, and in ``xm`` while the pair is unknown; re-plan when this try makes
    it known. The arrays come grouped by role: ``task = (R, terminal, indptr, indices,
    prim_adm)``, ``counts = (nf, xc, xm)``, ``plan = (Qx, Vx)`` (R-max's values) and
    ``fifo = (pred_ptr, pred_idx, queue, inq)`` (the sweep's predecessors and queue)."""
    R, terminal, indptr, indices, prim_adm = task
    nf, xc, xm = counts
    Qx, Vx = plan
    pred_ptr, pred_idx, queue, inq = fifo
    S = R.shape[0]
    row = a * S + s
    n = nf[k, s, a]
    for j in range(indptr[row], indptr[row + 1]):
        if indices[j] == s2:
            xc[k, j] += 1
            if n <= m:
                xm[k, j] += 1
            break
    if n == m:
        sweep(k, s, m, v_max, True, tol, gamma, R, terminal, indptr, indices, prim_adm, nf, xm,
              Qx, Vx, pred_ptr, pred_idx, queue, inq)


def rmax_observe(k, s, a, s2, m, v_max, tol, gamma, R, terminal, indptr, indices, prim_adm, nf,
                 xc, xm, Qx, Vx, pred_ptr, pred_idx, queue, inq):
    """:func:`observe` with its arrays one by one, for callers outside compiled code."""
    observe(k, s, a, s2, m, v_max, tol, gamma, (R, terminal, indptr, indices, prim_adm),
            (nf, xc, xm), (Qx, Vx), (pred_ptr, pred_idx, queue, inq))

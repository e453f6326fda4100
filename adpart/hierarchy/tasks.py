"""The estimator's inputs for one learned task: Q over the candidate columns and occupancies.

Section 4.4 describes a learned task as the triple ``T_i = (pi_i, P_i, Q_i)``; the expected learning
time needs, per task, the value of every candidate action in every state (``Q_i(., a)`` for the
primitive actions *and* the options) and the probability ``P(B_{i,k} | T_i)`` of meeting each of
the task's blocks. adpart stores per-state Q over the primitive actions (``Policy.q``), so:

* **Option values** are derived exactly from the stored values: with ``V_i = max_a Q_i(., a)``,
  ``Q_i(s, o) = E[sum_{t<tau} gamma^t r_i(s_t, a_t) + gamma^tau V_i(s_tau)]`` - the option runs
  with the *task's* rewards and terminal states (arrival in a task goal ends it with value 0) and
  hands over to the task's own values where it stops. That is one sparse solve per option,
  ``(I - gamma P_pi C) x = r_pi + gamma P_pi (I - C) V_i``, on the states the option can act in
  (the option-model system of eq. 3.1 with the continuation value added to the right-hand side).
* **Occupancies** are the discounted state occupancy under the task's greedy policy,
  ``d = mu + gamma P_pi^T d`` over the non-terminal states (no decision is taken in a terminal
  state), normalised to sum to one, started from *every* state reachable from the task's start
  distribution (``starts="reachable"``, the default: ``mu`` uniform over them) - learning explores,
  so every such state is met and acted in, while the greedy policy from the start alone puts
  weight on a corridor (320 of urban's 20,004 states). ``starts="start"`` is the greedy policy's
  occupancy from the start distribution itself. ``P(B | T_i) = sum_{s in B} d(s)``.

The per-state resolution is the task's own partition ``P_i`` (``B_{i,k} = {s}``) unless a task
partition is given (then block Q values are occupancy-weighted means, see
:mod:`adpart.hierarchy.estimator`).
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from adpart.errors import ModelError, TaskError
from adpart.learning.curves import start_distribution
from adpart.mdp.model import FiniteMDP
from adpart.options.option import Option


@dataclass(frozen=True, eq=False)
class LearnedTask:
    """One previously learned task, ready for the estimator.

    Attributes:
        name: label used in messages and traces.
        Q: ``(S, K)`` float64 values of the candidate columns (primitive actions first, then the
            options); ``-inf`` where a column cannot be started.
        occupancy: ``(S,)`` float64 non-negative, sums to 1: ``P(s | T_i)``.
        threshold: the significance margin ``L`` of ``P_refine`` for this task.
        weight: the importance ``U(T_i) >= 0`` (uniform by default).
        labels: ``(S,)`` int64 task partition ``P_i`` or None for the per-state resolution.
    """

    name: str
    Q: np.ndarray
    occupancy: np.ndarray
    threshold: float
    weight: float = 1.0
    labels: np.ndarray | None = None

    def __post_init__(self) -> None:
        Q = np.asarray(self.Q, dtype=np.float64)
        if Q.ndim != 2:
            raise TaskError(f"task {self.name!r}: Q must be (S, K); got shape {Q.shape}")
        Q = np.where(np.isnan(Q), -np.inf, Q)
        d = np.asarray(self.occupancy, dtype=np.float64)
        if d.shape != (Q.shape[0],) or not np.all(np.isfinite(d)) or np.any(d < 0):
            raise TaskError(
                f"task {self.name!r}: occupancy must be {Q.shape[0]} finite non-negative numbers"
            )
        total = float(d.sum())
        if total <= 0:
            raise TaskError(f"task {self.name!r}: occupancy has no mass; give a start distribution")
        if not (np.isfinite(self.threshold) and self.threshold >= 0):
            raise TaskError(f"task {self.name!r}: threshold L = {self.threshold!r} must be >= 0")
        if not (np.isfinite(self.weight) and self.weight >= 0):
            raise TaskError(f"task {self.name!r}: weight U = {self.weight!r} must be >= 0")
        if self.labels is not None:
            lab = np.asarray(self.labels)
            if lab.shape != d.shape or not np.issubdtype(lab.dtype, np.integer) or lab.min() < 0:
                raise TaskError(
                    f"task {self.name!r}: labels must be {d.size} non-negative integers"
                )
            object.__setattr__(self, "labels", lab.astype(np.int64))
        object.__setattr__(self, "Q", Q)
        object.__setattr__(self, "occupancy", d / total)

    @property
    def n_states(self) -> int:
        return self.Q.shape[0]

    @property
    def n_columns(self) -> int:
        return self.Q.shape[1]

    def with_threshold(self, threshold: float) -> LearnedTask:
        """The same task with significance margin ``L = threshold`` (nothing else recomputed)."""
        if not (np.isfinite(threshold) and threshold >= 0):
            raise TaskError(f"task {self.name!r}: threshold L = {threshold!r} must be >= 0")
        out = copy.copy(self)
        object.__setattr__(out, "threshold", float(threshold))
        return out

    def with_columns(self, columns: np.ndarray) -> LearnedTask:
        """The same task over the candidate columns ``columns`` (indices into ``Q``'s columns).

        A column's values depend on that column alone (:func:`option_values` solves per option),
        so selecting columns is exact; occupancy, threshold and weight stay as they are.
        """
        out = copy.copy(self)
        object.__setattr__(out, "Q", self.Q[:, np.asarray(columns, dtype=np.int64)])
        return out

    def value_range(self, n_primitives: int) -> float:
        """``max V - min V`` of ``V = max_a Q(., a)`` over the primitive actions, taken over the
        states with a finite value (terminal states and states without one are left out)."""
        Q = self.Q[:, :n_primitives]
        V = np.where(np.isfinite(Q), Q, -np.inf).max(axis=1, initial=-np.inf)
        V = V[np.isfinite(V)]
        return float(V.max() - V.min()) if V.size else 0.0


STARTS = ("reachable", "start")


def reachable_states(mdp: FiniteMDP, sources: np.ndarray) -> np.ndarray:
    """``(S,)`` bool: states some sequence of admissible actions reaches from ``sources``.

    Terminal states are reached but not left (the episode ends there). Breadth first over the
    union of the action graphs (``scipy.sparse.csgraph``).
    """
    from scipy.sparse.csgraph import breadth_first_order

    S, A = mdp.n_states, mdp.n_actions
    P = sp.csr_array(mdp.P)
    rows = np.repeat(np.arange(A * S), np.diff(P.indptr))
    a, s = rows // S, rows % S
    keep = mdp.admissible[s, a] & ~mdp.terminal[s] & (P.data > 0)
    src = np.flatnonzero(sources)
    # a virtual node S points at every source
    graph = sp.csr_array((np.ones(int(keep.sum()) + src.size),
                          (np.r_[s[keep], np.full(src.size, S)], np.r_[P.indices[keep], src])),
                         shape=(S + 1, S + 1))
    order = breadth_first_order(graph, S, directed=True, return_predecessors=False)
    out = np.zeros(S + 1, dtype=bool)
    out[order] = True
    return out[:S]


def discounted_occupancy(mdp: FiniteMDP, policy: np.ndarray, starts: str = "reachable"
                         ) -> np.ndarray:
    """``(S,)`` discounted occupancy under ``policy`` from ``starts`` (module docstring), sum 1.

    Solves ``(I - gamma P_pi^T) d = mu`` on the non-terminal states (sparse LU); terminal states
    get 0 (the episode is over on arrival). With ``gamma = 1`` the policy must reach a terminal
    state (the system is then the expected number of visits).
    """
    S = mdp.n_states
    pol = np.asarray(policy, dtype=np.int64)
    if pol.shape != (S,) or pol.min() < 0 or pol.max() >= mdp.n_actions:
        raise TaskError(f"policy must be {S} actions in 0..{mdp.n_actions - 1}")
    if starts not in STARTS:
        raise TaskError(f"starts = {starts!r}: use one of {', '.join(STARTS)}")
    live = np.flatnonzero(~mdp.terminal)
    P_pi = mdp.P[pol[live] * S + live][:, live]
    mu = start_distribution(mdp)
    if starts == "reachable":
        mu = (reachable_states(mdp, mu > 0) & ~mdp.terminal).astype(np.float64)
    mu = mu[live] / mu[live].sum()
    system = sp.csc_array(sp.eye_array(live.size) - mdp.gamma * sp.csr_array(P_pi).T)
    try:
        d_live = spla.splu(system).solve(mu)
    except RuntimeError as exc:
        raise TaskError(
            f"the policy of {mdp.name!r} never ends an episode from some start state (gamma = 1 "
            "and no terminal state reached); its occupancy is infinite"
        ) from exc
    d = np.zeros(S)
    d[live] = np.clip(d_live, 0.0, None)
    return d / d.sum()


def option_values(mdp: FiniteMDP, options: Sequence[Option], V: np.ndarray) -> np.ndarray:
    """``(S, O)`` ``Q(s, o)`` of each option under ``mdp``'s rewards, continuing with ``V``.

    Rows outside an option's initiation set (and terminal states) are ``-inf``. One sparse LU per
    option (module docstring); the loop is over options, each solve vectorised over states.
    """
    S, A = mdp.n_states, mdp.n_actions
    V = np.where(mdp.terminal, 0.0, np.asarray(V, dtype=np.float64))
    if V.shape != (S,) or not np.all(np.isfinite(V)):
        raise TaskError(f"V must be {S} finite values")
    out = np.full((S, len(options)), -np.inf)
    for j, option in enumerate(options):
        option.check(mdp)
        cont = np.where(mdp.terminal, 0.0, 1.0 - option.beta)
        acting = np.flatnonzero(option.acting_states(mdp.terminal))
        if option.deterministic:
            W = sp.csr_array((np.ones(acting.size),
                              (np.arange(acting.size), option.policy[acting] * S + acting)),
                             shape=(acting.size, A * S))
        else:
            i, a = np.nonzero(option.policy[acting])
            W = sp.csr_array((option.policy[acting][i, a], (i, a * S + acting[i])),
                             shape=(acting.size, A * S))
        P_pi = sp.csr_array(W @ mdp.P)
        r_pi = W @ mdp.R.T.reshape(-1)
        rhs = r_pi + mdp.gamma * (P_pi @ ((1.0 - cont) * V))
        inner = sp.csr_array(P_pi[:, acting] @ sp.diags_array(cont[acting]))
        system = sp.csc_array(sp.eye_array(acting.size) - mdp.gamma * inner)
        try:
            x = spla.splu(system).solve(rhs)
        except RuntimeError as exc:
            raise ModelError(
                f"option {option.name!r} may never terminate on {mdp.name!r} (singular "
                "I - gamma P_pi C); give it beta = 1 somewhere on every loop"
            ) from exc
        col = np.full(S, -np.inf)
        col[acting] = x
        starts = option.initiation & ~mdp.terminal
        out[:, j] = np.where(starts, col, -np.inf)
    return out


def task_from_model(
    mdp: FiniteMDP,
    Q: np.ndarray,
    options: Sequence[Option] = (),
    *,
    threshold: float,
    name: str | None = None,
    weight: float = 1.0,
    labels: np.ndarray | None = None,
    starts: str = "reachable",
) -> LearnedTask:
    """Build a :class:`LearnedTask` from a task's model and its learned primitive ``Q`` (S, A).

    Columns: the ``A`` primitive actions (the stored Q, ``-inf`` where inadmissible) then one per
    option (:func:`option_values`); occupancy from the greedy policy of ``Q``
    (:func:`discounted_occupancy` from ``starts``).
    """
    S, A = mdp.n_states, mdp.n_actions
    Qp = np.asarray(Q, dtype=np.float64)
    if Qp.shape != (S, A):
        raise TaskError(f"Q of task {name or mdp.name!r} has shape {Qp.shape}; expected ({S}, {A})")
    Qp = np.where(mdp.admissible & ~np.isnan(Qp), Qp, -np.inf)
    policy = np.argmax(Qp, axis=1).astype(np.int64)
    V = np.where(mdp.terminal, 0.0, Qp.max(axis=1))
    if not np.all(np.isfinite(V)):
        bad = int(np.flatnonzero(~np.isfinite(V))[0])
        raise TaskError(f"Q of task {name or mdp.name!r} has no finite value in state {bad}")
    Qo = option_values(mdp, options, V) if len(options) else np.zeros((S, 0))
    Qp[mdp.terminal] = -np.inf
    Qo[mdp.terminal] = -np.inf
    return LearnedTask(
        name=name or mdp.name,
        Q=np.concatenate([Qp, Qo], axis=1),
        occupancy=discounted_occupancy(mdp, policy, starts),
        threshold=float(threshold),
        weight=float(weight),
        labels=labels,
    )

"""Exact solvers for finite MDPs and stacked SMDP models, vectorised with scipy.sparse.

All solvers take anything with an ``as_smdp()`` method (a :class:`~adpart.mdp.model.FiniteMDP` or
an :class:`~adpart.mdp.model.SMDPModel` of options) and work on the Bellman operator

    (T V)(s) = max_{o admissible in s} [ R(s, o) + sum_s' F(s' | s, o) V(s') ]       (eq. 3.1-3.2)

whose contraction modulus ``kappa`` is the largest discounted row mass of ``F`` (``gamma`` for an
MDP). Stopping rules and bounds (Puterman 1994, Thm. 6.3.1 and Prop. 6.6.5): with ``V' = T V``,

* sup-norm: ``||V' - V|| < eps (1 - kappa) / (2 kappa)``  =>  the greedy policy of ``V'`` is
  eps-optimal; this is valid for every SMDP.
* span: ``sp(V' - V) < eps (1 - kappa) / kappa``  =>  the same, but valid only when every
  admissible row has the same discount (no terminal states, one-step actions); it is tighter.

``value_iteration`` is plain (Jacobi) value iteration. ``modified_policy_iteration`` interleaves
each full backup with ``m`` cheap sweeps that evaluate the current greedy policy on its ``S`` rows
only (instead of ``O*S``); it stops by the same rule and so carries the same guarantee.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from adpart.errors import ModelError
from adpart.mdp.model import SMDPModel


class HasSMDP(Protocol):
    def as_smdp(self) -> SMDPModel: ...


@dataclass(frozen=True)
class Solution:
    """The result of an exact solve.

    Attributes:
        V: ``(S,)`` value estimate (the last backup ``T V``).
        policy: ``(S,)`` int64 greedy policy of ``V``.
        sweeps: full Bellman backups performed (over all ``O*S`` rows).
        evaluation_sweeps: partial policy-evaluation sweeps (``S`` rows each; MPI only).
        residual: the stopping statistic of the last backup (sup-norm or span of ``T V - V``).
        loss_bound: guaranteed upper bound on ``||V* - V^policy||_inf``.
        value_error_bound: guaranteed upper bound on ``||V* - V||_inf``.
        converged: whether the stopping rule was met before ``max_sweeps``.
        rule: ``"span"`` or ``"sup"``, the stopping rule used.
    """

    V: np.ndarray
    policy: np.ndarray
    sweeps: int
    evaluation_sweeps: int
    residual: float
    loss_bound: float
    value_error_bound: float
    converged: bool
    rule: str


class _Backup:
    """Precomputed pieces of the Bellman backup for one model (validate and convert once)."""

    def __init__(self, model: SMDPModel) -> None:
        self.S, self.O = model.n_states, model.n_actions
        self.F = model.F
        # (O, S) rewards with -inf where the option is not admissible: max() then ignores them.
        self.R_t = np.where(model.admissible.T, model.R.T, -np.inf)
        self.kappa = model.modulus
        self.uniform = model.uniform_discount

    def q_t(self, V: np.ndarray) -> np.ndarray:
        """``(O, S)`` Q values: one sparse mat-vec over the action-major rows."""
        return self.R_t + (self.F @ V).reshape(self.O, self.S)

    def backup(self, V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        Qt = self.q_t(V)
        policy = np.argmax(Qt, axis=0)
        return Qt[policy, np.arange(self.S)], policy

    def policy_rows(self, policy: np.ndarray) -> tuple[sp.csr_array, np.ndarray]:
        rows = policy * self.S + np.arange(self.S)
        return self.F[rows], self.R_t[policy, np.arange(self.S)]


def _stop_threshold(kappa: float, epsilon: float, uniform: bool) -> tuple[float, str]:
    if kappa >= 1.0:
        return epsilon * 1e-3, "sup"
    if kappa == 0.0:
        return np.inf, "sup"
    if uniform:
        return epsilon * (1.0 - kappa) / kappa, "span"
    return epsilon * (1.0 - kappa) / (2.0 * kappa), "sup"


def _statistic(delta: np.ndarray, rule: str) -> float:
    return float(np.ptp(delta)) if rule == "span" else float(np.abs(delta).max())


def _finish(
    V_new: np.ndarray, delta: np.ndarray, kappa: float, residual: float, rule: str
) -> tuple[np.ndarray, float, float]:
    """Final values and (policy loss bound, value error bound) after the last backup.

    With the span rule the values are moved to the midpoint of MacQueen's bounds
    ``T V + kappa/(1-kappa) [min(T V - V), max(T V - V)]`` (Puterman Thm. 6.6.3), which bracket
    ``V*`` for any ``V``; the greedy policy is unchanged by the constant shift.
    """
    if kappa >= 1.0:
        return V_new, np.inf, np.inf
    scale = kappa / (1.0 - kappa)
    if rule == "span":
        shift = scale * 0.5 * (float(delta.max()) + float(delta.min()))
        return V_new + shift, scale * residual, 0.5 * scale * residual
    return V_new, 2.0 * scale * residual, scale * residual


def _check_epsilon(epsilon: float) -> None:
    if not (np.isfinite(epsilon) and epsilon > 0):
        raise ModelError(f"epsilon = {epsilon!r} must be a positive number")


def _initial_values(V0: np.ndarray | None, S: int) -> np.ndarray:
    if V0 is None:
        return np.zeros(S)
    V = np.array(V0, dtype=np.float64)
    if V.shape != (S,):
        raise ModelError(f"initial values have shape {V.shape}; expected ({S},)")
    return V


def value_iteration(
    model: HasSMDP,
    epsilon: float = 1e-6,
    *,
    max_sweeps: int = 100_000,
    V0: np.ndarray | None = None,
) -> Solution:
    """Jacobi value iteration until the greedy policy is ``epsilon``-optimal.

    Args:
        model: an MDP or stacked SMDP model.
        epsilon: the guaranteed bound on the greedy policy's loss ``||V* - V^pi||_inf``.
        max_sweeps: give up after this many backups (``converged`` is then False).
        V0: starting values (zeros by default).
    """
    _check_epsilon(epsilon)
    smdp = model.as_smdp()
    b = _Backup(smdp)
    threshold, rule = _stop_threshold(b.kappa, epsilon, b.uniform)
    V = _initial_values(V0, b.S)
    residual, converged, sweeps = np.inf, False, 0
    policy = np.zeros(b.S, dtype=np.int64)
    V_new, delta = V, np.zeros(b.S)
    while sweeps < max_sweeps:
        V_new, policy = b.backup(V)
        sweeps += 1
        delta = V_new - V
        residual = _statistic(delta, rule)
        V = V_new
        if residual < threshold:
            converged = True
            break
    V, loss, err = _finish(V, delta, b.kappa, residual, rule)
    return Solution(V, policy.astype(np.int64), sweeps, 0, residual, loss, err, converged, rule)


def modified_policy_iteration(
    model: HasSMDP,
    epsilon: float = 1e-6,
    *,
    evaluation_sweeps: int = 20,
    max_sweeps: int = 100_000,
    V0: np.ndarray | None = None,
) -> Solution:
    """Modified policy iteration (Puterman 6.5) with value iteration's epsilon-optimal stop.

    After each full backup ``V' = T V`` (greedy policy ``pi``), ``V'`` is pushed towards
    ``V^pi`` by ``evaluation_sweeps`` applications of ``T_pi``, each touching only the ``S`` rows
    of ``pi`` rather than all ``O*S``. Starting from ``V0`` with ``T V0 >= V0`` is not required for
    the stopping guarantee, which depends only on the last full backup.
    """
    _check_epsilon(epsilon)
    if evaluation_sweeps < 0:
        raise ModelError(f"evaluation_sweeps = {evaluation_sweeps} must be >= 0")
    smdp = model.as_smdp()
    b = _Backup(smdp)
    threshold, rule = _stop_threshold(b.kappa, epsilon, b.uniform)
    V = _initial_values(V0, b.S)
    residual, converged, sweeps, partial = np.inf, False, 0, 0
    policy = np.zeros(b.S, dtype=np.int64)
    delta = np.zeros(b.S)
    while sweeps < max_sweeps:
        V_new, policy = b.backup(V)
        sweeps += 1
        delta = V_new - V
        residual = _statistic(delta, rule)
        V = V_new
        if residual < threshold:
            converged = True
            break
        F_pi, R_pi = b.policy_rows(policy)
        for _ in range(evaluation_sweeps):
            V = R_pi + F_pi @ V
        partial += evaluation_sweeps
    V, loss, err = _finish(V, delta, b.kappa, residual, rule)
    return Solution(V, policy.astype(np.int64), sweeps, partial, residual, loss, err, converged, rule)


def _policy_matrix(smdp: SMDPModel, policy: np.ndarray) -> tuple[sp.csr_array, np.ndarray]:
    """``F_pi`` (S, S) and ``R_pi`` (S,) for a deterministic or stochastic policy."""
    S, O = smdp.n_states, smdp.n_actions
    pol = np.asarray(policy)
    if pol.ndim == 1:
        if pol.shape != (S,) or not np.issubdtype(pol.dtype, np.integer):
            raise ModelError(f"a deterministic policy must be {S} integers; got {pol.shape}")
        if pol.min() < 0 or pol.max() >= O:
            raise ModelError(f"policy names action {int(pol.max())} outside 0..{O - 1}")
        chosen = smdp.admissible[np.arange(S), pol]
        if not chosen.all():
            s = int(np.flatnonzero(~chosen)[0])
            raise ModelError(f"policy chooses inadmissible action {int(pol[s])} in state {s}")
        rows = pol.astype(np.int64) * S + np.arange(S)
        return smdp.F[rows], smdp.R[np.arange(S), pol]
    if pol.shape != (S, O):
        raise ModelError(f"a stochastic policy must have shape ({S}, {O}); got {pol.shape}")
    if not np.allclose(pol.sum(axis=1), 1.0) or np.any(pol < 0):
        raise ModelError("stochastic policy rows must be probability distributions")
    if np.any((pol > 0) & ~smdp.admissible):
        raise ModelError("stochastic policy puts mass on inadmissible actions")
    weights = sp.diags_array(pol.T.reshape(-1))
    stacked = sp.csr_array(weights @ smdp.F)
    gather = sp.csr_array(sp.hstack([sp.eye_array(S)] * O))
    R_pi = np.einsum("so,so->s", pol, np.where(smdp.admissible, smdp.R, 0.0))
    return sp.csr_array(gather @ stacked), R_pi


def policy_evaluation(model: HasSMDP, policy: np.ndarray) -> np.ndarray:
    """Exact ``V^pi`` by one sparse direct solve of ``(I - F_pi) V = R_pi``.

    Args:
        policy: ``(S,)`` int actions, or ``(S, O)`` probabilities.

    Raises:
        ModelError: if ``I - F_pi`` is singular (a policy that never ends with ``gamma = 1``).
    """
    smdp = model.as_smdp()
    F_pi, R_pi = _policy_matrix(smdp, policy)
    A = sp.csc_array(sp.eye_array(smdp.n_states) - F_pi)
    with warnings.catch_warnings():
        warnings.simplefilter("error", spla.MatrixRankWarning)
        try:
            V = spla.spsolve(A, R_pi)
        except (RuntimeError, spla.MatrixRankWarning) as exc:
            raise ModelError(
                "policy evaluation failed: I - F_pi is singular; with gamma = 1 the policy must "
                "reach a terminal state from every state (does it never terminate?)"
            ) from exc
    if not np.all(np.isfinite(V)):
        raise ModelError(
            "policy evaluation produced non-finite values: I - F_pi is singular (with gamma = 1 "
            "the policy must reach a terminal state from every state)"
        )
    return np.asarray(V, dtype=np.float64)


def q_from_v(model: HasSMDP, V: np.ndarray) -> np.ndarray:
    """``(S, O)`` action values ``R + F V``; ``-inf`` where the action is not admissible."""
    smdp = model.as_smdp()
    return _Backup(smdp).q_t(np.asarray(V, dtype=np.float64)).T.copy()


def greedy_policy(Q: np.ndarray) -> np.ndarray:
    """``(S,)`` int64 argmax of each row of ``Q`` (ties go to the lowest action index)."""
    return np.argmax(np.asarray(Q), axis=1).astype(np.int64)


def solve(model: HasSMDP, epsilon: float = 1e-6, *, method: str = "mpi", **kwargs: object) -> (
    Solution
):
    """Solve to an ``epsilon``-optimal greedy policy with the named method (``mpi`` or ``vi``)."""
    if method == "mpi":
        return modified_policy_iteration(model, epsilon, **kwargs)  # type: ignore[arg-type]
    if method == "vi":
        return value_iteration(model, epsilon, **kwargs)  # type: ignore[arg-type]
    raise ModelError(f"unknown solver method {method!r}; use 'mpi' or 'vi'")

"""Exact evaluation of a given policy, and the greedy policy of an action-value table.

``policy_evaluation`` computes ``V^pi`` of a deterministic or stochastic policy over a
:class:`~adpart.mdp.model.FiniteMDP` or an options' :class:`~adpart.mdp.model.SMDPModel` by one
sparse direct solve of ``(I - F_pi) V = R_pi`` (the policy's Bellman equation, eq. 3.1 with the
max replaced by ``pi``); a policy that never terminates under ``gamma = 1`` is refused with the
states it traps, found by a backward search rather than a singular factorisation.
``greedy_policy`` is the lowest-index argmax of each row of ``Q``.
"""

from __future__ import annotations

import warnings

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from adpart.errors import ModelError
from adpart.mdp import _kernels
from adpart.mdp.model import HasSMDP, SMDPModel

__all__ = ["GREEDY_COMPILED_ROWS", "greedy_policy", "never_terminating_states",
           "policy_evaluation"]


def _policy_matrix(smdp: SMDPModel, policy: np.ndarray) -> tuple[sp.csr_array, np.ndarray]:
    """``F_pi`` (S, S) and ``R_pi`` (S,) for a deterministic or stochastic policy."""
    S, n_opt = smdp.n_states, smdp.n_actions
    pol = np.asarray(policy)
    if pol.ndim == 1:
        if pol.shape != (S,) or not np.issubdtype(pol.dtype, np.integer):
            raise ModelError(f"a deterministic policy must be {S} integers; got {pol.shape}")
        if pol.min() < 0 or pol.max() >= n_opt:
            raise ModelError(f"policy names action {int(pol.max())} outside 0..{n_opt - 1}")
        chosen = smdp.admissible[np.arange(S), pol]
        if not chosen.all():
            s = int(np.flatnonzero(~chosen)[0])
            raise ModelError(f"policy chooses inadmissible action {int(pol[s])} in state {s}")
        rows = pol.astype(np.int64) * S + np.arange(S)
        return smdp.F[rows], smdp.R[np.arange(S), pol]
    if pol.shape != (S, n_opt):
        raise ModelError(f"a stochastic policy must have shape ({S}, {n_opt}); got {pol.shape}")
    if not np.allclose(pol.sum(axis=1), 1.0) or np.any(pol < 0):
        raise ModelError("stochastic policy rows must be probability distributions")
    if np.any((pol > 0) & ~smdp.admissible):
        raise ModelError("stochastic policy puts mass on inadmissible actions")
    weights = sp.diags_array(pol.T.reshape(-1))
    stacked = sp.csr_array(weights @ smdp.F)
    gather = sp.csr_array(sp.hstack([sp.eye_array(S)] * n_opt))
    R_pi = np.einsum("so,so->s", pol, np.where(smdp.admissible, smdp.R, 0.0))
    return sp.csr_array(gather @ stacked), R_pi


def never_terminating_states(F_pi: sp.csr_array, atol: float = 1e-12) -> np.ndarray:
    """States from which the discounted chain ``F_pi`` never loses mass (``I - F_pi`` singular).

    A state "leaks" when its row mass is below ``1 - atol`` (discount, or termination). ``V^pi``
    is finite exactly when every state can reach a leaking state along ``F_pi``'s nonzeros, so a
    backward search from the leaking states finds the trapped rest without any factorisation
    (and without handing LAPACK a singular matrix).

    Returns:
        int64 ids of the trapped states (empty for every discounted model).
    """
    S = F_pi.shape[0]
    mass = np.asarray(F_pi.sum(axis=1)).ravel()
    leaking = np.flatnonzero(mass < 1.0 - atol)
    if leaking.size == S:
        return np.empty(0, dtype=np.int64)
    reach = np.zeros(S, dtype=bool)
    reach[leaking] = True
    backward = sp.csr_array(F_pi.T)
    frontier = leaking
    while frontier.size:
        preds = backward[frontier].indices if frontier.size else np.empty(0, dtype=np.int64)
        new = np.unique(preds[~reach[preds]])
        reach[new] = True
        frontier = new
    return np.flatnonzero(~reach).astype(np.int64)


def policy_evaluation(model: HasSMDP, policy: np.ndarray, *, never: float | None = None
                      ) -> np.ndarray:
    """Exact ``V^pi`` by one sparse direct solve of ``(I - F_pi) V = R_pi``.

    Args:
        policy: ``(S,)`` int actions, or ``(S, O)`` probabilities.
        never: the value of a state from which ``pi`` never ends (possible only with
            ``gamma = 1``; :func:`never_terminating_states`), as if it ended there with that
            value. Default: such a state raises.

    Raises:
        ModelError: if ``I - F_pi`` is singular (a policy that never ends with ``gamma = 1``
            and no ``never`` value).
    """
    smdp = model.as_smdp()
    F_pi, R_pi = _policy_matrix(smdp, policy)
    trapped = never_terminating_states(F_pi)
    if trapped.size and never is not None:
        keep = np.ones(smdp.n_states)
        keep[trapped] = 0.0
        F_pi = sp.csr_array(sp.diags_array(keep) @ F_pi)
        R_pi = np.where(keep > 0, R_pi, never)
    elif trapped.size:
        raise ModelError(
            f"policy evaluation: the policy never terminates from {trapped.size} state(s) (first: "
            f"state {int(trapped[0])}); with gamma = 1 every state must reach a terminal state "
            "(or a discounted row) under the policy"
        )
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


#: Rows from which :func:`greedy_policy` uses the compiled parallel kernel (below, numpy's
#: argmax is as fast and needs no compiled code).
GREEDY_COMPILED_ROWS = 200_000


def greedy_policy(Q: np.ndarray) -> np.ndarray:
    """``(S,)`` int64 argmax of each row of ``Q`` (ties go to the lowest action index).

    ``Q`` must not hold NaN (``-inf`` marks inadmissible pairs). Large tables (the learners'
    ``(K*S, A)`` stacks) use the compiled kernel, with the same result as ``np.argmax``.
    """
    Q = np.asarray(Q)
    if Q.ndim == 2 and Q.shape[0] >= GREEDY_COMPILED_ROWS and Q.dtype == np.float64:
        k = _kernels.load()
        if k is not None:
            out = np.empty(Q.shape[0], dtype=np.int64)
            k.greedy_rows(np.ascontiguousarray(Q), out)
            return out
    return np.argmax(Q, axis=1).astype(np.int64, copy=False)

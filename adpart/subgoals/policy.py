"""Validating a policy against an MDP, and the walker chain of the count metric (eq. 4.1).

A policy is either deterministic, a ``(S,)`` integer array of actions (a learned greedy policy),
or stochastic, a ``(S, A)`` array of action probabilities. Actions chosen in terminal states are
never executed (the episode has ended on arrival), so they are not checked for admissibility.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from adpart.errors import ModelError, TaskError
from adpart.mdp.model import FiniteMDP
from adpart.subgoals._walkers import reach_backwards

#: Tolerance on the row sums of a stochastic policy.
POLICY_ATOL = 1e-8


def check_mdp(mdp: object) -> FiniteMDP:
    if not isinstance(mdp, FiniteMDP):
        raise ModelError(
            f"subgoal discovery needs a FiniteMDP, got {type(mdp).__name__}; build one with "
            "adpart.envs.registry.get_domain(name).mdp(task)"
        )
    return mdp


def check_policy(mdp: FiniteMDP, policy: object) -> np.ndarray:
    """The policy as int64 ``(S,)`` or float64 ``(S, A)``; else TaskError naming the fault."""
    S, A = mdp.n_states, mdp.n_actions
    arr = np.asarray(policy)
    live = ~mdp.terminal
    if arr.ndim == 1:
        if arr.shape != (S,):
            raise TaskError(
                f"policy has {arr.shape[0]} entries but the MDP has {S} states; give one action "
                "per state (e.g. solve(mdp).policy or a Q table's argmax)"
            )
        if arr.dtype == bool or not np.issubdtype(arr.dtype, np.integer):
            raise TaskError(
                f"a deterministic policy must hold integer action ids, got dtype {arr.dtype}; "
                "for action probabilities pass an (S, A) array"
            )
        bad = np.flatnonzero((arr < 0) | (arr >= A))
        if bad.size:
            raise TaskError(
                f"policy[{bad[0]}] = {arr[bad[0]]} is not an action id; the MDP has actions "
                f"0..{A - 1}"
            )
        out = arr.astype(np.int64)
        bad = np.flatnonzero(live & ~mdp.admissible[np.arange(S), out])
        if bad.size:
            s = bad[0]
            raise TaskError(
                f"policy chooses inadmissible action {mdp.action_names[out[s]]!r} ({out[s]}) in "
                f"state {s} ({bad.size} such states); choose among the admissible actions "
                "(mdp.admissible), e.g. mask inadmissible Q values with -inf before argmax"
            )
        return out
    if arr.ndim == 2:
        if arr.shape != (S, A):
            raise TaskError(
                f"stochastic policy has shape {arr.shape}; expected (n_states, n_actions) = "
                f"({S}, {A})"
            )
        out = np.asarray(arr, dtype=np.float64)
        if not np.all(np.isfinite(out)) or np.any(out < 0):
            raise TaskError("stochastic policy has negative or non-finite probabilities")
        sums = out.sum(axis=1)
        bad = np.flatnonzero(live & (np.abs(sums - 1.0) > POLICY_ATOL))
        if bad.size:
            raise TaskError(
                f"stochastic policy row {bad[0]} sums to {sums[bad[0]]!r}; each row must sum to 1"
            )
        bad = np.argwhere(live[:, None] & ~mdp.admissible & (out > 0))
        if bad.size:
            s, a = bad[0]
            raise TaskError(
                f"stochastic policy puts probability {out[s, a]} on inadmissible action "
                f"{mdp.action_names[a]!r} ({a}) in state {s}"
            )
        return out
    raise TaskError(
        f"policy must be (S,) action ids or (S, A) probabilities; got an array of shape {arr.shape}"
    )


def policy_matrix(mdp: FiniteMDP, policy: np.ndarray) -> sp.csr_array:
    """``(S, S)`` CSR ``P_pi(s' | s)`` of a checked policy (rows of terminal states included)."""
    S = mdp.n_states
    if policy.ndim == 1:
        return sp.csr_array(mdp.P[policy * S + np.arange(S)])
    A = mdp.n_actions
    rows = np.repeat(np.arange(S), A)
    cols = (np.arange(A)[None, :] * S + np.arange(S)[:, None]).ravel()
    mix = sp.csr_array((policy.ravel(), (rows, cols)), shape=(S, A * S))
    return sp.csr_array(mix @ mdp.P)


def walker_matrix(mdp: FiniteMDP, policy: np.ndarray) -> sp.csr_array:
    """``P_pi^0``: the policy's chain with self-loops removed and terminal rows zeroed.

    This is the matrix of eq. 4.1: the sum over ``s' != s`` drops self-loops, and an episode ends
    on arrival in a terminal state. Its row sums are below one where the walker can stop: it
    stops on arrival at a terminal state and *its path stops counting* on a self-loop step (a path
    through a self-loop is not counted by eq. 4.1).
    """
    W = policy_matrix(mdp, policy)
    S = mdp.n_states
    rows = np.repeat(np.arange(S), np.diff(W.indptr))
    drop = (W.indices == rows) | mdp.terminal[rows] | ~(W.data > 0)
    walker = sp.csr_array((np.where(drop, 0.0, W.data), W.indices.copy(), W.indptr.copy()),
                          shape=(S, S))
    walker.eliminate_zeros()
    return walker


def trapped_states(walker: sp.csr_array, atol: float = 1e-12) -> np.ndarray:
    """States from which the walker can never stop: the policy loops forever from them.

    A state *leaks* when its row of ``P_pi^0`` sums to less than one (terminal, or a self-loop
    possible). States that cannot reach a leaking state form closed cycles of the policy that
    never reach a terminal state; the count metric of eq. 4.1 then grows with its horizon.
    Found exactly by one breadth-first search backwards from all leaking states at once.
    """
    leak = 1.0 - np.asarray(walker.sum(axis=1)).ravel() > atol
    into = walker.tocsc()  # column j lists the states that step into j
    reached = leak.copy()
    reach_backwards(into.indptr.astype(np.int64), into.indices.astype(np.int64), reached)
    return np.flatnonzero(~reached)


def loop_error(trapped: np.ndarray, what: str) -> TaskError:
    shown = ", ".join(str(s) for s in trapped[:8]) + (" ..." if trapped.size > 8 else "")
    return TaskError(
        f"the policy never terminates from {trapped.size} state(s) ({shown}): it cycles without "
        f"reaching a terminal state, so {what} would only measure the horizon. Learn the policy "
        "longer (or use the optimal one), or pass on_loop='truncate' to count up to the horizon"
    )


def sample_actions(policy: np.ndarray, states: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Actions for many states at once (deterministic lookup, or one draw per state)."""
    if policy.ndim == 1:
        return policy[states]
    cdf = np.cumsum(policy[states], axis=1)
    u = rng.random(states.shape[0]) * cdf[:, -1]
    return np.minimum((u[:, None] >= cdf).sum(axis=1), policy.shape[1] - 1).astype(np.int64)

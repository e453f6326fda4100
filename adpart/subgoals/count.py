"""The exhaustive count metric of eq. 4.1, by sparse matrix-vector iterations.

DESIGN.md fixes the interpretation: ``C^1 = (1/|S|) (P_pi^0)^T 1``, ``C^t = (P_pi^0)^T C^{t-1}``,
``C* = |S| sum_t C^t`` where ``P_pi^0`` is the policy's transition matrix with a zero diagonal
(and zero rows at terminal states: the episode ends on arrival). ``C^t(s)`` is then the
probability that a walker started uniformly is at ``s`` at step ``t`` having made no self-loop
step, and ``C*(s)`` the expected number of such arrivals (definition 4.3; the standard metric is
``|S|`` times the normalised one). The sum stops when the walker's remaining mass is negligible
(``tol``: ``C^n = C^{n+1}`` up to ``tol``) or after ``|S|`` steps, the cap of eq. 4.1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from adpart.errors import TaskError
from adpart.mdp.model import FiniteMDP
from adpart.subgoals.policy import (
    check_mdp,
    check_policy,
    loop_error,
    trapped_states,
    walker_matrix,
)
from adpart.subgoals.settings import ON_LOOP, CountSettings, given

__all__ = ["COUNT_TOL", "ON_LOOP", "CountMetric", "count_metric"]

#: Default stopping tolerance on the walker mass still alive (a fraction of the one walker).
COUNT_TOL = 1e-10


@dataclass(frozen=True, eq=False)
class CountMetric:
    """The count metric of every state and how it was computed.

    Attributes:
        counts: ``(S,)`` float64, ``C*`` (standard) or ``C^*-hat`` (normalised, eq. 4.1).
        normalised: which of the two ``counts`` holds.
        iterations: the number ``n`` of terms summed.
        remaining: walker mass still alive after the last term (<= tol when the sum is complete).
        trapped: states from which the policy never terminates (empty for a proper policy).
    """

    counts: np.ndarray
    normalised: bool
    iterations: int
    remaining: float
    trapped: np.ndarray

    @property
    def standard(self) -> np.ndarray:
        """``C*`` whichever form was asked for."""
        return self.counts * self.counts.shape[0] if self.normalised else self.counts


def count_metric(
    mdp: FiniteMDP,
    policy: np.ndarray,
    settings: CountSettings | None = None,
    *,
    normalised: bool = False,
    tol: float = COUNT_TOL,
    max_iter: int | None = None,
) -> CountMetric:
    """The (normalised) count metric ``C*_pi`` of eq. 4.1 for every state.

    Args:
        mdp: the task's MDP (its dynamics, terminal states and admissible actions are used).
        policy: ``(S,)`` action ids or ``(S, A)`` action probabilities.
        settings: the detector's :class:`~adpart.subgoals.settings.CountSettings` (None: its
            defaults); only its ``on_loop`` concerns the count: a policy that cycles without
            terminating (see :func:`trapped_states`) raises :class:`TaskError` with ``"error"``;
            ``"truncate"`` (default) sums to the cap as eq. 4.1 says.
        normalised: return ``C^*-hat`` (definition 4.3) instead of ``C* = |S| C^*-hat``.
        tol: stop when the mass of walkers still counting falls to ``tol`` or below.
        max_iter: the largest ``n`` of eq. 4.1; default ``|S|``.

    Returns:
        A :class:`CountMetric`.
    """
    on_loop = given(CountSettings, settings).on_loop
    mdp = check_mdp(mdp)
    pol = check_policy(mdp, policy)
    if not (np.isfinite(tol) and tol >= 0):
        raise TaskError(f"tol = {tol!r} must be a finite number >= 0")
    S = mdp.n_states
    cap = S if max_iter is None else int(max_iter)
    if cap < 1:
        raise TaskError(f"max_iter = {max_iter!r} must be >= 1")
    walker = walker_matrix(mdp, pol)
    trapped = trapped_states(walker)
    if trapped.size and on_loop == "error":
        raise loop_error(trapped, "the count metric")
    step = walker.T.tocsr()
    c = np.full(S, 1.0 / S)
    total = np.zeros(S)
    n = 0
    alive = 1.0
    while n < cap:
        c = step @ c
        total += c
        n += 1
        alive = float(c.sum())
        if alive <= tol:
            break
    counts = total if normalised else total * S
    counts.setflags(write=False)
    return CountMetric(counts, normalised, n, alive, trapped)

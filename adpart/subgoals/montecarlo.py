"""Monte Carlo count metric (definition 4.4) and the Bernstein sample bound (eqs. 4.3, thm 4.2).

Trajectories are sampled under the policy from uniform start states by compiled walkers
(:mod:`adpart.subgoals._walkers`), until they arrive at a terminal state or reach the horizon.
A trajectory's count of state ``s`` is its number of arrivals at ``s`` before its first
self-loop step, which makes the estimator
``C_H(s) = |S| * mean arrivals`` unbiased for the exhaustive ``C*`` of eq. 4.1 (whose sum over
``s' != s`` does not count paths through a self-loop; see :mod:`adpart.subgoals.count`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from adpart.errors import TaskError
from adpart.mdp.model import FiniteMDP
from adpart.subgoals._walkers import count_arrivals, expected_arrivals, walk_paths
from adpart.subgoals.policy import check_mdp, check_policy


@dataclass(frozen=True, eq=False)
class Trajectories:
    """Sampled state sequences.

    Attributes:
        paths: ``(N, L)`` int64; row ``i`` is ``s_0, s_1, ...`` of trajectory ``i`` padded with -1.
        lengths: ``(N,)`` number of states in each trajectory (``>= 1``).
        truncated: ``(N,)`` bool, True where the horizon cut the trajectory before it ended.
    """

    paths: np.ndarray
    lengths: np.ndarray
    truncated: np.ndarray

    @property
    def n(self) -> int:
        return self.paths.shape[0]


def sample_trajectories(
    mdp: FiniteMDP,
    policy: np.ndarray,
    n: int,
    rng: np.random.Generator,
    horizon: int | None = None,
    *,
    checked: bool = False,
) -> Trajectories:
    """Sample ``n`` trajectories under ``policy`` from uniform start states.

    Args:
        mdp: the MDP; an episode ends on arrival at a terminal state.
        policy: ``(S,)`` action ids or ``(S, A)`` probabilities.
        n: number of trajectories (>= 1).
        rng: the only source of randomness.
        horizon: the most steps a trajectory takes (default ``|S|``, the cap of eq. 4.1).
        checked: skip validating ``policy`` (callers that already did).
    """
    args, start, H = _walk_setup(mdp, policy, n, rng, horizon, checked)
    columns, truncated = walk_paths(*args, start, H, rng)
    paths = np.ascontiguousarray(columns.T)
    lengths = (paths >= 0).sum(axis=1)
    return Trajectories(paths, lengths, truncated)


def sample_arrivals(
    mdp: FiniteMDP,
    policy: np.ndarray,
    n: int,
    rng: np.random.Generator,
    horizon: int | None = None,
    *,
    checked: bool = False,
    starts: np.ndarray | None = None,
    expected: bool = False,
) -> tuple[np.ndarray, int]:
    """Arrival counts of ``n`` fresh trajectories, without keeping the trajectories.

    Returns ``(arrivals, cut)``: ``(S,)`` float64 arrivals of each state before each
    trajectory's first self-loop step (so ``|S| * arrivals / n`` is ``C_H`` of definition 4.4,
    the same estimator as :func:`arrival_counts` of :func:`sample_trajectories`), and the number
    of trajectories the horizon cut while they were still counting. A trajectory is not walked
    past its first self-loop step, whose later arrivals would not count.

    ``starts`` (``(n,)`` state ids) replaces the uniform draw of the start states, e.g. by the
    stratified stream of :class:`StartStream`. ``expected=True`` adds each trajectory's
    accumulated likelihoods of arrival instead of the arrivals drawn
    (:func:`adpart.subgoals._walkers.expected_arrivals`: same mean, smaller variance).
    """
    args, start, H = _walk_setup(mdp, policy, n, rng, horizon, checked, starts)
    arrivals = np.zeros(mdp.n_states)
    if expected:
        _keys, indptr, indices = mdp.sampler_arrays
        cut = expected_arrivals(np.ascontiguousarray(mdp.P.data, dtype=np.float64), indptr,
                                indices, *args[3:], start, H, rng, arrivals)
    else:
        cut = count_arrivals(*args, start, H, rng, arrivals)
    return arrivals, int(cut)


def _walk_setup(
    mdp: FiniteMDP, policy: np.ndarray, n: int, rng: np.random.Generator, horizon: int | None,
    checked: bool, starts: np.ndarray | None = None,
) -> tuple[tuple, np.ndarray, int]:
    """Validate, then ``(walker arguments, start states, horizon)``; draws the starts first."""
    mdp = check_mdp(mdp)
    pol = policy if checked else check_policy(mdp, policy)
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise TaskError(f"number of trajectories n = {n!r} must be an integer >= 1")
    H = mdp.n_states if horizon is None else int(horizon)
    if H < 1:
        raise TaskError(f"horizon = {horizon!r} must be >= 1")
    if starts is None:
        start = rng.integers(0, mdp.n_states, size=int(n))
    else:
        start = np.ascontiguousarray(starts, dtype=np.int64)
        if start.shape != (int(n),) or start.min() < 0 or start.max() >= mdp.n_states:
            raise TaskError(f"starts must be {n} state ids in 0..{mdp.n_states - 1}")
    stochastic = pol.ndim == 2
    actions = np.zeros(1, dtype=np.int64) if stochastic else pol
    cdf = np.cumsum(pol, axis=1) if stochastic else np.zeros((1, 1))
    return (*mdp.sampler_arrays, mdp.terminal, actions, cdf, stochastic), start, H


class StartStream:
    """Start states drawn uniformly *without replacement*: a random permutation of the states,
    taken in order, and a fresh permutation when it is used up.

    Every state is still equally likely at every draw, so ``C_H`` stays unbiased, but after
    ``k |S|`` draws every state has started exactly ``k`` trajectories: the start-state part of
    the sampling error (the only part on deterministic dynamics, where ``C_H`` is then exactly
    ``C*``) shrinks by the finite-population factor ``1 - N/|S|`` and vanishes at multiples of
    ``|S|``.
    """

    def __init__(self, n_states: int, rng: np.random.Generator) -> None:
        self.n_states = int(n_states)
        self.rng = rng
        self._perm = np.zeros(0, dtype=np.int64)
        self._pos = 0

    def take(self, n: int) -> np.ndarray:
        parts, need = [], int(n)
        while need > 0:
            if self._pos == self._perm.size:
                self._perm = self.rng.permutation(self.n_states).astype(np.int64)
                self._pos = 0
            k = min(need, self._perm.size - self._pos)
            parts.append(self._perm[self._pos:self._pos + k])
            self._pos += k
            need -= k
        return np.concatenate(parts) if parts else np.zeros(0, dtype=np.int64)


def arrival_counts(traj: Trajectories, n_states: int) -> np.ndarray:
    """``(S,)`` total arrivals over the trajectories, each cut at its first self-loop step.

    Arrivals are steps ``t >= 1``; the start state is not an arrival (``C^1`` of eq. 4.1 counts
    one-step successors). ``C_H = |S| * arrival_counts / N`` (definition 4.4).
    """
    p = traj.paths
    if p.shape[1] < 2:
        return np.zeros(n_states)
    step = p[:, 1:]
    looped = np.logical_or.accumulate(step == p[:, :-1], axis=1)
    ok = (step >= 0) & ~looped
    return np.bincount(step[ok], minlength=n_states).astype(np.float64)


def bernstein_samples(max_count: float, epsilon: float, confidence: float) -> int:
    """Smallest ``N`` satisfying eq. 4.3: ``N >= max C_H / eps^2 * 2 (1 + eps) ln(2 / (1 - p))``.

    With ``max_count = |S|`` (no loops: each state at most once per trajectory) this is the
    a-priori bound of section 5.1.4 (3600 states, eps = 5, p = 0.9 give 5,177; the seed prints
    5176, rounding down).
    """
    _check_bernstein(epsilon, confidence)
    if max_count <= 0:
        return 1
    log_term = math.log(2 / (1 - confidence))
    return max(1, math.ceil(max_count / epsilon**2 * 2 * (1 + epsilon) * log_term))


def bernstein_epsilon(n: int, max_count: float, confidence: float) -> float:
    """The ``eps_N`` that ``n`` samples guarantee by eq. 4.3 (its positive root in ``eps``)."""
    _check_bernstein(1.0, confidence)
    if n < 1:
        return math.inf
    cl = max_count * math.log(2 / (1 - confidence))
    return (cl + math.sqrt(cl * cl + 2 * n * cl)) / n


def _check_bernstein(epsilon: float, confidence: float) -> None:
    if not (np.isfinite(epsilon) and epsilon > 0):
        raise TaskError(f"epsilon = {epsilon!r} must be a positive number (count units)")
    if not (0.0 < confidence < 1.0):
        raise TaskError(f"confidence = {confidence!r} must be in (0, 1) (the p of eq. 4.3)")

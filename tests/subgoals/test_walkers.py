"""The compiled walkers (adpart.subgoals._walkers) against a vectorised numpy reference."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from adpart.envs.registry import get_domain
from adpart.mdp.generate import random_mdp
from adpart.mdp.solvers import solve
from adpart.subgoals import CountSettings, arrival_counts, count_metric, sample_trajectories
from adpart.subgoals.montecarlo import sample_arrivals


def numpy_trajectories(mdp, policy, n, rng, horizon):
    """The time-major numpy walker the compiled one replaces (the oracle for its random stream).

    Per time step: one action uniform per running walker (stochastic policies), then one
    successor uniform per running walker through ``FiniteMDP.sample_next``.
    """
    S, A = mdp.n_states, mdp.n_actions
    state = rng.integers(0, S, size=n)
    columns = [state.copy()]
    running = np.flatnonzero(~mdp.terminal[state])
    for _ in range(horizon):
        if running.size == 0:
            break
        cur = state[running]
        if policy.ndim == 1:
            act = policy[cur]
        else:
            cdf = np.cumsum(policy[cur], axis=1)
            u = rng.random(cur.size) * cdf[:, -1]
            act = np.minimum((u[:, None] >= cdf).sum(axis=1), A - 1)
        nxt = mdp.sample_next(cur, act, rng)
        state[running] = nxt
        col = np.full(n, -1, dtype=np.int64)
        col[running] = nxt
        columns.append(col)
        running = running[~mdp.terminal[nxt]]
    truncated = np.zeros(n, dtype=bool)
    truncated[running] = True
    return np.stack(columns, axis=1), truncated


def _mdp(seed, S, A):
    mdp = random_mdp(S, A, density=0.4, seed=seed)
    terminal = np.zeros(S, dtype=bool)
    terminal[-1] = True
    return mdp.with_rewards(mdp.R, terminal=terminal)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 10_000), S=st.integers(2, 12), A=st.integers(1, 3),
       stochastic=st.booleans(), horizon=st.integers(1, 30))
def test_walk_paths_draws_like_the_numpy_walker(seed, S, A, stochastic, horizon):
    mdp = _mdp(seed, S, A)
    rng = np.random.default_rng(seed)
    policy = (rng.dirichlet(np.ones(A), size=S) if stochastic
              else rng.integers(0, A, S).astype(np.int64))
    traj = sample_trajectories(mdp, policy, 17, np.random.default_rng(seed + 1), horizon)
    paths, truncated = numpy_trajectories(mdp, policy, 17, np.random.default_rng(seed + 1),
                                          horizon)
    np.testing.assert_array_equal(traj.paths, paths)
    np.testing.assert_array_equal(traj.truncated, truncated)
    np.testing.assert_array_equal(traj.lengths, (paths >= 0).sum(axis=1))


def test_sample_arrivals_matches_path_counts_in_distribution():
    """Fixed seed 11, 40,000 trajectories: the two estimators of C_H agree with eq. 4.1."""
    mdp = _mdp(3, 6, 2)
    policy = np.array([0, 1, 0, 1, 0, 1])
    exact = count_metric(mdp, policy, CountSettings(on_loop="truncate")).counts
    rng = np.random.default_rng(11)
    arrivals, _ = sample_arrivals(mdp, policy, 40_000, rng)
    traj = sample_trajectories(mdp, policy, 40_000, rng)
    from_paths = mdp.n_states * arrival_counts(traj, mdp.n_states) / traj.n
    assert np.max(np.abs(mdp.n_states * arrivals / 40_000 - exact)) <= 0.05
    assert np.max(np.abs(from_paths - exact)) <= 0.05


def test_sample_arrivals_on_four_rooms_is_close_to_the_count_metric():
    mdp = get_domain("four-rooms").mdp("G1")
    policy = solve(mdp).policy
    exact = count_metric(mdp, policy).counts
    arrivals, cut = sample_arrivals(mdp, policy, 20_000, np.random.default_rng(2))
    est = mdp.n_states * arrivals / 20_000
    assert cut == 0
    # Counts are at most ~|S|; 20,000 trajectories put the error well under 2% of the largest.
    assert np.max(np.abs(est - exact)) <= 0.02 * exact.max()


def test_sample_arrivals_reports_horizon_cuts():
    mdp = get_domain("four-rooms").mdp("G1")
    policy = solve(mdp).policy
    _, cut = sample_arrivals(mdp, policy, 500, np.random.default_rng(0), horizon=2)
    assert 0 < cut < 500


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), S=st.integers(2, 15), A=st.integers(1, 3))
def test_trapped_states_match_a_fixpoint_oracle(seed, S, A):
    from adpart.subgoals import trapped_states, walker_matrix

    mdp = random_mdp(S, A, density=0.25, seed=seed)
    terminal = np.random.default_rng(seed).random(S) < 0.15
    mdp = mdp.with_rewards(mdp.R, terminal=terminal)
    policy = np.random.default_rng(seed + 1).integers(0, A, S).astype(np.int64)
    W = walker_matrix(mdp, policy).toarray()
    # Oracle: the walker can stop from s if s leaks, or some successor of s can stop.
    can_stop = W.sum(axis=1) < 1 - 1e-12
    while True:
        grown = can_stop | ((W > 0).astype(int) @ can_stop.astype(int) > 0)
        if np.array_equal(grown, can_stop):
            break
        can_stop = grown
    np.testing.assert_array_equal(trapped_states(walker_matrix(mdp, policy)),
                                  np.flatnonzero(~can_stop))
    # the walker matrix itself: P_pi without the diagonal and without terminal rows
    P = mdp.P.toarray().reshape(A, S, S)[policy, np.arange(S)]
    expect = np.where(np.eye(S, dtype=bool) | terminal[:, None], 0.0, P)
    np.testing.assert_allclose(W, expect)

"""Count metric against brute-force path enumeration, MC convergence, domains, bad input."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adpart.envs.registry import get_domain
from adpart.errors import TaskError
from adpart.mdp.model import FiniteMDP
from adpart.mdp.solvers import solve
from adpart.plugins.builtin.detectors import Betweenness, CountExhaustive, CountMonteCarlo
from adpart.subgoals import (
    arrival_counts,
    bernstein_samples,
    betweenness,
    count_metric,
    discover_exhaustive,
    discover_monte_carlo,
    sample_trajectories,
    t_test_threshold,
    transition_graph,
)


def _tiny_mdp(seed: int, S: int) -> FiniteMDP:
    """Random dense-ish MDP with state S-1 terminal, 2 actions."""
    rng = np.random.default_rng(seed)
    P = rng.random((S, 2, S)) * (rng.random((S, 2, S)) < 0.6)
    P[:, :, S - 1] += 0.2
    P /= P.sum(axis=2, keepdims=True)
    term = np.zeros(S, bool)
    term[S - 1] = True
    return FiniteMDP.from_dense(P, np.zeros((S, 2)), 0.9, terminal=term)


def _brute_force(mdp: FiniteMDP, policy: np.ndarray) -> np.ndarray:
    """Enumerate all paths of up to |S| steps from every start (no self-loops, stop at terminal)."""
    S = mdp.n_states
    P = mdp.P.toarray().reshape(mdp.n_actions, S, S)
    C = np.zeros(S)
    for s0 in range(S):
        frontier = [(s0, 1.0 / S)]
        for _ in range(S):
            nxt = []
            for s, w in frontier:
                if mdp.terminal[s]:
                    continue
                for s2 in range(S):
                    pr = P[policy[s], s, s2]
                    if s2 != s and pr > 0:
                        C[s2] += w * pr
                        nxt.append((s2, w * pr))
            frontier = nxt
    return S * C


@settings(max_examples=25)
@given(seed=st.integers(0, 10_000), S=st.integers(2, 5), pol_seed=st.integers(0, 100))
def test_subgoal_count_equals_path_enumeration(seed, S, pol_seed):
    mdp = _tiny_mdp(seed, S)
    policy = np.random.default_rng(pol_seed).integers(0, 2, S)
    cm = count_metric(mdp, policy, tol=0.0, on_loop="truncate")
    np.testing.assert_allclose(cm.counts, _brute_force(mdp, policy), rtol=1e-10, atol=1e-12)
    norm = count_metric(mdp, policy, tol=0.0, normalised=True, on_loop="truncate")
    np.testing.assert_allclose(norm.counts * S, cm.counts, rtol=1e-12)


def test_subgoal_mc_converges_to_exhaustive():
    """Fixed seed 7, 20,000 trajectories: every |C_H(s) - C*(s)| <= 0.05 (counts are O(1))."""
    mdp = _tiny_mdp(3, 5)
    policy = np.array([0, 1, 0, 1, 0])
    exact = count_metric(mdp, policy).counts
    # the horizon defaults to |S|, the cap of eq. 4.1, as in the exhaustive sum
    traj = sample_trajectories(mdp, policy, 20_000, np.random.default_rng(7))
    est = mdp.n_states * arrival_counts(traj, mdp.n_states) / traj.n
    assert np.max(np.abs(est - exact)) <= 0.05


def test_subgoal_two_rooms_doorway_only_optimal_policy():
    domain = get_domain("two-rooms")
    mdp = domain.mdp("reach-goal")
    door = int(np.flatnonzero(domain.dynamics().features["door"])[0])
    policy = solve(mdp).policy
    for seed in range(5):
        res = CountExhaustive().detect(mdp, policy, np.random.default_rng(seed))
        assert res.subgoals.tolist() == [door]
        assert res.scores.argmax() == door


def test_subgoal_two_rooms_doorway_only_q_learned_policy():
    from adpart.learning import q_learning

    domain = get_domain("two-rooms")
    mdp = domain.mdp("reach-goal")
    door = int(np.flatnonzero(domain.dynamics().features["door"])[0])
    learn_on = mdp.with_rewards(mdp.R, initial=np.full(mdp.n_states, 1 / mdp.n_states))
    q = q_learning(learn_on, runs=1, episodes=3000, seed=1, epsilon=0.2)
    policy = q.greedy_policies()[0]
    res = CountExhaustive().detect(mdp, policy, np.random.default_rng(0))
    assert res.subgoals.tolist() == [door]


def test_subgoal_four_rooms_count_follows_the_t_test():
    """four-rooms G1, optimal policy: the subgoals are exactly the states passing eq. 4.2.

    The threshold is recomputed from the reported ratio statistics with scipy's t quantile
    (``mean + t_{1-p, N-1} sd / sqrt(N)``), and the subgoals must be exactly the states whose
    score reaches it; the counts behind the scores are checked against path enumeration above.
    """
    from scipy import stats as scipy_stats

    mdp = get_domain("four-rooms").mdp("G1")
    policy = solve(mdp).policy
    res = CountExhaustive().detect(mdp, policy, np.random.default_rng(0))
    n, mean, sd = (res.stats[k] for k in ("samples_per_state", "ratio_mean", "ratio_sd"))
    assert res.threshold == pytest.approx(
        mean + scipy_stats.t.ppf(1 - 0.025, n - 1) * sd / np.sqrt(n), rel=1e-12)
    assert res.subgoals.tolist() == np.flatnonzero(res.scores >= res.threshold).tolist()
    assert 0 < res.subgoals.size < mdp.n_states // 4  # a few bottlenecks, not a whole room
    mc = CountMonteCarlo().detect(mdp, policy, np.random.default_rng(0))
    assert set(mc.subgoals.tolist()) <= set(res.subgoals.tolist())
    assert mc.stats["history"][-1]["samples"] == mc.stats["samples"]


def test_subgoal_four_rooms_betweenness():
    """Local maxima of betweenness (Simsek & Barto's rule) are the 8 cells flanking the hallways.

    A one-cell hallway of a 4-connected grid can never be among the top: every shortest path
    through it also passes both cells beside it, and those cells carry paths inside their rooms
    as well. Checked here for all four hallways; the top 4 is hallway 25 and its neighbours.
    """
    mdp = get_domain("four-rooms").mdp("G1")
    res = Betweenness().detect(mdp, None, np.random.default_rng(0))
    assert res.subgoals.tolist() == [24, 26, 42, 54, 58, 70, 87, 89]
    graph = transition_graph(mdp)
    for hallway in (25, 51, 62, 88):
        neighbours = graph[[hallway]].indices
        assert neighbours.size == 2 and set(neighbours) <= set(res.subgoals.tolist())
        assert np.all(res.scores[neighbours] > res.scores[hallway])
    top = Betweenness(select="top", top=12).detect(mdp, None, np.random.default_rng(0))
    assert {25, 51, 62, 88} <= set(top.subgoals.tolist())
    assert Betweenness(select="top").detect(mdp, None, None).subgoals.tolist() == [24, 25, 26, 54]


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 10_000), S=st.integers(2, 9))
def test_local_maxima_match_a_loop_oracle(seed, S):
    import scipy.sparse as sp

    from adpart.subgoals.literature import local_maxima

    rng = np.random.default_rng(seed)
    adj = rng.random((S, S)) < 0.3
    scores = rng.integers(0, 4, S).astype(float)
    got = local_maxima(sp.csr_array(adj.astype(float)), scores)
    expect = [s for s in range(S) if scores[s] > 0 and all(
        scores[s] > scores[t] for t in range(S) if t != s and (adj[s, t] or adj[t, s]))]
    assert got.tolist() == expect


def _brandes_oracle(adj: np.ndarray) -> np.ndarray:
    """Betweenness by enumerating all shortest paths explicitly (tiny graphs)."""
    S = adj.shape[0]
    bc = np.zeros(S)
    for s, t in itertools.permutations(range(S), 2):
        paths, layer = [], [[s]]
        while layer and not paths:
            nxt = []
            for p in layer:
                for w in np.flatnonzero(adj[p[-1]]):
                    if w not in p:
                        (paths if w == t else nxt).append([*p, int(w)])
            layer = nxt
        for p in paths:
            for v in p[1:-1]:
                bc[v] += 1.0 / len(paths)
    return bc


@settings(max_examples=20)
@given(seed=st.integers(0, 10_000), S=st.integers(2, 7))
def test_subgoal_betweenness_matches_oracle(seed, S):
    import scipy.sparse as sp

    adj = np.random.default_rng(seed).random((S, S)) < 0.35
    np.fill_diagonal(adj, False)
    got = betweenness(sp.csr_array(adj.astype(float)), chunk=3)
    np.testing.assert_allclose(got, _brandes_oracle(adj), atol=1e-9)


def test_subgoal_bad_inputs():
    mdp = get_domain("two-rooms").mdp("reach-goal")
    good = solve(mdp).policy
    rng = np.random.default_rng(0)
    with pytest.raises(TaskError, match="entries"):
        count_metric(mdp, good[:-1])
    with pytest.raises(TaskError, match="not an action id"):
        count_metric(mdp, np.full(mdp.n_states, 99))
    with pytest.raises(TaskError, match="level p"):
        discover_exhaustive(mdp, good, rng, p=1.5)
    with pytest.raises(TaskError, match="level p"):
        t_test_threshold(0.0, 1.0, 5, 0.0)
    with pytest.raises(TaskError, match="integer action"):
        count_metric(mdp, good.astype(float))


def test_subgoal_inadmissible_action():
    mdp = get_domain("four-rooms").mdp("G1")
    adm = mdp.admissible.copy()
    adm[0, 0] = False
    m2 = FiniteMDP(mdp.P, mdp.R, mdp.gamma, terminal=mdp.terminal, admissible=adm)
    pol = solve(m2).policy
    pol[0] = 0
    with pytest.raises(TaskError, match="inadmissible"):
        count_metric(m2, pol)


def test_subgoal_looping_policy():
    """A deterministic 2-cycle never terminates: the core errors by default, the detector plugins
    truncate by default (the pipeline must work on any policy) and error on request."""
    P = np.zeros((3, 1, 3))
    P[0, 0, 1] = P[1, 0, 0] = P[2, 0, 2] = 1.0
    mdp = FiniteMDP.from_dense(P, np.zeros((3, 1)), 0.9, terminal=np.array([False, False, True]))
    pol = np.zeros(3, dtype=np.int64)
    with pytest.raises(TaskError, match="never terminates"):
        count_metric(mdp, pol)
    with pytest.raises(TaskError, match="never terminates"):
        CountMonteCarlo(on_loop="error").detect(mdp, pol, np.random.default_rng(0))
    assert CountMonteCarlo().kw["on_loop"] == "truncate"
    cm = count_metric(mdp, pol, on_loop="truncate")
    assert cm.iterations == 3 and cm.trapped.tolist() == [0, 1]


def test_subgoal_bernstein_seed_example():
    assert bernstein_samples(3600, 5.0, 0.9) == 5177  # the seed prints 5176 (rounded down)


def test_subgoal_transition_graph_no_self_loops():
    g = transition_graph(get_domain("four-rooms").mdp("G1"))
    assert g.diagonal().sum() == 0


def test_expected_arrivals_are_unbiased_and_tighter_than_drawn_arrivals():
    from adpart.subgoals.montecarlo import sample_arrivals

    mdp = _tiny_mdp(3, 5)
    policy = np.array([0, 1, 0, 1, 0])
    exact = count_metric(mdp, policy).counts
    S, n = mdp.n_states, 20_000
    expected, _ = sample_arrivals(mdp, policy, n, np.random.default_rng(7), expected=True)
    assert np.max(np.abs(S * expected / n - exact)) <= 0.05
    # smaller variance: mean squared error over 40 independent estimates of 200 samples each
    mse = {}
    for flag in (False, True):
        errs = [S * sample_arrivals(mdp, policy, 200, np.random.default_rng(k), expected=flag)[0]
                / 200 - exact for k in range(40)]
        mse[flag] = float(np.mean(np.square(errs)))
    assert mse[True] < mse[False]


@settings(max_examples=20, deadline=None)
@given(S=st.integers(1, 40), n=st.integers(1, 200), seed=st.integers(0, 1000))
def test_start_stream_draws_every_state_once_per_pass(S, n, seed):
    from adpart.subgoals.montecarlo import StartStream

    stream = StartStream(S, np.random.default_rng(seed))
    drawn = np.concatenate([stream.take(k) for k in (n // 3, n - n // 3)])
    counts = np.bincount(drawn, minlength=S)
    assert drawn.size == n
    assert counts.max() - counts.min() <= 1  # without replacement within each pass


@pytest.mark.parametrize("name", ["two-rooms", "three-floor"])
def test_monte_carlo_agrees_with_exhaustive_by_default(name):
    """Issue 22: with the default stopping rule the two subgoal sets have Jaccard >= 0.9."""
    mdp = get_domain(name).mdp()
    policy = solve(mdp).policy
    ex = discover_exhaustive(mdp, policy, np.random.default_rng(0))
    mc = discover_monte_carlo(mdp, policy, np.random.default_rng(0))
    union = np.union1d(ex.subgoals, mc.subgoals).size
    jaccard = np.intersect1d(ex.subgoals, mc.subgoals).size / union if union else 1.0
    assert ex.subgoals.size > 0
    assert jaccard >= 0.9
    assert mc.stats["stop_reason"] == "passes"


def test_monte_carlo_agrees_with_exhaustive_on_slippery_three_floor_arm():
    mdp = get_domain("three-floor-arm").mdp("deliver")
    policy = solve(mdp).policy
    ex = discover_exhaustive(mdp, policy, np.random.default_rng(0))
    mc = discover_monte_carlo(mdp, policy, np.random.default_rng(0))
    both = np.intersect1d(ex.subgoals, mc.subgoals).size
    assert both / np.union1d(ex.subgoals, mc.subgoals).size >= 0.9

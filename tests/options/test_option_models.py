"""Exact option models against independent oracles: a dense numpy solve, Bellman iteration,
and Monte Carlo rollouts of the option on the stochastic domains (fixed seeds)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import norm

from adpart.envs.registry import get_domain
from adpart.execution import LocalExecutor
from adpart.mdp.generate import random_mdp
from adpart.mdp.model import FiniteMDP
from adpart.options import (
    Option,
    option_model,
    option_model_by_iteration,
    option_models,
    sample_option_model,
    subgoal_options,
)


def random_option(mdp: FiniteMDP, seed: int, stochastic: bool) -> Option:
    rng = np.random.default_rng(seed)
    S, A = mdp.n_states, mdp.n_actions
    init = rng.random(S) < 0.6
    init[rng.integers(S)] = True
    beta = np.where(rng.random(S) < 0.3, 1.0, rng.uniform(0.05, 1.0, S))
    if stochastic:
        pol = rng.random((S, A)) * (rng.random((S, A)) < 0.7)
        pol[np.arange(S), rng.integers(0, A, S)] += 0.1
        pol /= pol.sum(axis=1, keepdims=True)
    else:
        pol = rng.integers(0, A, S)
    return Option(f"random-{seed}", init, pol, beta)


def dense_oracle(mdp: FiniteMDP, o: Option):
    """R, F and D on every state by dense numpy solves over all S states (no restriction)."""
    S, A = mdp.n_states, mdp.n_actions
    P = mdp.P.toarray().reshape(A, S, S)
    pi = np.eye(A)[o.policy] if o.deterministic else o.policy
    P_pi = np.einsum("sa,ast->st", pi, P)
    r_pi = np.einsum("sa,sa->s", pi, mdp.R)
    c = np.where(mdp.terminal, 0.0, 1.0 - o.beta)
    g = mdp.gamma
    M = np.eye(S) - g * P_pi * c[None, :]
    R = np.linalg.solve(M, r_pi)
    F = np.linalg.solve(M, g * P_pi * (1.0 - c)[None, :])
    D = np.linalg.solve(np.eye(S) - P_pi * c[None, :], np.ones(S))
    return R, F, D


@settings(max_examples=30)
@given(
    seed=st.integers(0, 10_000),
    S=st.integers(2, 12),
    A=st.integers(1, 4),
    gamma=st.sampled_from([0.5, 0.9, 0.99, 1.0]),
    stochastic=st.booleans(),
    with_terminal=st.booleans(),
)
def test_exact_model_matches_dense_oracle(seed, S, A, gamma, stochastic, with_terminal):
    base = random_mdp(S, A, density=0.4, seed=seed, gamma=gamma)
    terminal = np.zeros(S, bool)
    if with_terminal:
        terminal[seed % S] = True
    mdp = base.with_rewards(base.R, terminal=terminal)
    o = random_option(mdp, seed, stochastic)
    m = option_model(mdp, o)
    R, F, D = dense_oracle(mdp, o)
    rows = np.flatnonzero(o.initiation & ~terminal)
    np.testing.assert_allclose(m.R[rows], R[rows], atol=1e-9, rtol=1e-9)
    np.testing.assert_allclose(m.F.toarray()[rows], F[rows], atol=1e-9)
    np.testing.assert_allclose(m.duration[rows], D[rows], rtol=1e-9)
    outside = np.flatnonzero(~(o.initiation & ~terminal))
    assert np.all(m.R[outside] == 0) and m.F[outside].nnz == 0
    it_model, _ = option_model_by_iteration(mdp, o, tol=1e-11)
    np.testing.assert_allclose(it_model.R, m.R, atol=1e-8)
    assert abs(it_model.F - m.F).max() < 1e-8


def test_parallel_executor_gives_the_serial_models():
    mdp = random_mdp(40, 3, density=0.1, seed=3, gamma=0.95)
    opts = [random_option(mdp, s, s % 2 == 0) for s in range(6)]
    serial = option_models(mdp, opts)
    with LocalExecutor(workers=2) as ex:
        parallel = option_models(mdp, opts, executor=ex)
    for a, b in zip(serial, parallel, strict=True):
        assert a.name == b.name
        np.testing.assert_array_equal(a.R, b.R)
        assert abs(a.F - b.F).max() == 0.0
        np.testing.assert_array_equal(a.duration, b.duration)


#: Family-wise confidence of the Monte Carlo comparisons: all of them at once hold w.p. 99.9%.
FAMILY_CONFIDENCE = 0.999


def assert_within_ci(exact, estimate, se, n_comparisons):
    """|estimate - exact| <= z se with a Bonferroni-corrected two-sided normal z."""
    z = norm.ppf(1.0 - (1.0 - FAMILY_CONFIDENCE) / (2.0 * n_comparisons))
    err = np.abs(estimate - exact)
    assert np.all(err <= z * se + 1e-9), (float((err / np.maximum(se, 1e-300)).max()), z)


def check_against_rollouts(mdp, options, seed, n_starts=25, n_rollouts=800):
    rng = np.random.default_rng(seed)
    models = option_models(mdp, options)
    n_cmp = 3 * n_starts * len(options)  # R, mass of F, duration per start state
    for o, m in zip(options, models, strict=True):
        pool = np.flatnonzero(m.admissible)
        starts = np.sort(rng.choice(pool, size=min(n_starts, pool.size), replace=False))
        est = sample_option_model(mdp, o, rng, starts=starts, n_rollouts=n_rollouts)
        assert est.truncated == 0
        assert_within_ci(m.R[starts], est.R, est.R_se, n_cmp)
        assert_within_ci(m.mass[starts], est.mass, est.mass_se, n_cmp)
        assert_within_ci(m.duration[starts], est.duration, est.duration_se, n_cmp)
        # The estimated F rows sum to the estimated masses (same rollouts).
        np.testing.assert_allclose(np.asarray(est.F.sum(axis=1)).ravel(), est.mass, atol=1e-12)


def test_models_match_rollouts_three_floor_arm():
    mdp = get_domain("three-floor-arm").mdp()
    doors = np.flatnonzero((mdp.features["door"] == 1) & ~mdp.terminal)
    subgoals = doors[[0, 7, 15, 30]]
    check_against_rollouts(mdp, subgoal_options(mdp, subgoals), seed=11)


def test_models_match_rollouts_parr_maze_with_stochastic_policy():
    mdp = get_domain("parr-maze").mdp()
    subgoals = np.array([400, 1200, 2000, 2800])
    options = subgoal_options(mdp, subgoals)
    # A stochastic variant: 70 % the subgoal policy, 30 % uniform; ends w.p. 0.02 per step too.
    base = options[1]
    pol = 0.3 * mdp.admissible / mdp.admissible.sum(axis=1, keepdims=True)
    pol[np.arange(mdp.n_states), base.policy] += 0.7
    beta = np.maximum(base.beta, 0.02)
    noisy = Option("noisy-to-1200", base.initiation, pol, beta)
    check_against_rollouts(mdp, [*options[::2], noisy], seed=5)


@pytest.mark.parametrize("gamma", [0.9, 1.0])
def test_iteration_reference_counts_iterations(gamma):
    base = random_mdp(30, 2, density=0.2, seed=1, gamma=gamma)
    o = random_option(base, 2, stochastic=False)
    exact = option_model(base, o)
    ref, iterations = option_model_by_iteration(base, o)
    assert iterations > 1
    np.testing.assert_allclose(ref.R, exact.R, atol=1e-8)

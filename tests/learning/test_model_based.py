"""The known-dynamics learner: its planner against the solvers' Q*, its two kernels against each
other, its knowledge against the guard, and what it learns."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adpart.learning.knowledge import FLAT, KnowledgeError, guard
from adpart.learning.model_based import (
    KNOWN_DYNAMICS,
    PLAN_TOLERANCE,
    _plan,
    _RewardModel,
    known_dynamics_learning,
)
from adpart.learning.settings import Run
from adpart.mdp.generate import random_grid_mdp
from adpart.mdp.solvers import q_from_v, solve

from .test_hierarchical import goal_grid


def _csr(mdp):
    P = mdp.P.tocsr()
    return P.indptr.astype(np.int64), P.indices.astype(np.int64), P.data.astype(np.float64)


@settings(max_examples=25, deadline=None)
@given(n=st.integers(9, 49), slip=st.sampled_from([0.0, 0.2, 0.5]), seed=st.integers(0, 10**6))
def test_planning_with_the_true_rewards_gives_the_solvers_q_star(n, slip, seed):
    mdp = random_grid_mdp(n, slip=slip, terminal_fraction=0.1, seed=seed)
    S, A = mdp.n_states, mdp.n_actions
    adm = np.asarray(mdp.admissible, dtype=bool)
    Q = np.where(adm, 0.0, -np.inf)
    _plan(*_csr(mdp), np.asarray(mdp.R, dtype=np.float64), np.asarray(mdp.terminal), adm, Q,
          float(mdp.gamma), S, A)
    expected = q_from_v(mdp, solve(mdp, 1e-12).V)
    live = adm & ~np.asarray(mdp.terminal)[:, None]
    tolerance = 10 * PLAN_TOLERANCE / (1 - mdp.gamma)
    np.testing.assert_allclose(Q[live], expected[live], atol=tolerance)


def test_an_untried_pair_is_worth_the_best_reward_seen_so_far():
    m = _RewardModel(2, 2)
    np.testing.assert_array_equal(m.R_hat(), 0.0)  # nothing seen: 0
    m.r_sum[0, 0], m.n_sa[0, 0] = -2.0, 2
    np.testing.assert_array_equal(m.R_hat(), [[-1.0, 0.0], [0.0, 0.0]])
    m.r_sum[1, 1], m.n_sa[1, 1] = 5.0, 1
    np.testing.assert_array_equal(m.R_hat(), [[-1.0, 5.0], [5.0, 5.0]])


@pytest.mark.extended
@pytest.mark.parametrize("slip", [0.0, 0.3])
def test_the_compiled_and_the_interpreted_kernel_agree_bit_for_bit(slip):
    mdp = random_grid_mdp(36, slip=slip, terminal_fraction=0.05, seed=4)
    run = {"runs": 3, "episodes": 12, "seed": 9, "eval_every": 4, "max_steps_per_episode": 200}
    a = known_dynamics_learning(mdp, Run(kernel="python", **run))
    b = known_dynamics_learning(mdp, Run(kernel="numba", **run))
    assert np.array_equal(a.Q, b.Q)
    for column in a.curve.columns:
        assert np.array_equal(a.curve[column], b.curve[column], equal_nan=True), column


def test_it_reads_the_dynamics_it_declares_and_no_rewards():
    mdp = goal_grid()
    run = Run(runs=2, episodes=40, seed=0, eval_every=10)
    res = known_dynamics_learning(guard(mdp, KNOWN_DYNAMICS), run)
    assert res.parameters["knowledge"] == KNOWN_DYNAMICS.to_dict()
    assert np.array_equal(res.Q, known_dynamics_learning(mdp, run).Q)
    with pytest.raises(KnowledgeError, match="read P"):
        known_dynamics_learning(guard(mdp, FLAT), run)


def test_it_learns_a_deterministic_goal_task_to_the_optimum():
    mdp = goal_grid()
    res = known_dynamics_learning(mdp, Run(runs=4, episodes=60, seed=1, eval_every=10))
    np.testing.assert_allclose(res.curve.matrix("value_gap")[:, -1], 0.0, atol=1e-9)

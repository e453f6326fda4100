"""Successor features with GPI: exact values against explicit successor features, the GPI
theorem against exact policy evaluation, and the learner's reproducibility, knowledge and CLI."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from adpart.learning.knowledge import Knowledge, guard
from adpart.learning.qlearning import q_learning
from adpart.learning.settings import Run
from adpart.learning.sf_gpi import SuccessorFeatures, sf_gpi_learning
from adpart.mdp.evaluation import greedy_policy, policy_evaluation
from adpart.mdp.generate import random_mdp
from adpart.mdp.model import FiniteMDP

from .test_hierarchical import goal_grid


def explicit_psi(P: sp.csr_array, policy: np.ndarray, gamma: float,
                 terminal: np.ndarray) -> np.ndarray:
    """``(SA, SA)`` successor features of pair-indicator features, by their definition:
    ``psi = phi + gamma M psi`` with ``M[(s, a), (s', a')] = P(s'|s, a) [a' = pi(s')]`` (zero
    into terminal states), solved densely. Index ``s * A + a``."""
    AS, S = P.shape
    A = AS // S
    dense = P.toarray().reshape(A, S, S)  # [a, s, s']
    M = np.zeros((S * A, S * A))
    for s in range(S):
        for a in range(A):
            for s2 in range(S):
                if not terminal[s2]:
                    M[s * A + a, s2 * A + policy[s2]] += dense[a, s, s2]
    return np.linalg.inv(np.eye(S * A) - gamma * M)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(2, 9), A=st.integers(1, 4),
       gamma=st.floats(0.05, 0.97))
def test_values_are_the_explicit_successor_features_times_w(seed, n, A, gamma):
    mdp = random_mdp(n, A, density=0.4, seed=seed, gamma=gamma)
    rng = np.random.default_rng(seed)
    policies = rng.integers(0, A, size=(3, n))
    w = rng.standard_normal((n, A))
    terminal = rng.random(n) < 0.3
    sf = SuccessorFeatures(mdp.P, policies, gamma)
    Q = sf.values(w, terminal)
    for i, pi in enumerate(policies):
        psi = explicit_psi(mdp.P, pi, gamma, terminal)
        np.testing.assert_allclose(Q[i], (psi @ w.reshape(-1)).reshape(n, A), atol=1e-9)
    np.testing.assert_allclose(sf.gpi(w, terminal), Q.max(axis=0))


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(2, 12), A=st.integers(2, 4))
def test_gpi_is_at_least_as_good_as_every_base_policy(seed, n, A):
    """Barreto et al. (2017), Theorem 1: the greedy policy on max_i Q^{pi_i} is at least as
    good as every pi_i at every state, here by exact policy evaluation of each."""
    base = random_mdp(n, A, density=0.3, seed=seed, gamma=0.9)
    rng = np.random.default_rng(seed + 1)
    w = rng.standard_normal((n, A))
    task = FiniteMDP(base.P, w, 0.9)
    policies = rng.integers(0, A, size=(4, n))
    gpi = greedy_policy(SuccessorFeatures(task.P, policies, 0.9).gpi(w, np.zeros(n, bool)))
    best = np.max([policy_evaluation(task, pi) for pi in policies], axis=0)
    assert np.all(policy_evaluation(task, gpi) >= best - 1e-9)
    # with the optimal policy among the bases, GPI's policy is optimal
    from adpart.mdp.solvers import value_iteration

    star = value_iteration(task, epsilon=1e-12)
    with_star = np.vstack([policies, star.policy])
    gpi = greedy_policy(SuccessorFeatures(task.P, with_star, 0.9).gpi(w, np.zeros(n, bool)))
    np.testing.assert_allclose(policy_evaluation(task, gpi), star.V, atol=1e-8)


def test_a_discount_of_one_and_foreign_policies_are_refused():
    mdp = goal_grid()
    with pytest.raises(Exception, match="discount below 1"):
        SuccessorFeatures(mdp.P, np.zeros((1, mdp.n_states), int), 1.0)
    with pytest.raises(Exception, match=r"base policies must be \(n, 25\)"):
        sf_gpi_learning(mdp, Run(runs=1, episodes=2), policies=np.zeros((1, 3), int))


def _prior(mdp: FiniteMDP, runs: int = 4):
    first = q_learning(mdp, Run(runs=runs, episodes=40, seed=3, eval_every=10))
    return first, greedy_policy(first.Q.reshape(-1, mdp.n_actions)).reshape(runs, -1)


def test_the_kernels_agree_and_the_seed_fixes_the_result():
    mdp = goal_grid()
    first, pis = _prior(mdp)
    run = Run(runs=3, episodes=25, seed=5, eval_every=5)
    a = sf_gpi_learning(mdp, run, policies=pis, experience=first.experience)
    b = sf_gpi_learning(mdp, Run(runs=3, episodes=25, seed=5, eval_every=5, kernel="python"),
                        policies=pis, experience=first.experience)
    np.testing.assert_array_equal(a.Q, b.Q)
    np.testing.assert_array_equal(a.curve.matrix("value_gap"), b.curve.matrix("value_gap"))
    again = sf_gpi_learning(mdp, run, policies=pis, experience=first.experience)
    np.testing.assert_array_equal(a.curve.matrix("steps"), again.curve.matrix("steps"))
    assert a.parameters["base_policies"] == len(np.unique(pis, axis=0))


def test_on_experience_it_reads_no_dynamics_and_no_rewards_of_the_task():
    """Guarded against the task's model, the learner on earlier runs' counts runs (and gives
    what it gives unguarded); with the true model it must declare the dynamics."""
    mdp = goal_grid()
    first, pis = _prior(mdp)
    run = Run(runs=2, episodes=15, seed=2, eval_every=5)
    declared = Knowledge("estimated", "observed")
    guarded = sf_gpi_learning(guard(mdp, declared), run, policies=pis,
                              experience=first.experience)
    plain = sf_gpi_learning(mdp, run, policies=pis, experience=first.experience)
    np.testing.assert_array_equal(guarded.Q, plain.Q)
    knows = Knowledge.from_dict(plain.parameters["knowledge"])
    assert (knows.dynamics, knows.rewards) == ("estimated", "observed")
    from adpart.learning.knowledge import KnowledgeError

    with pytest.raises(KnowledgeError, match="read P"):
        sf_gpi_learning(guard(mdp, declared), run, policies=pis)  # the true model: undeclared
    true = sf_gpi_learning(mdp, run, policies=pis)
    assert Knowledge.from_dict(true.parameters["knowledge"]).dynamics == "true-model"


def test_without_base_policies_it_learns_from_nothing_and_says_so():
    """No policy to transfer: GPI's max is Q_new alone and the declared knowledge is none."""
    mdp = goal_grid()
    res = sf_gpi_learning(mdp, Run(runs=2, episodes=30, seed=1, eval_every=10))
    assert Knowledge.from_dict(res.parameters["knowledge"]).dynamics == "none"
    assert res.parameters["base_policies"] == 0
    gaps = res.curve.matrix("value_gap")[:, 9::10]  # the evaluated episodes
    assert np.isfinite(gaps).all() and (gaps >= -1e-9).all()


def test_the_plugin_passes_the_learner_conformance_check():
    from adpart.plugins.builtin.learners import SFGPILearner
    from adpart.testing import check_learner

    check_learner(SFGPILearner)


def test_the_cli_transfers_the_named_runs_policies(tmp_path):
    from click.testing import CliRunner

    from adpart.cli import cli
    from adpart.store import KnowledgeBase

    kb = str(tmp_path / "kb")
    first = CliRunner().invoke(cli, ["learn", "two-rooms", "--task", "reach-goal", "--runs", "3",
                                     "--episodes", "40", "--kb", kb, "-q", "--out",
                                     str(tmp_path / "a")])
    assert first.exit_code == 0, first.output
    sf = CliRunner().invoke(cli, ["learn", "two-rooms", "--task", "goal:x=1,y=4", "--learner",
                                  "sf-gpi", "--model", "two-rooms@experience:run:1", "--runs",
                                  "3", "--episodes", "30", "--kb", kb, "-q", "--out",
                                  str(tmp_path / "b")])
    assert sf.exit_code == 0, sf.output
    with KnowledgeBase.open(kb) as base:
        first_pis = [base.load(base.get("policy", i), "pi") for i in (1, 2, 3)]
        run = base.get("run", 2)
        knows = run.metrics["knowledge"]
        assert (knows["dynamics"], knows["rewards"]) == ("estimated", "observed")
        distinct = len(np.unique(np.vstack(first_pis), axis=0))
        assert knows["uses"][0] == (f"successor features of {distinct} policies of run:1 on "
                                    "their counts model")
    true = CliRunner().invoke(cli, ["learn", "two-rooms", "--task", "goal:x=1,y=4", "--learner",
                                    "sf-gpi", "--dynamics", "true-model", "--model",
                                    "two-rooms@experience:run:1", "--runs", "3", "--episodes",
                                    "30", "--kb", kb, "-q", "--out", str(tmp_path / "c")])
    assert true.exit_code == 0, true.output
    with KnowledgeBase.open(kb) as base:
        knows = base.get("run", 3).metrics["knowledge"]
        assert knows["dynamics"] == "true-model"  # the same policies, the true model declared
        assert knows["uses"][0].endswith("earlier policies on the true dynamics")
    bad = CliRunner().invoke(cli, ["learn", "two-rooms", "--learner", "sf-gpi", "--dynamics",
                                   "exact", "--kb", kb, "-q", "--out", str(tmp_path / "d")])
    assert bad.exit_code == 2 and "--dynamics" in bad.output

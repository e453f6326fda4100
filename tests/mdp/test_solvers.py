"""Exact solvers against dense numpy oracles on random MDPs and SMDPs (hypothesis)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given
from hypothesis import strategies as st

from adpart.errors import ModelError
from adpart.mdp.evaluation import greedy_policy, policy_evaluation
from adpart.mdp.model import FiniteMDP, SMDPModel
from adpart.mdp.solvers import q_from_v, solve, value_iteration


def random_dense(seed: int, S: int, A: int, density: float):
    rng = np.random.default_rng(seed)
    P = rng.random((S, A, S)) * (rng.random((S, A, S)) < density)
    P[np.arange(S), :, rng.integers(0, S, S)] += 0.1  # every row non-empty
    P /= P.sum(axis=2, keepdims=True)
    R = rng.normal(size=(S, A))
    return P, R


def dense_optimal_values(P, R, gamma, terminal=None, admissible=None):
    """Oracle: policy iteration with numpy.linalg.solve on dense matrices."""
    S, A, _ = P.shape
    keep = np.ones(S) if terminal is None else (~terminal).astype(float)
    Pk = P * keep[:, None, None]
    Rk = R * keep[:, None]
    adm = np.ones((S, A), bool) if admissible is None else admissible
    pi = np.argmax(adm, axis=1)
    for _ in range(500):
        Ppi = Pk[np.arange(S), pi]
        V = np.linalg.solve(np.eye(S) - gamma * Ppi, Rk[np.arange(S), pi])
        Q = np.where(adm, Rk + gamma * np.einsum("sat,t->sa", Pk, V), -np.inf)
        new = np.argmax(Q, axis=1)
        if np.all(Q[np.arange(S), new] <= Q[np.arange(S), pi] + 1e-12):
            return V
        pi = new
    raise AssertionError("policy iteration oracle did not converge")


mdp_params = st.tuples(
    st.integers(0, 10_000),
    st.integers(1, 25),
    st.integers(1, 5),
    st.sampled_from([0.1, 0.4, 1.0]),
    st.sampled_from([0.5, 0.9, 0.99]),
)


@given(mdp_params, st.sampled_from(["vi", "mpi", "gs", "gs-mpi", "auto"]))
def test_solution_is_epsilon_optimal_against_dense_oracle(params, method):
    seed, S, A, density, gamma = params
    P, R = random_dense(seed, S, A, density)
    mdp = FiniteMDP.from_dense(P, R, gamma)
    V_star = dense_optimal_values(P, R, gamma)
    eps = 1e-6
    sol = solve(mdp, eps, method=method)
    assert sol.converged
    V_pi = policy_evaluation(mdp, sol.policy)
    assert np.max(V_star - V_pi) <= eps + 1e-9
    assert np.max(np.abs(sol.V - V_star)) <= sol.value_error_bound + 1e-9
    assert sol.loss_bound <= eps


@given(mdp_params)
def test_terminal_states_and_admissible_masks(params):
    seed, S, A, density, gamma = params
    P, R = random_dense(seed, S, A, density)
    rng = np.random.default_rng(seed + 1)
    terminal = rng.random(S) < 0.2
    admissible = rng.random((S, A)) < 0.7
    admissible[np.arange(S), rng.integers(0, A, S)] = True
    mdp = FiniteMDP.from_dense(P, R, gamma, terminal=terminal, admissible=admissible)
    V_star = dense_optimal_values(P, R, gamma, terminal, admissible)
    for method in ("mpi", "gs"):
        sol = solve(mdp, 1e-7, method=method)
        assert sol.rule == "sup" or not terminal.any()
        assert np.all(admissible[np.arange(S), sol.policy])
        np.testing.assert_allclose(policy_evaluation(mdp, sol.policy), V_star, atol=2e-7)
        assert np.max(V_star - policy_evaluation(mdp, sol.policy)) <= 1e-7 + 1e-9
        assert np.all(sol.V[terminal] == 0.0)


@given(st.integers(0, 10_000), st.integers(2, 20), st.integers(1, 4))
def test_policy_evaluation_matches_dense_solve(seed, S, A):
    P, R = random_dense(seed, S, A, 0.5)
    mdp = FiniteMDP.from_dense(P, R, 0.9)
    rng = np.random.default_rng(seed)
    pi = rng.integers(0, A, S)
    expected = np.linalg.solve(np.eye(S) - 0.9 * P[np.arange(S), pi], R[np.arange(S), pi])
    np.testing.assert_allclose(policy_evaluation(mdp, pi), expected, atol=1e-10)
    stochastic = rng.dirichlet(np.ones(A), size=S)
    P_mix = np.einsum("sa,sat->st", stochastic, P)
    expected = np.linalg.solve(np.eye(S) - 0.9 * P_mix, (stochastic * R).sum(axis=1))
    np.testing.assert_allclose(policy_evaluation(mdp, stochastic), expected, atol=1e-10)


@given(st.integers(0, 10_000), st.integers(2, 20), st.integers(1, 4))
def test_a_never_value_changes_nothing_where_the_policy_ends(seed, S, A):
    P, R = random_dense(seed, S, A, 0.5)
    mdp = FiniteMDP.from_dense(P, R, 0.9)
    pi = np.random.default_rng(seed).integers(0, A, S)
    np.testing.assert_allclose(policy_evaluation(mdp, pi, never=-5.0), policy_evaluation(mdp, pi),
                               atol=1e-10)


def test_a_never_value_is_given_where_an_undiscounted_policy_loops():
    """A 4-state chain, gamma = 1: state 3 is terminal; 0 -> 1 -> 3 ends, 2 loops on itself.
    By hand: V(1) = -1, V(0) = -2, V(2) = never; a state that may enter the loop mixes both."""
    P = np.zeros((4, 2, 4))
    P[0, :, 1] = 1.0
    P[1, :, 3] = 1.0
    P[2, :, 2] = 1.0
    P[3, :, 3] = 1.0
    P[0, 1] = [0.0, 0.5, 0.5, 0.0]  # action 1 from 0: half to 1, half into the loop
    terminal = np.array([False, False, False, True])
    mdp = FiniteMDP.from_dense(P, -np.ones((4, 2)), 1.0, terminal=terminal)
    with pytest.raises(ModelError, match="never terminates"):
        policy_evaluation(mdp, np.zeros(4, dtype=int))
    np.testing.assert_allclose(policy_evaluation(mdp, np.zeros(4, dtype=int), never=-50.0),
                               [-2.0, -1.0, -50.0, 0.0])
    np.testing.assert_allclose(policy_evaluation(mdp, np.array([1, 0, 0, 0]), never=-50.0),
                               [-1 + 0.5 * -1 + 0.5 * -50, -1.0, -50.0, 0.0])


@given(st.integers(0, 10_000), st.integers(2, 15), st.integers(1, 4))
def test_smdp_option_models_solve_like_their_semi_markov_oracle(seed, S, n_options):
    O = n_options  # noqa: E741 (the dissertation's name for the option count)
    """Stacked SMDP models (R, discounted F with varying row mass) against a dense solve."""
    rng = np.random.default_rng(seed)
    F = rng.random((O, S, S)) * (rng.random((O, S, S)) < 0.5)
    F[:, np.arange(S), rng.integers(0, S, S)] += 0.1
    F *= rng.uniform(0.3, 0.95, size=(O, S, 1)) / F.sum(axis=2, keepdims=True)
    R = rng.normal(size=(S, O))
    model = SMDPModel(R=R, F=sp.csr_array(F.reshape(O * S, S)), admissible=np.ones((S, O), bool))
    V = np.zeros(S)
    for _ in range(3000):
        V = (R + np.einsum("ost,t->so", F, V)).max(axis=1)
    for method in ("vi", "mpi", "gs"):
        sol = solve(model, 1e-8, method=method)
        assert sol.rule == "sup"
        np.testing.assert_allclose(sol.V, V, atol=1e-7)
        np.testing.assert_allclose(policy_evaluation(model, sol.policy), V, atol=1e-7)


def test_q_from_v_and_greedy():
    P, R = random_dense(1, 6, 3, 0.5)
    adm = np.ones((6, 3), bool)
    adm[0, 0] = False
    mdp = FiniteMDP.from_dense(P, R, 0.8, admissible=adm)
    V = np.arange(6, dtype=float)
    Q = q_from_v(mdp, V)
    expected = R + 0.8 * np.einsum("sat,t->sa", P, V)
    assert Q[0, 0] == -np.inf
    np.testing.assert_allclose(Q[adm], expected[adm])
    assert greedy_policy(np.array([[1.0, 1.0], [0.0, 2.0]])).tolist() == [0, 1]


def test_span_rule_values_are_shifted_to_macqueen_midpoint():
    P, R = random_dense(5, 30, 4, 0.3)
    mdp = FiniteMDP.from_dense(P, R, 0.99)
    sol = value_iteration(mdp, 1e-3)
    assert sol.rule == "span"
    V_star = dense_optimal_values(P, R, 0.99)
    assert np.max(np.abs(sol.V - V_star)) <= sol.value_error_bound


def test_max_sweeps_reports_not_converged():
    P, R = random_dense(2, 10, 2, 0.5)
    sol = value_iteration(FiniteMDP.from_dense(P, R, 0.99), 1e-12, max_sweeps=3)
    assert not sol.converged and sol.sweeps == 3


def test_solver_input_errors():
    P, R = random_dense(3, 5, 2, 0.5)
    mdp = FiniteMDP.from_dense(P, R, 0.9)
    with pytest.raises(ModelError, match=r"epsilon"):
        value_iteration(mdp, 0.0)
    with pytest.raises(ModelError, match=r"initial values have shape"):
        value_iteration(mdp, V0=np.zeros(3))
    with pytest.raises(ModelError, match=r"unknown solver method 'pi'"):
        solve(mdp, method="pi")
    with pytest.raises(ModelError, match=r"outside 0..1"):
        policy_evaluation(mdp, np.full(5, 4))
    adm = np.ones((5, 2), bool)
    adm[2, 1] = False
    P[2, 1] = 0
    masked = FiniteMDP.from_dense(P, R, 0.9, admissible=adm)
    with pytest.raises(ModelError, match=r"inadmissible action 1 in state 2"):
        policy_evaluation(masked, np.ones(5, dtype=int))


def test_improper_policy_with_gamma_one_is_reported():
    P = np.zeros((2, 1, 2))
    P[0, 0, 0] = P[1, 0, 1] = 1.0
    mdp = FiniteMDP.from_dense(P, -np.ones((2, 1)), 1.0)
    with pytest.raises(ModelError, match=r"singular|never terminate"):
        policy_evaluation(mdp, np.zeros(2, dtype=int))


def test_greedy_policy_compiled_path_matches_argmax():
    from adpart.mdp.evaluation import GREEDY_COMPILED_ROWS

    rng = np.random.default_rng(0)
    Q = rng.integers(0, 3, size=(GREEDY_COMPILED_ROWS, 4)).astype(np.float64)  # many ties
    Q[rng.random(Q.shape) < 0.2] = -np.inf
    Q[:5] = -np.inf  # all inadmissible-looking rows: argmax gives 0
    np.testing.assert_array_equal(greedy_policy(Q), np.argmax(Q, axis=1))


@given(mdp_params)
def test_gauss_seidel_index_orders_keep_the_guarantee(params):
    # force the large-model path (index order or its reverse when it agrees with the search)
    from adpart.mdp import solvers

    seed, S, A, density, gamma = params
    P, R = random_dense(seed, S, A, density)
    terminal = np.random.default_rng(seed).random(S) < 0.3
    mdp = FiniteMDP.from_dense(P, R, gamma, terminal=terminal)
    V_star = dense_optimal_values(P, R, gamma, terminal)
    saved = solvers.LOCALITY_NNZ, solvers.INDEX_ORDER_AGREEMENT
    try:
        solvers.LOCALITY_NNZ, solvers.INDEX_ORDER_AGREEMENT = 0, 0.0
        sol = solvers.gauss_seidel_value_iteration(mdp, 1e-6)
    finally:
        solvers.LOCALITY_NNZ, solvers.INDEX_ORDER_AGREEMENT = saved
    assert sol.converged
    assert np.max(V_star - policy_evaluation(mdp, sol.policy)) <= 1e-6 + 1e-9


def test_auto_picks_gauss_seidel_with_sinks_and_mpi_without():
    from adpart.mdp.solvers import choose_method, sweep_order

    P, R = random_dense(0, 6, 2, 0.5)
    plain = FiniteMDP.from_dense(P, R, 0.9)
    goal = FiniteMDP.from_dense(P, R, 0.9, terminal=np.arange(6) == 5)
    assert choose_method(plain) == "mpi" and sweep_order(plain.as_smdp()) is None
    assert choose_method(goal) == "gs-mpi"
    assert sweep_order(goal.as_smdp())[0] == 5  # swept from the sink outwards


@given(mdp_params, st.integers(1, 3))
def test_gauss_seidel_handing_over_to_mpi_keeps_the_guarantee(params, gs_sweeps):
    """A budget of 1-3 Gauss-Seidel sweeps forces the MPI phase on most models; the policy must
    still be epsilon-optimal against the dense policy-iteration oracle, with terminal states."""
    from adpart.mdp.solvers import gauss_seidel_then_mpi

    seed, S, A, density, gamma = params
    P, R = random_dense(seed, S, A, density)
    terminal = np.random.default_rng(seed).random(S) < 0.3
    mdp = FiniteMDP.from_dense(P, R, gamma, terminal=terminal)
    V_star = dense_optimal_values(P, R, gamma, terminal)
    eps = 1e-6
    sol = gauss_seidel_then_mpi(mdp, eps, gs_sweeps=gs_sweeps)
    assert sol.converged
    assert np.max(V_star - policy_evaluation(mdp, sol.policy)) <= eps + 1e-9
    assert np.max(np.abs(sol.V - V_star)) <= sol.value_error_bound + 1e-9


def test_gs_mpi_on_three_floor_arm_is_epsilon_optimal_after_the_handover():
    """three-floor-arm (slip 0.5) needs more than GS_SWEEP_BUDGET Gauss-Seidel sweeps, so
    solve(method="gs-mpi") ends in MPI there; its policy's loss against an independent tight
    solve (plain value iteration to 1e-10) stays below epsilon. The default solve() is that
    hand-over wherever the model has sinks."""
    from adpart.envs.registry import get_domain
    from adpart.mdp.solvers import GS_SWEEP_BUDGET, gauss_seidel_value_iteration

    mdp = get_domain("three-floor-arm").mdp()
    eps = 1e-6
    gs = gauss_seidel_value_iteration(mdp, eps)
    assert gs.sweeps > GS_SWEEP_BUDGET
    sol = solve(mdp, eps, method="gs-mpi")
    assert sol.converged and sol.evaluation_sweeps > 0  # the MPI phase ran
    np.testing.assert_array_equal(solve(mdp, eps).policy, sol.policy)
    tight = value_iteration(mdp, 1e-10)
    V_star = tight.V
    loss = np.max(V_star - policy_evaluation(mdp, sol.policy))
    assert loss <= eps + tight.value_error_bound
    assert sol.loss_bound <= eps


def test_gauss_seidel_then_mpi_input_errors():
    from adpart.mdp.solvers import gauss_seidel_then_mpi

    P, R = random_dense(0, 4, 2, 0.5)
    mdp = FiniteMDP.from_dense(P, R, 0.9, terminal=np.arange(4) == 3)
    for bad in (0, -1, 1.5, True):
        with pytest.raises(ModelError, match="gs_sweeps"):
            gauss_seidel_then_mpi(mdp, 1e-6, gs_sweeps=bad)

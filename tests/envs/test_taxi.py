"""Taxi against an independent oracle: a model built straight from Gymnasium's ``Taxi-v4`` ``P``."""

from __future__ import annotations

from collections import deque

import gymnasium as gym
import numpy as np
import pytest

from adpart.envs.domains.taxi import (
    ACTION_NAMES,
    IN_TAXI,
    LANDMARKS,
    PUTDOWN,
    Taxi,
    decode,
    encode,
)
from adpart.envs.registry import get_domain
from adpart.errors import TaskError
from adpart.mdp.evaluation import policy_evaluation
from adpart.mdp.solvers import solve

S, A = 500, 6


def gym_model(**kwargs):
    """Dense ``(A*S, S)`` transitions, ``(S, A)`` rewards and terminal flags of Gymnasium's P."""
    env = gym.make("Taxi-v4", **kwargs).unwrapped
    P = np.zeros((A * S, S))
    R = np.zeros((S, A))
    terminal = np.zeros(S, dtype=bool)
    for s in range(S):
        for a in range(A):
            for p, s2, r, done in env.P[s][a]:
                P[a * S + s, s2] += p
                R[s, a] += p * r
                terminal[s2] |= bool(done)
    env.close()
    return P, R, terminal, np.asarray(env.initial_state_distrib)


@pytest.fixture(scope="module")
def oracle():
    return gym_model()


def dense_optimal_values(P, R, terminal, gamma):
    """Policy iteration with dense numpy solves (terminal states have value 0)."""
    keep = (~terminal).astype(float)
    F = gamma * P * np.tile(keep, A)[:, None]
    Rt = np.where(terminal[:, None], 0.0, R)
    policy = np.zeros(S, dtype=int)
    while True:
        rows = policy * S + np.arange(S)
        V = np.linalg.solve(np.eye(S) - F[rows], Rt[np.arange(S), policy])
        Q = Rt + (F @ V).reshape(A, S).T
        better = Q.max(axis=1) > Q[np.arange(S), policy] + 1e-12
        if not better.any():
            return V
        policy = np.where(better, Q.argmax(axis=1), policy)


def test_gymnasium_variant_equals_gymnasium_P_entry_by_entry(oracle):
    P, R, terminal, initial = oracle
    mdp = Taxi(putdown="gymnasium").mdp()
    assert mdp.action_names == ACTION_NAMES
    assert mdp.n_states == S and mdp.n_actions == A
    np.testing.assert_array_equal(mdp.P.toarray(), P)
    np.testing.assert_array_equal(mdp.R, R)
    np.testing.assert_array_equal(mdp.terminal, terminal)
    np.testing.assert_allclose(mdp.initial, initial, atol=1e-15)


def test_optimal_values_equal_dense_solve_of_gymnasium_P(oracle):
    P, R, terminal, _ = oracle
    mdp = Taxi(putdown="gymnasium").mdp()
    V_dense = dense_optimal_values(P, R, terminal, mdp.gamma)
    sol = solve(mdp, epsilon=1e-10)
    assert sol.converged
    np.testing.assert_allclose(sol.V, V_dense, rtol=0, atol=1e-8)
    np.testing.assert_allclose(policy_evaluation(mdp, sol.policy), V_dense, rtol=0, atol=1e-8)


def test_dietterich_variant_differs_exactly_in_wrong_landmark_putdowns(oracle):
    P, R, _, _ = oracle
    mdp = Taxi().mdp()
    row, col, passenger, dest = decode(np.arange(S))
    at_landmark = np.zeros(S, dtype=bool)
    at_dest = np.zeros(S, dtype=bool)
    for i, (r, c) in enumerate(LANDMARKS):
        here = (row == r) & (col == c)
        at_landmark |= here
        at_dest |= here & (dest == i)
    wrong = (passenger == IN_TAXI) & at_landmark & ~at_dest
    assert wrong.sum() == 4 * 3  # taxi on one of 4 landmarks, one of 3 other destinations
    Pd = mdp.P.toarray()
    differs_P = np.abs(Pd - P).reshape(A, S, S).max(axis=2).T > 0
    differs_R = mdp.R != R
    expected = np.zeros((S, A), dtype=bool)
    expected[wrong, PUTDOWN] = True
    np.testing.assert_array_equal(differs_P, expected)
    np.testing.assert_array_equal(differs_R, expected)
    s = np.flatnonzero(wrong)
    np.testing.assert_array_equal(mdp.R[s, PUTDOWN], -10.0)
    np.testing.assert_array_equal(Pd[PUTDOWN * S + s, s], 1.0)  # passenger stays in the taxi


def test_500_states_and_404_reachable_by_bfs():
    mdp = Taxi().mdp()
    seen = np.zeros(S, dtype=bool)
    queue = deque(np.flatnonzero(mdp.initial > 0).tolist())
    seen[list(queue)] = True
    while queue:
        s = queue.popleft()
        if mdp.terminal[s]:
            continue
        for a in range(A):
            for s2 in mdp.transition_row(s, a)[0]:
                if not seen[s2]:
                    seen[s2] = True
                    queue.append(int(s2))
    assert mdp.n_states == 500
    assert int(seen.sum()) == 404
    assert int((mdp.initial > 0).sum()) == 300


def test_optimal_policy_delivers_from_a_fixed_state():
    mdp = Taxi().mdp()
    policy = solve(mdp, epsilon=1e-8).policy
    # taxi at (2, 2), passenger waiting at Y, destination G
    s = int(encode(2, 2, 2, 1))
    total, steps, discount = 0.0, 0, 1.0
    while not mdp.terminal[s]:
        a = int(policy[s])
        total += discount * mdp.R[s, a]
        discount *= mdp.gamma
        succ, prob = mdp.transition_row(s, a)
        assert prob.tolist() == [1.0]
        s = int(succ[0])
        steps += 1
        assert steps < 50, "the greedy policy does not deliver"
    row, col, passenger, dest = decode(s)
    assert (passenger, dest) == (1, 1) and (row, col) == LANDMARKS[1]
    # (2,2) -> Y(4,0): 4 moves, pickup, Y -> G(0,4): 8 moves (around the walls), putdown
    assert steps == 4 + 1 + 8 + 1
    np.testing.assert_allclose(total, solve(mdp, epsilon=1e-10).V[int(encode(2, 2, 2, 1))],
                               atol=1e-8)


def test_slip_rows_equal_gymnasium_rainy_where_the_intended_move_is_open():
    P_rainy, _, _, _ = gym_model(is_rainy=True)
    slip = Taxi(putdown="gymnasium", slip=True).mdp()
    det = Taxi(putdown="gymnasium").mdp().P.toarray()
    Ps = slip.P.toarray()
    np.testing.assert_allclose(Ps.sum(axis=1), 1.0, atol=1e-12)
    moves = np.arange(4 * S)
    s = moves % S
    open_move = det[moves, s] == 0.0
    np.testing.assert_allclose(Ps[moves[open_move]], P_rainy[moves[open_move]], atol=1e-12)
    # Pickup and Putdown are unaffected by the noise
    np.testing.assert_array_equal(Ps[4 * S:], det[4 * S:])
    # a blocked intended move still slips sideways here (Gymnasium keeps the taxi in place)
    s0 = int(encode(0, 1, 0, 1))  # West from (0,1) is open, North is the border
    north = Ps[1 * S + s0]
    # intended (border) and east (wall between (0,1) and (0,2)) stay put; west slips to (0,0)
    assert north[s0] == pytest.approx(0.9)
    assert north[int(encode(0, 0, 0, 1))] == pytest.approx(0.1)
    assert north[int(encode(0, 2, 0, 1))] == 0.0


def test_features_and_layout():
    dom = Taxi()
    f = dom.dynamics().features
    row, col, passenger, dest = decode(np.arange(S))
    np.testing.assert_array_equal(f["x"], col)
    np.testing.assert_array_equal(f["y"], row)
    np.testing.assert_array_equal(f["passenger"], passenger)
    np.testing.assert_array_equal(f["destination"], dest)
    assert dom.layout().shape == (1, 5, 5) and dom.layout().all()


def test_registry_and_bad_parameters():
    dom = get_domain("taxi")
    assert isinstance(dom, Taxi) and dom.task().name == "deliver"
    with pytest.raises(TaskError, match="putdown"):
        Taxi(putdown="wrong")
    with pytest.raises(TaskError, match="slip_probability"):
        Taxi(slip=True, slip_probability=1.5)
    with pytest.raises(TaskError, match="gamma"):
        Taxi(gamma=0.0)


def test_undiscounted_taxi_as_dietterich():
    discounted = Taxi().mdp()
    mdp = Taxi(gamma=1.0).mdp()
    assert mdp.gamma == 1.0
    V = policy_evaluation(mdp, solve(discounted, epsilon=1e-8).policy)
    # 13 actions at -1, then the delivering Putdown's +20
    assert V[int(encode(2, 2, 2, 1))] == pytest.approx(-13 + 20)

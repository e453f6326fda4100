"""MAXQ-Q against independent oracles.

* Deterministic Taxi: the hierarchically greedy policy after training is optimal from every
  start state (value iteration on the flat model).
* A tiny key-and-door corridor: the learned completion values satisfy the decomposed Bellman
  equations, solved here exactly with dense linear algebra and value iteration per subtask.
"""

from __future__ import annotations

import numpy as np
import pytest

from adpart.envs.domains.taxi import Taxi
from adpart.errors import TaskError
from adpart.learning.maxq import Subtask, TaskGraph, decomposed_values, maxq_q, taxi_graph
from adpart.learning.maxq.maxq_q import root_q
from adpart.learning.settings import Run
from adpart.mdp.evaluation import policy_evaluation
from adpart.mdp.model import FiniteMDP
from adpart.mdp.solvers import solve
from adpart.plugins.builtin.maxq import MaxQLearner

# ----------------------------------------------------------------------------- tiny domain
L, KEY = 5, 2
LEFT, RIGHT, GRAB, OPEN = range(4)


def corridor(slip: float = 0.8, gamma: float = 0.9) -> FiniteMDP:
    """Cells 0..4 x key flag; the key lies at 0, the door at 4; state 10 = through the door.

    Left/Right succeed w.p. ``slip`` (else stay); Grab takes the key at cell 0; Open at cell 4
    with the key ends the episode with +5; every other action costs -1.
    """
    S = L * KEY + 1
    P = np.zeros((S, 4, S))
    R = np.full((S, 4), -1.0)
    for key in range(KEY):
        for x in range(L):
            s = key * L + x
            for a, dx in ((LEFT, -1), (RIGHT, 1)):
                x2 = min(max(x + dx, 0), L - 1)
                P[s, a, key * L + x2] += slip
                P[s, a, s] += 1 - slip
            P[s, GRAB, L + x if x == 0 else s] = 1.0
            if key == 1 and x == L - 1:
                P[s, OPEN, S - 1] = 1.0
                R[s, OPEN] = 5.0
            else:
                P[s, OPEN, s] = 1.0
    P[S - 1, :, S - 1] = 1.0
    terminal = np.zeros(S, dtype=bool)
    terminal[-1] = True
    initial = np.where(terminal, 0.0, 1.0)
    pos = np.array([*range(L), *range(L), L - 1])
    key = np.array([0] * L + [1] * L + [1])
    return FiniteMDP.from_dense(P, R, gamma, terminal=terminal, initial=initial / initial.sum(),
                                features={"pos": pos, "key": key},
                                action_names=("Left", "Right", "Grab", "Open"))


def corridor_graph() -> TaskGraph:
    return TaskGraph("corridor", "Root", (
        Subtask("Root", ("GetKey", "Finish"), terminal=lambda f: np.zeros(f["pos"].shape, bool)),
        Subtask("GetKey", ("Grab", "Nav"), terminal=lambda f: f["key"] == 1),
        Subtask("Finish", ("Open", "Nav"), terminal=lambda f: f["key"] == 0),
        Subtask("Nav", ("Left", "Right"), terminal=lambda f, t: f["pos"] == t,
                params={"t": (0, L - 1)}, abstraction=("pos",)),
    ))


def oracle(mdp: FiniteMDP, g) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray]]:
    """Recursively optimal ``C*(i, s, k)`` and ``V*(i, s)`` by exact solves, bottom-up.

    For each composite node (children first): value iteration on
    ``V_i(s) = max_k [V_k(s) + sum_s' F_k(s, s') V_i(s')]`` (0 on ``T_i``), where ``F_k`` is the
    child's discounted exit distribution; then ``F_i`` from the linear system
    ``F_i = M D_T + M D_N F_i`` with ``M(s, .) = F_{pi_i(s)}(s, .)``.
    """
    S, A, gamma = mdp.n_states, mdp.n_actions, mdp.gamma
    P = mdp.P.toarray().reshape(A, S, S)
    F = {a: gamma * P[a] for a in range(A)}
    Vn = {a: mdp.R[:, a].copy() for a in range(A)}
    C, Vs = {}, {}
    for node in g.postorder():
        j = node - A
        T = g.terminal[j]
        kids = g.children[j]
        assert np.all(kids >= 0)  # static children only in this small graph
        V = np.zeros(S)
        for _ in range(5000):
            q = np.stack([Vn[c] + F[c] @ V for c in kids])
            q = np.where(g.available[j], q, -np.inf)
            new = np.where(T, 0.0, q.max(axis=0))
            new = np.where(np.isfinite(new), new, 0.0)
            if np.max(np.abs(new - V)) < 1e-13:
                V = new
                break
            V = new
        pi = np.argmax(np.where(g.available[j], np.stack([Vn[c] + F[c] @ V for c in kids]),
                                -np.inf), axis=0)
        M = np.stack([F[kids[pi[s]]][s] for s in range(S)])
        M[T] = 0.0
        DN, DT = np.diag((~T).astype(float)), np.diag(T.astype(float))
        F[node] = np.linalg.solve(np.eye(S) - M @ DN, M @ DT)
        Vn[node] = V
        C[node] = np.stack([F[c] @ V for c in kids])[:, g.rows[j]]
        Vs[node] = V
    return C, Vs


def greedy_errors(mdp, g, tables) -> list[float]:
    """Per composite node, ``max_s |C(i, s, pi_i(s)) - C*(i, s, pi_i(s))|`` and the same for
    ``V(i, s)``, over the states where the node runs (``pi_i`` = the learned greedy child).

    These are the decomposition equations of the hierarchical policy; the entries of children
    that are never greedy are estimates from exploration only and are not compared.
    """
    C_star, V_star = oracle(mdp, g)
    V, greedy = decomposed_values(g, tables)
    errs = []
    for node, c_star in C_star.items():
        j = node - g.n_primitives
        s = np.flatnonzero(~g.terminal[j])
        k = greedy[j]
        cols = np.arange(s.size)
        c = tables.completion(g, node)
        errs.append(float(np.abs(c[k, cols] - c_star[k, cols]).max()))
        errs.append(float(np.abs(V[node][s] - V_star[node][s]).max()))
    return errs


@pytest.mark.parametrize("abstraction", [False, True])
def test_completion_values_satisfy_the_decomposed_bellman_equations(abstraction):
    """Deterministic corridor, GLIE exploration: the equations hold to rounding."""
    mdp = corridor(slip=1.0)
    g = corridor_graph().compile(mdp, abstraction=abstraction)
    res = maxq_q(mdp, g, Run(runs=1, episodes=5000, seed=3, alpha="0.5", epsilon="exp:0.5,0.998",
                             eval_every=5000, max_steps_per_episode=200))
    assert max(greedy_errors(mdp, g, res.tables[0])) < 1e-9
    # and V(Root, s) is the flat optimum (this hierarchy can express the optimal policy)
    V, _ = decomposed_values(g, res.tables[0])
    v_star = policy_evaluation(mdp, solve(mdp, 1e-12).policy)
    np.testing.assert_allclose(V[g.root][~mdp.terminal], v_star[~mdp.terminal], atol=1e-9)
    assert res.curve.matrix("value_gap")[0, -1] == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("abstraction", [False, True])
def test_stochastic_completion_values_approach_the_oracle(abstraction):
    """Slippery corridor (moves succeed 0.8): stochastic approximation, so a tolerance."""
    mdp = corridor(slip=0.8)
    g = corridor_graph().compile(mdp, abstraction=abstraction)
    res = maxq_q(mdp, g, Run(runs=1, episodes=8000, seed=3, alpha="1/n^0.7",
                             epsilon="exp:0.5,0.999", eval_every=8000, max_steps_per_episode=200))
    assert max(greedy_errors(mdp, g, res.tables[0])) < 0.1
    assert res.curve.matrix("value_gap")[0, -1] == pytest.approx(0.0, abs=1e-9)


def test_deterministic_taxi_greedy_policy_is_optimal_from_every_start():
    mdp = Taxi(gamma=1.0).mdp()
    g = taxi_graph().compile(mdp)
    res = maxq_q(mdp, g, Run(runs=1, episodes=1500, seed=1, alpha="0.5", epsilon="0.1",
                             eval_every=500))
    v_star = policy_evaluation(mdp, solve(mdp, 1e-12).policy)
    pi = res.policies[0]
    v_pi = policy_evaluation(mdp, pi)
    starts = mdp.initial > 0
    assert starts.sum() == 300
    np.testing.assert_allclose(v_pi[starts], v_star[starts], atol=1e-8)
    assert res.curve.matrix("value_gap")[0, -1] == pytest.approx(0.0, abs=1e-9)
    # the root-path action values rank the polled action first
    Q = res.Q[0]
    assert np.all(Q[np.arange(mdp.n_states), pi][starts] == Q.max(axis=1)[starts])


def test_learner_plugin_runs_and_is_reproducible():
    mdp = Taxi(gamma=1.0).mdp()
    learner = MaxQLearner(alpha="0.5", max_steps=300)
    a = learner.learn(mdp, runs=2, episodes=20, seed=11, eval_every=10)
    b = learner.learn(mdp, runs=2, episodes=20, seed=11, eval_every=10)
    np.testing.assert_array_equal(a.curve["steps"], b.curve["steps"])
    np.testing.assert_array_equal(a.Q, b.Q)
    assert a.Q.shape == (2, 500, 6) and a.curve.n_episodes == 20
    assert a.parameters["graph"] == "taxi" and a.parameters["abstraction"] is True
    assert np.all(a.curve["steps"] <= 300)


def test_bad_settings():
    mdp = Taxi().mdp()
    g = taxi_graph().compile(mdp)
    with pytest.raises(TaskError, match="runs"):
        maxq_q(mdp, g, Run(runs=0))
    with pytest.raises(TaskError, match="compiled on this MDP"):
        maxq_q(corridor(), g)
    assert root_q(g, maxq_q(mdp, g, Run(runs=1, episodes=1, seed=0)).tables[0]).shape == (500, 6)

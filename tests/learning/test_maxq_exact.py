"""MAXQ-Q's value decomposition checked against an exact solve of every subtask's own SMDP on
Taxi (Dietterich 2000 sec. 3-4), and that exact solve against oracles that share no code with it:
flat value iteration (Taxi's recursively optimal policy is optimal) and shortest paths."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import shortest_path

from adpart.envs.domains.taxi import Taxi
from adpart.learning.curves import start_distribution, start_values
from adpart.learning.maxq import (
    decomposed_values,
    maxq_q,
    polled_policy,
    reachable_states,
    recursively_optimal,
    taxi_graph,
)
from adpart.learning.settings import Run
from adpart.mdp.solvers import value_iteration

LANDMARKS = ((0, 0), (0, 4), (4, 0), (4, 3))


@pytest.fixture(scope="module")
def taxi():
    mdp = Taxi(fickle=False, gamma=1.0).mdp()
    g = taxi_graph().compile(mdp, abstraction=True)
    return mdp, g, recursively_optimal(mdp, g)


def test_exact_root_is_flat_v_star_and_navigate_is_shortest_paths(taxi) -> None:
    mdp, g, sol = taxi
    live = ~mdp.terminal
    v_star = value_iteration(mdp, epsilon=1e-10).V
    np.testing.assert_allclose(sol.V[g.root][live], v_star[live], atol=1e-8)
    # Navigate(t): minus the number of moves to landmark t, by BFS over the cell graph
    f = mdp.features
    cell = f["taxi_row"] * 5 + f["taxi_col"]
    S = mdp.n_states
    P = mdp.P.tocoo()
    move = P.row // S < 4
    adj = sp.csr_array((np.ones(int(move.sum())), (cell[P.row[move] % S], cell[P.col[move]])),
                       shape=(25, 25))
    dist = shortest_path(adj, unweighted=True)
    A0 = g.n_primitives
    for t, (r, c) in enumerate(LANDMARKS):
        node = g.names.index(f"Navigate(t={t})")
        rows = g.rows[node - A0]
        rows = rows[~mdp.terminal[rows]]
        # an MDP terminal reached on the way would end Navigate early; the reachable
        # configurations never pass one, so compare on them
        rows = rows[reachable_states(mdp)[rows]]
        np.testing.assert_allclose(sol.V[node][rows], -dist[cell[rows], r * 5 + c])


def test_learned_decomposition_equals_the_exact_one_on_deterministic_taxi(taxi) -> None:
    """alpha = 1 on a deterministic model: every C entry updated a few times is exact."""
    mdp, g, sol = taxi
    res = maxq_q(mdp, g, Run(runs=1, episodes=1000, seed=0, alpha="1", epsilon="0.5",
                             eval_every=1000))
    tables = res.tables[0]
    V, _ = decomposed_values(g, tables)
    reach = reachable_states(mdp)
    A = g.n_primitives
    compared = 0
    for node in g.postorder():
        j = node - A
        rows = g.rows[j]
        m = reach[rows]
        np.testing.assert_allclose(V[node][rows][m], sol.V[node][rows][m], atol=1e-9,
                                   err_msg=g.names[node])
        C = tables.completion(g, node)
        counts = np.stack([c[i] for c, i in zip(tables.nC[j], g.c_index[j], strict=True)])
        ok = np.isfinite(sol.C[j]) & m[None] & (counts >= 3)
        np.testing.assert_allclose(C[ok], sol.C[j][ok], atol=1e-9, err_msg=g.names[node])
        compared += int(ok.sum())
    assert compared > 5000
    assert res.curve.matrix("value_gap")[0, -1] == pytest.approx(0.0, abs=1e-9)


def test_fickle_taxi_recursive_and_polled_ceilings() -> None:
    """Fickle Taxi: executing the recursively optimal policy as a hierarchy loses value (a
    Navigate keeps driving to the old destination); polling it every step nearly recovers V*."""
    mdp = Taxi(fickle=True, gamma=1.0).mdp()
    g = taxi_graph().compile(mdp)
    sol = recursively_optimal(mdp, g)
    mu = start_distribution(mdp)
    v_star = float(mu @ value_iteration(mdp, epsilon=1e-10).V)
    recursive = float(mu @ sol.V[g.root])
    polled = float(start_values(mdp, polled_policy(g, sol, mdp.admissible)[None], mu)[0])
    assert recursive < v_star - 1.0
    assert v_star - 0.05 < polled <= v_star + 1e-9


@pytest.mark.slow
def test_learned_decomposition_approaches_the_exact_one_on_fickle_taxi() -> None:
    mdp = Taxi(fickle=True, gamma=1.0).mdp()
    g = taxi_graph().compile(mdp)
    sol = recursively_optimal(mdp, g)
    res = maxq_q(mdp, g, Run(runs=1, episodes=3000, seed=0, alpha="1/n^0.6", epsilon="1/n^0.5",
                             eval_every=3000))
    V, _ = decomposed_values(g, res.tables[0])
    reach = reachable_states(mdp)
    A = g.n_primitives
    for node in g.postorder():
        rows = g.rows[node - A]
        err = np.abs(V[node][rows] - sol.V[node][rows])[reach[rows]]
        limit = 0.6 if node == g.root else 0.2  # the root sums every level's noise
        assert err.mean() < limit, (g.names[node], err.mean())

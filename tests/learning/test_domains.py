"""Q-learning on the built-in domains (``adpart.envs.registry``); skipped while a domain is missing.

Budgets (docs/learning.md): two-rooms (55 states, deterministic) reaches the optimal policy
within 500 episodes for all runs (alpha = 1, epsilon = 0.5; measured: all 8 runs by episode
200). Four-rooms (stochastic 2/3 + 3 x 1/9) has optimal action gaps as small as 3.3e-5, so an
exactly optimal greedy policy under its uniform start distribution needs Q errors below ~1e-5,
i.e. far more than 1e9 updates per pair; the test checks the documented gap < 1e-4
after 20,000 episodes instead (measured 1e-5 to 6e-5).
"""

from __future__ import annotations

import numpy as np
import pytest

from adpart.learning import q_learning
from adpart.learning.settings import Run


def _mdp(name: str):
    from adpart.envs.registry import BUILTIN_DOMAINS, get_domain

    module = BUILTIN_DOMAINS[name].partition(":")[0]
    try:
        __import__(module)
    except ModuleNotFoundError as exc:
        if exc.name == module:
            pytest.skip(f"domain {name} not written yet")
        raise
    return get_domain(name).mdp()


def test_two_rooms_all_runs_reach_optimal_policy():
    mdp = _mdp("two-rooms")
    # Deterministic: alpha = 1 makes each update an exact sampled Bellman backup.
    res = q_learning(mdp, Run(runs=8, episodes=500, seed=0, alpha=1.0, epsilon=0.5, eval_every=100))
    gaps = res.curve.matrix("value_gap")[:, -1]
    assert np.all(np.abs(gaps) < 1e-6), gaps


@pytest.mark.slow
def test_four_rooms_all_runs_get_close_to_optimal():
    mdp = _mdp("four-rooms")
    res = q_learning(mdp, Run(runs=4, episodes=20_000, seed=0, alpha="1/n^0.8", epsilon=1.0,
                              eval_every=5_000, max_steps_per_episode=10_000))
    gaps = res.curve.matrix("value_gap")[:, -1]
    assert np.all(gaps < 1e-4), gaps
    assert np.all(gaps >= -1e-9)


def test_four_rooms_near_ties_carry_more_than_1e6_of_the_start_value():
    """Why four-rooms is held to 1e-4, not 1e-6 (docs/learning.md, "Budgets").

    Under the uniform start distribution every non-goal state matters: taking the second-best
    action in any single state alone costs more than 1e-6 of the start value, yet at states 44
    and 3 the two best actions differ by less than 4e-5. A greedy policy within 1e-6 therefore
    needs every such pair ordered correctly, i.e. Q errors below ~1.5e-5 there.
    """
    from adpart.learning.curves import start_distribution
    from adpart.mdp.evaluation import policy_evaluation
    from adpart.mdp.solvers import solve

    mdp = _mdp("four-rooms")
    V = solve(mdp, 1e-12).V
    S, A = mdp.n_states, mdp.n_actions
    Q = mdp.R + mdp.gamma * (mdp.P @ np.where(mdp.terminal, 0.0, V)).reshape(A, S).T
    Q = np.where(mdp.admissible, Q, -np.inf)
    mu = start_distribution(mdp)
    best = Q.argmax(axis=1)
    base = mu @ policy_evaluation(mdp, best)
    costs, gaps = [], []
    for s in np.flatnonzero(~mdp.terminal):
        order = np.argsort(-Q[s])
        switched = best.copy()
        switched[s] = order[1]
        costs.append(base - mu @ policy_evaluation(mdp, switched))
        gaps.append(Q[s, order[0]] - Q[s, order[1]])
    costs, gaps = np.array(costs), np.array(gaps)
    assert costs.min() > 1e-6
    assert np.sort(gaps)[:2].max() < 4e-5

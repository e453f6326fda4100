"""R-max's value ceiling of a goal task: the goal's reward once, not at every step forever.

``termination_ceiling`` claims ``V*(s) <= G`` for every state when every positive reward comes
with a chance of ending the episode (``G`` the largest reward per unit of that chance). The
oracle is the solver's ``V*``: never above the ceiling on random slippery goal grids, and equal to
it where a state reaches the goal in one sure step.
"""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from adpart.learning.hierarchical import episodic_ceiling, reward_ceiling
from adpart.mdp.evaluation import policy_evaluation
from adpart.mdp.generate import random_grid_mdp
from adpart.mdp.solvers import solve


def goal_task(n: int, slip: float, goal: float, step: float, gamma: float, seed: int):
    """A slippery grid with a terminal goal cell paying ``goal`` on arrival, ``step`` else."""
    base = random_grid_mdp(n, slip=slip, gamma=gamma, seed=seed)
    rng = np.random.default_rng(seed)
    terminal = np.zeros(n, dtype=bool)
    terminal[rng.integers(n)] = True
    S, A = base.n_states, base.n_actions
    arrive = np.asarray(base.P @ terminal.astype(float)).reshape(A, S).T
    return base.with_rewards(step + (goal - step) * arrive, terminal=terminal)


@settings(max_examples=40, deadline=None, derandomize=True)
@given(n=st.integers(9, 49), slip=st.sampled_from([0.0, 0.2, 0.5]),
       goal=st.floats(0.5, 100.0), step=st.sampled_from([0.0, -0.1, -1.0]),
       gamma=st.sampled_from([0.9, 0.99, 1.0]), seed=st.integers(0, 1000))
def test_no_state_is_worth_more_than_the_goal_once(n, slip, goal, step, gamma, seed):
    mdp = goal_task(n, slip, goal, step, gamma, seed)
    ceiling = episodic_ceiling(mdp, horizon=1000)
    v_star = policy_evaluation(mdp, solve(mdp, 1e-10).policy, never=step * 1e6)
    assert np.all(v_star <= ceiling + 1e-6)
    assert ceiling <= goal + 1e-9  # the goal's reward: every positive reward comes with it
    if gamma < 1.0:  # far below the bound of a reward paid at every step
        assert ceiling < reward_ceiling(goal, gamma, 1000)


def test_the_ceiling_is_attained_where_the_goal_is_one_sure_step_away():
    mdp = goal_task(25, 0.0, 10.0, -1.0, 0.95, 3)
    ceiling = episodic_ceiling(mdp, horizon=1000)
    v_star = policy_evaluation(mdp, solve(mdp, 1e-12).policy)
    assert ceiling == 10.0 and np.isclose(v_star[~mdp.terminal].max(), 10.0)


def test_a_positive_reward_that_cannot_end_the_episode_keeps_the_loose_ceiling():
    mdp = goal_task(16, 0.2, 5.0, -1.0, 0.9, 1)
    R = np.array(mdp.R)
    live = mdp.admissible & ~mdp.terminal[:, None]
    S, A = mdp.n_states, mdp.n_actions
    arrive = np.asarray(mdp.P @ mdp.terminal.astype(float)).reshape(A, S).T
    s, a = np.argwhere(live & (arrive == 0))[0]
    R[s, a] = 2.0  # paid at a pair that never ends the episode: it may be collected forever
    looser = mdp.with_rewards(R, terminal=mdp.terminal)
    top = float(R[live].max())  # the largest reward a live pair pays
    assert episodic_ceiling(looser, horizon=1000) == reward_ceiling(top, 0.9, 1000)

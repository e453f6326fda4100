"""The SMDP over options: primitive options reproduce V*, four-rooms sweeps (Sutton et al. 1999,
Fig. 4), hand-made options on the grid domains, stacking errors."""

from __future__ import annotations

import numpy as np
import pytest

from adpart.envs.registry import get_domain
from adpart.errors import ModelError
from adpart.mdp.evaluation import policy_evaluation
from adpart.mdp.generate import random_mdp
from adpart.mdp.solvers import solve
from adpart.options import (
    Option,
    doorway_options,
    hallway_options,
    option_model,
    option_models,
    options_smdp,
    primitive_options,
    stack_models,
    sweeps_to_accuracy,
    wall_options,
)


@pytest.mark.parametrize("name", ["four-rooms", "two-rooms"])
def test_primitive_options_give_the_mdps_optimal_values(name):
    mdp = get_domain(name).mdp()
    smdp, _ = options_smdp(mdp, primitive_options(mdp), include_primitives=False)
    flat = solve(mdp, 1e-12)
    over_options = solve(smdp, 1e-12)
    # Independent of the solvers' stopping: evaluate both greedy policies exactly.
    np.testing.assert_allclose(over_options.V, flat.V, atol=1e-10)
    np.testing.assert_allclose(
        policy_evaluation(smdp, over_options.policy), policy_evaluation(mdp, flat.policy),
        atol=1e-10,
    )


def test_primitive_options_on_random_mdp_with_terminals():
    base = random_mdp(30, 3, density=0.2, seed=4, gamma=0.95)
    terminal = np.zeros(30, bool)
    terminal[[3, 17]] = True
    mdp = base.with_rewards(base.R, terminal=terminal)
    smdp, _ = options_smdp(mdp, primitive_options(mdp), include_primitives=False)
    np.testing.assert_allclose(solve(smdp, 1e-12).V, solve(mdp, 1e-12).V, atol=1e-10)


#: Measured sweep counts (docs/options.md): primitive actions need 38 sweeps until every state
#: is within 1% of V*; the eight hallway options need 8 until every state is within 1% of their
#: own optimum V*_O; hallway options plus primitive actions need 10 to be within 1% of V*.
def test_four_rooms_hallway_options_need_at_most_half_the_sweeps():
    mdp = get_domain("four-rooms").mdp("G1")
    options = hallway_options(mdp)
    assert len(options) == 8
    assert sorted(int(o.initiation.sum()) for o in options) == [20, 21, 26, 26, 26, 26, 30, 31]
    hallway_smdp, models = options_smdp(mdp, options, include_primitives=False)
    both = stack_models(mdp, models, include_primitives=True)
    V_star = solve(mdp, 1e-13, method="vi").V
    V_star_O = solve(hallway_smdp, 1e-13, method="vi").V
    primitive_sweeps, _ = sweeps_to_accuracy(mdp.as_smdp(), V_star)
    option_sweeps, _ = sweeps_to_accuracy(hallway_smdp, V_star_O)
    both_sweeps, _ = sweeps_to_accuracy(both, V_star)
    assert (primitive_sweeps, option_sweeps, both_sweeps) == (38, 8, 10)
    assert 2 * option_sweeps <= primitive_sweeps
    assert 2 * both_sweeps <= primitive_sweeps
    # Options plus primitives have the same optimum as the MDP; options alone lose a little
    # (their policies avoid leaving the room through the other hallway).
    np.testing.assert_allclose(solve(both, 1e-13, method="vi").V, V_star, atol=1e-10)
    assert np.all(V_star_O <= V_star + 1e-12)


def test_hallway_option_shape_matches_sutton():
    mdp = get_domain("four-rooms").mdp("G1")
    by_name = {o.name: o for o in hallway_options(mdp)}
    o = by_name["room0->25"]  # upper-left room to the hallway (3, 6) on its east side
    x, y = mdp.features["x"], mdp.features["y"]
    room = (x <= 5) & (y <= 5)
    assert np.array_equal(o.beta == 0, room)
    assert np.flatnonzero(o.initiation & ~room).tolist() == [51]  # the other hallway (6, 2)
    m = option_model(mdp, o)
    # From inside the room it ends in one of the two hallways; started in the other hallway
    # (6, 2) its first step may slip south into the lower-left room, cell (7, 2) = state 58.
    assert set(np.unique(m.F[np.flatnonzero(room)].indices).tolist()) == {25, 51}
    assert set(m.F[[51]].indices.tolist()) == {25, 51, 58}


def test_wall_options_repeat_until_wall_on_deterministic_grid():
    domain = get_domain("three-floor")
    mdp = domain.mdp()
    options = wall_options(domain, mdp)
    assert [o.name for o in options] == [
        "GoNorth-until-wall", "GoEast-until-wall", "GoSouth-until-wall", "GoWest-until-wall"]
    east = options[1]
    s = domain.cell_state(1, 1, 0)  # top-left room of floor 0, wall at x = 10
    m = option_model(mdp, east)
    end = domain.cell_state(9, 1, 0)
    assert m.F[s, end] == pytest.approx(mdp.gamma**8)
    assert m.duration[s] == 8.0
    assert m.R[s] == pytest.approx(-sum(mdp.gamma**k for k in range(8)))
    assert not east.initiation[end] and east.beta[end] == 1.0


def test_doorway_options_cover_three_floor_and_solve():
    mdp = get_domain("three-floor").mdp()
    options = doorway_options(mdp)
    hubs = (mdp.features["doorway"] == 1) | (mdp.features["stair"] == 1)
    assert [o.subgoal for o in options] == np.flatnonzero(hubs).tolist()
    models = option_models(mdp, options)
    # the options cover every state: no error
    smdp = stack_models(mdp, models, include_primitives=False)
    with_primitives = stack_models(mdp, models, include_primitives=True)
    V_star = solve(mdp, 1e-8).V
    # Options alone cannot enter the goal's room interior: never better than V*.
    assert np.all(solve(smdp, 1e-8).V <= V_star + 1e-6)
    # With the primitive actions the optimum is the MDP's, and value iteration needs fewer sweeps.
    both = solve(with_primitives, 1e-8, method="vi")
    np.testing.assert_allclose(both.V, V_star, atol=1e-5)
    assert both.sweeps < solve(mdp, 1e-8, method="vi").sweeps


def test_stacking_refuses_uncovered_states():
    mdp = get_domain("four-rooms").mdp("G1")
    only = hallway_options(mdp)[:1]
    with pytest.raises(ModelError, match=r"state \d+ .* is in no option's initiation set"):
        options_smdp(mdp, only, include_primitives=False)
    smdp, _ = options_smdp(mdp, only, include_primitives=True)
    assert smdp.n_actions == mdp.n_actions + 1
    bad = option_model(get_domain("two-rooms").mdp(), Option(
        "x", np.ones(get_domain("two-rooms").n_states, bool),
        np.zeros(get_domain("two-rooms").n_states, dtype=np.int64),
        np.ones(get_domain("two-rooms").n_states)))
    with pytest.raises(ModelError, match="model of option 'x' covers"):
        stack_models(mdp, [bad], include_primitives=False)


def test_models_of_another_task_cannot_make_the_new_goal_pay():
    """Models computed under the first task, stacked for a new one: its goal's rows are empty.

    The independent check: every state's value under any policy is the value of the same policy
    with the new goal made absorbing by hand (column 0 chosen there), so which column a policy
    picks at the goal cannot matter. Before the fix, the option columns kept their first-task F
    rows at the new goal and the start value ranged from -34 to +172 with the column.
    """
    from adpart.learning.curves import start_distribution, start_values
    from adpart.options import subgoal_options

    domain = get_domain("three-floor")
    first, new = domain.mdp("reach-goal"), domain.mdp("reach-top-west")
    goal = np.flatnonzero(new.terminal)
    assert not first.terminal[goal].any()
    hubs = np.flatnonzero(np.asarray(new.features["doorway"]) == 1)[:6]
    options = subgoal_options(first, hubs, initiation="basin")
    stale = stack_models(new, option_models(first, options, duration=False),
                         include_primitives=True)
    assert stale.F[np.r_[[o * new.n_states + goal for o in range(stale.n_actions)]].ravel()
                   ].nnz == 0
    policy = solve(stale).policy
    mu = start_distribution(new)
    values = []
    for column in range(stale.n_actions):
        at_goal = policy.copy()
        at_goal[goal] = column
        values.append(start_values(stale, at_goal[None], mu)[0])
    np.testing.assert_allclose(values, values[0], rtol=0, atol=1e-9)

"""Section 4.2.2: a walled grid with four "repeat the move until a wall" options (Figs. 4.3-4.5).

Map (``#`` wall cell, ``G`` goal, gamma = 0.95, -1 per move, +20 for the move into the goal)::

    .....
    .#...
    .#..G
    .....

The block layouts below were worked out by hand from the option semantics (see
``docs/partitioning.md``) and are rendered one letter per block in canonical order.
"""

from __future__ import annotations

import numpy as np
import pytest

from adpart.mdp.solvers import solve
from adpart.partition import MultiPhasePartitioner, check_stability, point_model
from tests.partition.example_grid import as_grid, slide_options

ROWS = [".....", ".#...", ".#..G", "....."]
OPTIONS = [0, 1, 2, 3]  # up, right, down, left


@pytest.fixture(scope="module")
def grid():
    return slide_options(ROWS)


def test_delta_one_phase1_has_two_blocks_per_option(grid):
    model, _cells, term, goal = grid
    res = MultiPhasePartitioner(model, term, delta=1.0).run(OPTIONS, epsilon=1.0)
    for o in OPTIONS:
        p1 = res.phase1[o]
        assert p1.n_blocks == 2
        # the two blocks are exactly the option's termination states and the rest
        assert np.array_equal(p1.labels == p1.labels[goal], term[:, o])
        assert check_stability(p1, model, options=[o], delta=1.0)


def test_delta_one_only_the_reward_splits(grid):
    model, cells, term, _goal = grid
    res = MultiPhasePartitioner(model, term, delta=1.0).run(OPTIONS, epsilon=1.0)
    # phase 2 is the plain intersection of the four termination partitions
    assert as_grid(ROWS, cells, res.phase2.labels) == ["ABCCD", "E#FGH", "E#FGI", "JBKKL"]
    # phase 3: only the reward of "right" (reaching the goal) splits row 2 from row 1
    assert as_grid(ROWS, cells, res.phase3.labels) == ["ABCCD", "E#FGH", "E#IJK", "LBMMN"]
    assert check_stability(res.phase3, model, delta=1.0, epsilon=1.0)


def test_delta_below_one_blocks_follow_where_options_land(grid):
    model, cells, term, _goal = grid
    res = MultiPhasePartitioner(model, term, delta=0.5).run(OPTIONS, epsilon=1.0)
    # "up": wall-bumpers (row 0 and below the wall) / slides into row 0 / the goal / the one
    # cell whose upward slide ends at the goal
    assert as_grid(ROWS, cells, res.phase1[0].labels) == ["AAAAA", "B#BBB", "B#BBC", "BABBD"]
    # "right": cells whose slide ends at the goal (row 2) split from those ending at the border
    assert as_grid(ROWS, cells, res.phase1[1].labels) == ["AAAAB", "B#AAB", "B#CCD", "AAAAB"]
    expected = ["ABCCD", "E#FGH", "E#IJK", "LMNNO"]
    assert as_grid(ROWS, cells, res.phase2.labels) == expected
    assert as_grid(ROWS, cells, res.phase3.labels) == expected
    for p in (*res.phase1.values(), res.phase2, res.phase3):
        opts = OPTIONS if p is not res.phase1.get(0) else [0]
        assert check_stability(p, model, options=opts, delta=0.5)
    assert check_stability(res.phase3, model, delta=0.5, epsilon=1.0)


def _landing(model, s, o):
    S = model.n_states
    row = model.F[[o * S + s]]
    return int(row.indices[0]) if row.nnz else None


def test_policy_solved_on_the_blocks_reaches_the_goal(grid):
    model, cells, term, goal = grid
    part = MultiPhasePartitioner(model, term, delta=0.5).run(OPTIONS, epsilon=1.0).phase3
    sol = solve(point_model(part, model), 1e-9)
    policy = sol.policy[part.labels]
    for start in range(model.n_states):
        s, steps = start, 0
        while s != goal and steps < 20:
            s = _landing(model, s, int(policy[s]))
            steps += 1
        assert s == goal, f"from cell {cells[start]} the block policy does not reach the goal"

"""three-rooms-line: the conformance check, the map's facts and V* in closed form."""

from __future__ import annotations

import numpy as np
import pytest
from adpart.mdp.solvers import solve
from adpart.testing import check_environment

from adpart_plugin_example import ThreeRoomsLine


def test_passes_adparts_environment_check():
    check_environment(ThreeRoomsLine)


def test_the_map():
    domain = ThreeRoomsLine()
    assert (domain.n_states, domain.n_actions) == (77, 4)
    doors = np.flatnonzero(domain.dynamics().features["door"])
    assert doors.tolist() == [domain.cell_state(5, 2), domain.cell_state(11, 2)]
    assert set(domain.tasks()) == {"reach-east", "reach-middle", "reach-west"}


@pytest.mark.parametrize(("task", "start", "goal"), [
    ("reach-east", (0, 4), (15, 1)),
    ("reach-middle", (0, 4), (8, 2)),
    ("reach-west", (16, 4), (0, 0)),
])
def test_optimal_start_value_is_the_shortest_path_through_the_doors(task, start, goal):
    # Every shortest path is monotone in x and y and passes the doors (both at y = 2), so the
    # distance is the Manhattan distance d: V* = -(1 + g + ... + g^(d-1)) + 10 g^(d-1).
    domain = ThreeRoomsLine()
    mdp = domain.mdp(task)
    d = abs(start[0] - goal[0]) + abs(start[1] - goal[1])
    g = mdp.gamma
    expected = -(1 - g**d) / (1 - g) + 10 * g ** (d - 1)
    s0 = domain.cell_state(*start)
    assert mdp.initial[s0] == 1.0 and mdp.terminal[domain.cell_state(*goal)]
    assert solve(mdp, 1e-12).V[s0] == pytest.approx(expected, abs=1e-9)

"""Four rooms (Sutton, Precup & Singh 1999, "Between MDPs and semi-MDPs", AIJ 112, Fig. 2).

The 13 x 13 map of Sutton, Precup & Singh (1999) with its 104 free cells; the hallways at
(row, col) (3,6), (6,2), (7,9), (10,6) are states 25, 51, 62, 88 (row-major order over free
cells) and carry the feature ``hallway`` = 1 (used by the hallway options). Four moves; the
intended move succeeds w.p. 2/3 and each of the other three happens w.p. 1/9; a move into a wall
stays put. gamma = 0.9.

Reward convention: the paper pays +1 on the transition *out of* the goal into an extra terminal
state. Our FiniteMDP ends an episode on *arrival* in a terminal state (value 0), so we pay +1 on
arrival in the goal and 0 otherwise. The two formulations have the same optimal policies and
``V_here(s) = V_paper(s) / gamma`` for every non-goal state.

Tasks: ``G1`` = the east hallway (row 7, col 9); ``G2`` = the cell (row 9, col 8), inside the
lower-right room (our choice: the paper only says "a cell inside a room"). Episodes start
uniformly over the non-goal cells.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

from adpart.envs.base import Dynamics, GoalSpec, TaskFactory
from adpart.envs.grid import GridDomain, Slip

FOUR_ROOMS_MAP = """
#############
#.....#.....#
#.....#.....#
#.....D.....#
#.....#.....#
#.....#.....#
##D####.....#
#.....###D###
#.....#.....#
#.....#.....#
#.....D.....#
#.....#.....#
#############
"""

GAMMA = 0.9
#: (row, col) of the hallways, west-to-east / north-to-south as in ENVIRONMENTS.md.
HALLWAYS = ((3, 6), (6, 2), (7, 9), (10, 6))


class FourRooms(GridDomain):
    """Sutton, Precup & Singh's four-room world: 104 states, 4 noisy moves."""

    name = "four-rooms"
    description = "13x13 four-room grid, 104 states, moves succeed 2/3 else 1/9 each other move"
    source = "Sutton, Precup & Singh 1999 (AIJ 112), Fig. 2"
    default_task = "G1"

    MAP = FOUR_ROOMS_MAP
    CONNECTIVITY = 4
    SLIP = Slip("uniform", 2.0 / 3.0)
    DEFAULT_COST = 0.0

    def _build_dynamics(self) -> Dynamics:
        dyn = super()._build_dynamics()
        return dataclasses.replace(dyn, features={**dyn.features, "hallway": dyn.features["door"]})

    def tasks(self) -> Mapping[str, TaskFactory | GoalSpec]:
        return {
            "G1": GoalSpec(goal={"x": 9, "y": 7}, goal_reward=1.0, gamma=GAMMA, name="G1"),
            "G2": GoalSpec(goal={"x": 8, "y": 9}, goal_reward=1.0, gamma=GAMMA, name="G2"),
        }

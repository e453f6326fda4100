"""Two rooms joined by a doorway (dissertation section 4.1, Fig. 4.2).

A 10 x 6 grid split by a wall column with one doorway; eight deterministic moves (the four
compass moves and the four diagonals), reward -1 per straight and -1.2 per diagonal move, +10 on
arrival at the goal in the upper right; every episode starts in the lower-left corner. The figure
gives neither the wall's column nor the doorway's row: we put the wall at x = 5 and the doorway
at (x=5, y=2), and the goal at (x=8, y=1), which leaves 55 free cells = 55 states. The
dissertation does not state gamma; we use 0.95.
"""

from __future__ import annotations

from collections.abc import Mapping

from adpart.envs.base import GoalSpec, TaskFactory
from adpart.envs.grid import GridDomain

TWO_ROOMS_MAP = """
.....#....
.....#..G.
.....D....
.....#....
.....#....
S....#....
"""

DIAGONAL_COST = -1.2
GAMMA = 0.95


class TwoRooms(GridDomain):
    """The two-room world of Fig. 4.2: 55 states, 8 deterministic moves."""

    name = "two-rooms"
    description = "10x6 grid, two rooms joined by a doorway, 8 deterministic moves (55 states)"
    source = "Dissertation section 4.1, Fig. 4.2"
    default_task = "reach-goal"

    MAP = TWO_ROOMS_MAP
    CONNECTIVITY = 8
    DEFAULT_COST = -1.0
    COSTS: Mapping[str, float] = {
        "GoNorthEast": DIAGONAL_COST,
        "GoSouthEast": DIAGONAL_COST,
        "GoSouthWest": DIAGONAL_COST,
        "GoNorthWest": DIAGONAL_COST,
    }

    def tasks(self) -> Mapping[str, TaskFactory | GoalSpec]:
        return {
            "reach-goal": GoalSpec(
                goal={"goal": 1}, goal_reward=10.0, gamma=GAMMA, name="reach-goal"
            ),
        }

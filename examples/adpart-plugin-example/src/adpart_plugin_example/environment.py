"""``three-rooms-line``: three rooms in a row, joined by single-cell doors.

A 17 x 5 grid of three 5 x 5 rooms separated by wall columns at x = 5 and x = 11, each with one
door in the middle row (y = 2); four deterministic compass moves (a move into a wall leaves the
agent in place), reward -1 per move and +10 on arrival at the goal; episodes start in the
lower-left corner of the west room. 75 room cells + 2 doors = 77 states; gamma 0.95.

Unlike adpart's two-rooms (8 moves, one door) every path east crosses two doors in turn, and with
4 moves each door is a corridor of three cut cells (the door and the cells in front of it).
"""

from __future__ import annotations

from collections.abc import Mapping

from adpart.envs.base import GoalSpec, TaskFactory
from adpart.envs.grid import GridDomain
from adpart.params import Param
from adpart.plugins import hookimpl

THREE_ROOMS_LINE_MAP = """
.....#.....#.....
.....#.....#...G.
.....D.....D.....
.....#.....#.....
S....#.....#.....
"""

GAMMA = 0.95
GOAL_REWARD = 10.0


class ThreeRoomsLine(GridDomain):
    """Three 5x5 rooms in a row joined by doors at (5, 2) and (11, 2): 77 states, 4 moves."""

    name = "three-rooms-line"
    description = ("17x5 grid, three rooms in a row joined by two doors, 4 deterministic moves "
                   "(77 states)")
    source = "adpart-plugin-example (a plugin-authoring example)"
    #: Environments are built with ``cls()`` (adpart passes no parameters to an environment), so a
    #: variant of the map is another class with another name, not a parameter.
    params: tuple[Param, ...] = ()
    default_task = "reach-east"

    MAP = THREE_ROOMS_LINE_MAP
    CONNECTIVITY = 4
    DEFAULT_COST = -1.0

    def tasks(self) -> Mapping[str, TaskFactory | GoalSpec]:
        return {
            # the G cell of the east room, from the start S in the west room
            "reach-east": GoalSpec(goal={"goal": 1}, goal_reward=GOAL_REWARD, gamma=GAMMA,
                                   name="reach-east"),
            # the centre of the middle room, from the same start
            "reach-middle": GoalSpec(goal={"x": 8, "y": 2}, goal_reward=GOAL_REWARD, gamma=GAMMA,
                                     name="reach-middle"),
            # back west: the upper-left corner, from the lower-right corner of the east room
            "reach-west": GoalSpec(goal={"x": 0, "y": 0}, start={"x": 16, "y": 4},
                                   goal_reward=GOAL_REWARD, gamma=GAMMA, name="reach-west"),
        }


@hookimpl
def register_environments(register) -> None:  # type: ignore[no-untyped-def]
    register(ThreeRoomsLine)

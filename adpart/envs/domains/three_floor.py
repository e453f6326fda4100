"""The dissertation's three-floor worlds (section 5.1): ``three-floor`` and ``three-floor-arm``.

No layout of either world is published (the figures show them only schematically), so the maps
below are our own: three floors of rooms of random sizes, drawn once by recursive division with
a fixed seed and written out here, joined by stairways. They are fixed; nothing is random at run
time.

``three-floor`` (section 5.1.1, Fig. 5.1): three 40 x 33 floors, 2,900 free cells = 2,900 states,
deterministic moves GoNorth/GoEast/GoSouth/GoWest plus GoUp/GoDown on the stair cells (``H``;
each joins the same (x, y) on the floor above or below). The doorways (``D``) and the stair cells
are the hand-designed subgoals drawn black in Fig. 5.1; they carry the features ``doorway`` and
``stair``. Two reward models, each task in both:

* ``reach-...`` (the default): -1 per action and +100 on arrival at the goal;
* ``reach-...-goal-only``: +100 on arrival at the goal and nothing else - the model of section
  5.1.3, whose minimum reward is 0 (the seed states "let the minimum reward be r = 0" for this
  domain; 5.1.1 gives only the goal's +100).

The default keeps the step cost because it is the usual shortest-path formulation and every
earlier figure of this project was measured on it; the goal-only model is the seed's, under
which Q = 0 is a true lower bound instead of an optimistic guess (docs/environments/grid.md).
gamma = 0.99 for both (not stated in the dissertation; shortest paths to the goal run up to 129
steps, so a smaller gamma would hide the goal).

``three-floor-arm`` (section 5.1.4, Fig. 5.6): three 20 x 17 floors with obstacles, 600 free
cells; the state is cell x arm (closed/open) x object (at its source site 0, at the destination
site 1, or held), 600 x 2 x 3 = 3,600 states. Actions GoNorth, GoEast, GoSouth, GoWest (succeed
w.p. 0.5, slip to each perpendicular side w.p. 0.25), GoUp, GoDown, OpenArm, CloseArm, Pickup,
Drop (deterministic). Pickup needs an open arm on the object's cell; Drop puts a held object on
the object site the agent stands on (sites ``0`` and ``1`` of the map); both are no-ops
otherwise. The dissertation's stairways are macro actions of 10 GoUp/GoDown steps; ours are single
steps, which leaves the macro to the option layer. Reward -1 per action, +100 on arrival in the
goal; gamma = 0.99. Task ``deliver`` = pick the object up at site 0 (floor 0) and drop it at
site 1 (floor 2); ``navigate`` = reach the cell of site 1 (x=3, y=2, floor 2) carrying nothing
in particular.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from types import MappingProxyType
from typing import ClassVar

from adpart.envs.base import Dynamics, GoalSpec, TaskFactory
from adpart.envs.grid import GridDomain, Slip

THREE_FLOOR_MAP = """
--- floor 0 ---
########################################
#S........#.........#.....#......#.....#
#.........#.........#.....#......##....#
#.........#.........#.....#......#.....#
#.........#.........#.....#......#.....#
#.........#.........#.....#......#.....#
#.........#.........###D###......D.....#
####D######.........#.....##########D###
#.........#.........#.....#......#.....#
#.........#.........#.....#......#.....#
#.........########D##.....#......#.....#
#.........D.........#.....#......#.....#
#.........#.........#..#..#......#.....#
#...H.....#.........#.....#......#.....#
#.........#.........#####D#......#.....#
#.........#.........#.....#......#.....#
#.........#.........#.....#......#.....#
#.........#.........#.....#......D.....#
##D##################.....#####D########
#..........D........#.....#......#.....#
#..........#........#.#...#......#.....#
#..........#........#.....#......#.....#
#..........#...#....#.....#......#.....#
#..........#........D.....#......D.....#
#############D##################D#######
#..........#.....#........#..H...#.....#
#..........#.....#........#......D.....#
#..........#.....#........#......#.....#
#..........#.....D........#......#.....#
#..........#.....#........#......#.....#
#.#........#.....#........D......#.....#
#..........D.....#........#......#.....#
########################################
--- floor 1 ---
########################################
#......#........#.....#.....#..........#
#......#........#.....#.....#..........#
#......#........#.....#.....#..........#
#......D........#.....#.....#..........#
#......#........#.....#.....#..........#
###########D#####D######D####..........#
#.........#.....#.....#.....#..........#
#.........#.....#.....#.....#..........#
#.........#.....#.....#.....#######D####
#.........#.....#.....D.....#..........#
#.........#.....#.....#.....#..........#
#.........D.....###########D#..........#
#...H.....#.....#.....#.....#..........#
#.........#.....#.....D.....D..........#
#D###############.....#.....#..........#
#......#........D.....#.....#..........#
#......#........#.....#.....#######D####
#......D........#.....#.....#..........#
#......#........#.....#.....#..........#
#......#........#.....#.....#..........#
#......#........#.....#.....#..........#
#......#........#.....#.....#..........#
###################D#########..........#
#.........#.......#.........####D#######
#.........#..H....#.........#H.........#
#.##......#.......#.........#..........#
#.........#.......#.........#..........#
#.........#.......#.........#..........#
#.........#.......#.........#.......#..#
#.........#.......D.....H...#..........#
#.........D.......#.........#..........#
########################################
--- floor 2 ---
########################################
#........#..........#......#.....#.....#
#........#..........#......#.....#.....#
#........#..........#......#.....#.....#
#........#..........#......#.....#.....#
#........#..........#......#.....D.....#
#........##D#########......########D####
#........#..........###D####.....#.....#
#........#..........#......#.....#.....#
#........#..........D......#.....#.....#
#........#..........#......#...#.#.....#
#######D##..........#......#.....#.....#
#........#..........#......D.....D.....#
#........##D############################
#........#.........#.........#.........#
#........#.........#.........#.........#
#........#.........#.........#.........#
#........#.........#.........#.........#
#####D####.........#.........#.........#
#........###D###############D#######D###
#........D.........#.........#.........#
#........#........##.........#.........#
#........#.........#.........#.........#
#........#.........#.........#.........#
###D######.........#.........#.........#
#........#...H.....##D###############D##
#........#######D###.........#.........#
#........#.........#.........D.........#
#........#.........#.........#......#..#
#........#.........#.........#.........#
#........#.........D....H....#.......G.#
#........#.........#.........#.........#
########################################
"""

THREE_FLOOR_ARM_MAP = """
--- floor 0 ---
####################
#S.......#....##...#
#.H......##...#....#
#........#....#....#
#..#.....#....#....#
#D########....D....#
#.....#..########D##
#........#....#....#
##.#.....D....#....#
#........#..#.D....#
########D#....#....#
#.....#..##D######D#
#....#...#.H..#....#
#........#....#....#
#.#......#....#..0.#
#........#.#..#....#
####################
--- floor 1 ---
####################
#.......##...#..#..#
#.H.....#....#.....#
#.......D.#..#..#..#
#.......#....#.....#
####D#######D###D###
#.......#....#.....#
#.......#....#.....#
#.......##..##..H..#
#.......#....#.....#
#######D######.....#
##...#.......#D#####
#....D.....H.D.....#
#.#..#...#...#..#.##
#....#...#..##....##
#H...#.......#.....#
####################
--- floor 2 ---
####################
#.#...#.#....#.....#
#..1....#....D..#..#
#.#..#..##...#.#...#
#.....#.#...##.....#
#.......########D###
##D######....#.....#
#.......D....#.....#
#.......#..#.#..H..#
#.......#....#.....#
#...#...####DD.....#
##D######....#####D#
#.......#...###....#
#..#..#.##.###....##
#..#..#.#....#...#.#
#H......#..#.#.....#
####################
"""

GAMMA = 0.99
GOAL_REWARD = 100.0
#: A moved goal (``goal:x=..,y=..,floor=..``) pays what the named tasks pay.
MOVED_GOAL = MappingProxyType({"goal_reward": GOAL_REWARD, "gamma": GAMMA})
#: Suffix of the tasks in section 5.1.3's reward model (no step cost, +100 at the goal).
GOAL_ONLY = "-goal-only"


class ThreeFloor(GridDomain):
    """Fig. 5.1's deterministic three-floor world: 2,900 states, 6 actions."""

    name = "three-floor"
    description = "three floors of rooms joined by stairways, deterministic (2,900 states)"
    source = "Dissertation section 5.1.1, Fig. 5.1 (our layout; the figure is schematic)"
    default_task = "reach-goal"
    goal_defaults: ClassVar[Mapping[str, object]] = MOVED_GOAL

    MAP = THREE_FLOOR_MAP

    def _build_dynamics(self) -> Dynamics:
        dyn = super()._build_dynamics()
        return dataclasses.replace(dyn, features={**dyn.features, "doorway": dyn.features["door"]})

    def tasks(self) -> Mapping[str, TaskFactory | GoalSpec]:
        goals = {
            "reach-goal": {"goal": 1},
            "reach-ground-east": {"x": 37, "y": 1, "floor": 0},
            "reach-middle-south": {"x": 1, "y": 30, "floor": 1},
            "reach-top-west": {"x": 1, "y": 1, "floor": 2},
        }
        free = (0.0,) * len(self.dynamics().action_names)
        tasks: dict[str, TaskFactory | GoalSpec] = {}
        for name, goal in goals.items():
            tasks[name] = GoalSpec(goal=goal, goal_reward=GOAL_REWARD, gamma=GAMMA, name=name)
        for name, goal in goals.items():
            tasks[f"{name}{GOAL_ONLY}"] = GoalSpec(
                goal=goal, goal_reward=GOAL_REWARD, gamma=GAMMA, step_costs=free,
                name=f"{name}{GOAL_ONLY}")
        return tasks


class ThreeFloorArm(GridDomain):
    """Fig. 5.6's stochastic three-floor world with an arm and one object: 3,600 states."""

    name = "three-floor-arm"
    description = (
        "three floors with obstacles, an arm and one object; moves succeed 0.5 (3,600 states)"
    )
    source = "Dissertation section 5.1.4, Fig. 5.6 (our layout; the figure is schematic)"
    default_task = "deliver"
    goal_defaults: ClassVar[Mapping[str, object]] = MOVED_GOAL

    MAP = THREE_FLOOR_ARM_MAP
    SLIP = Slip("perpendicular", 0.5)
    ARM = True

    def tasks(self) -> Mapping[str, TaskFactory | GoalSpec]:
        return {
            "deliver": GoalSpec(
                goal={"object": 1}, goal_reward=GOAL_REWARD, gamma=GAMMA, name="deliver"
            ),
            "navigate": GoalSpec(
                goal={"x": 3, "y": 2, "floor": 2}, goal_reward=GOAL_REWARD, gamma=GAMMA,
                name="navigate",
            ),
        }

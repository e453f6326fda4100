"""Parr's maze (Parr & Russell 1998; Dietterich 2000 sec. 7.3; dissertation ch. 6, Fig. 6.1).

Hallways and intersections built from 12 x 12 rooms with obstacles; start in the top-left corner,
goal = any cell of the bottom-right room (terminal). No original map is public: the layout is
the published *reconstruction* of BaRL_Envs (Joshua Evans, MIT licence; see
``adpart/envs/data/NOTICE``), shipped as package data: 86 x 86 cells, 3,710 free cells = 3,710
states, start S = (x=1, y=1), 143 goal cells G. ``ParrMaze(mini=True)`` loads its smaller
version (1,988 free cells).

Dynamics as in the dissertation: GoNorth/GoEast/GoSouth/GoWest succeed w.p. 0.8 and move to each
perpendicular side w.p. 0.1; a move into a wall or obstacle has no effect. Reward -1 per step
(0 extra on arrival in the goal). Dietterich's task is undiscounted; we use gamma = 0.99 so that
every solver's contraction argument holds (with a proper policy the undiscounted values are the
limit gamma -> 1; the optimal policies agree closely).
"""

from __future__ import annotations

from collections.abc import Mapping
from importlib import resources

from adpart.envs.base import GoalSpec, TaskFactory
from adpart.envs.grid import GridDomain, Slip
from adpart.errors import MapError

LAYOUT = "parr_maze_ueva_barl_envs.txt"
MINI_LAYOUT = "parr_mini_maze_ueva_barl_envs.txt"
GAMMA = 0.99


def load_layout(filename: str) -> str:
    """Read a shipped BaRL_Envs layout (cells separated by spaces) as map-language text."""
    path = resources.files("adpart") / "envs" / "data" / filename
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise MapError(
            f"layout {filename!r} is missing from the installed package (adpart/envs/data); "
            "reinstall adpart"
        ) from None
    return "\n".join("".join(line.split()) for line in text.splitlines())


class ParrMaze(GridDomain):
    """Parr's maze as reconstructed by BaRL_Envs: 3,710 states, 4 noisy moves."""

    name = "parr-maze"
    description = "Parr's 86x86 maze, hallways and intersections, moves succeed 0.8 (3,710 states)"
    source = (
        "Dissertation chapter 6, Fig. 6.1 (Parr & Russell 1998; Dietterich 2000 sec. 7.3); "
        "layout: BaRL_Envs reconstruction, MIT licence (c) 2020 Joshua Evans"
    )
    default_task = "reach-goal"

    CONNECTIVITY = 4
    SLIP = Slip("perpendicular", 0.8)
    DEFAULT_COST = -1.0

    def __init__(self, mini: bool = False) -> None:
        self.mini = mini
        self.MAP = load_layout(MINI_LAYOUT if mini else LAYOUT)
        if mini:
            self.name = "parr-maze-mini"

    def tasks(self) -> Mapping[str, TaskFactory | GoalSpec]:
        return {
            "reach-goal": GoalSpec(
                goal={"goal": 1}, goal_reward=0.0, gamma=GAMMA, name="reach-goal"
            ),
        }

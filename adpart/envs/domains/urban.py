"""Urban: a pose-based city domain standing in for the dissertation's 20,000-state game domain.

The seed's third and fourth experiments (dissertation sections 5.1.5 and 5.2, Fig. 5.11) run in the
Urban Combat Testbed, a computer game whose map is not public: the agent moves with GoUp, GoDown,
TurnLeft and TurnRight, picks up and drops off objects, every action costs -1, navigation
succeeds with probability 1, the goal pays 100, and the state - the agent's pose plus local
object percepts - has about 20,000 values. This module rebuilds a domain with those facts on a
fixed city map of its own (:data:`MAP`, 46 x 58 cells, 1,667 free):

* five regions: ``downtown`` (NW, a street grid of city blocks with a plaza), ``park`` (NE, a
  fenced park with trees and a pond, three gates), ``industrial`` (SW, three warehouses with
  doors, crates inside), ``residential`` (SE, rows of houses on narrow lanes and a square), and
  the ``avenue`` cross joining them;
* pickup sites ``P`` (inside the warehouses), drop sites ``D`` (two in the residential quarter,
  one downtown), the start ``S`` on the avenue, and the named locations ``A`` (downtown) and
  ``B`` (in the park).

State: ``s = (cell * 4 + heading) * 3 + load``, with ``cell`` the row-major index of the free
cell, ``heading`` 0-3 = N, E, S, W and ``load`` 0 = hands empty (nothing delivered yet),
1 = carrying the object, 2 = delivered (hands empty again). So there are exactly
1,667 x 4 x 3 = **20,004 states**. The third load value is the only "percept" beyond the pose;
it is needed because the fifth task ("pick up, then drop off") must tell an agent that has
delivered from one that never picked up.

Actions (6): GoForward (one cell along the heading), GoBack (one cell against it, heading
kept), TurnLeft, TurnRight (rotate 90 degrees in place), PickUp (at a pickup site with empty
hands, load 0 or 2 -> 1), DropOff (at a drop site while carrying, load 1 -> 2). Everything is
deterministic; a move into a building, tree, water or the border, and a PickUp / DropOff where
it does not apply, leave the state unchanged and still cost -1.

Tasks (:meth:`Urban.tasks`; each a :class:`~adpart.envs.base.GoalSpec` with step cost -1,
``goal_reward = 100`` added on the arriving transition - so that step earns 99 - terminal goal
states and ``gamma = 0.95``, the discount of the seed's grid experiments):

============================  ===================================  ==========================
task                          start (uniform over the 4 headings)  goal (terminal)
============================  ===================================  ==========================
``navigate``                  ``S``, load 0                        at ``A`` (downtown)
``navigate-pickup``           ``S``, load 0                        load 1 (carrying)
``navigate-2``                ``S``, load 0                        at ``B`` (the park)
``navigate-dropoff``          ``S``, load 1 (carrying)             load 2 (delivered)
``pickup-dropoff``            ``S``, load 0                        load 2 (delivered)
============================  ===================================  ==========================
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from adpart.envs.base import Domain, Dynamics, GoalSpec, TaskFactory
from adpart.errors import MapError, TaskError

if TYPE_CHECKING:
    from matplotlib.axes import Axes

#: The city map. ``#`` building or wall, ``T`` tree, ``~`` water (all blocked); ``.`` street or
#: floor, ``P`` pickup site, ``D`` drop site, ``S`` start, ``A`` / ``B`` named locations (free).
MAP: tuple[str, ...] = (
    "##########################################################",
    "#.D..........######..####..#...###########################",
    "#............######..####..#...#.........................#",
    "#..####..####..####..####..#...#...T............T....T...#",
    "#A.####..####..####..####......#.......................T.#",
    "#..####..####..####..####..#...#......T.T........TTT.....#",
    "#..........................#...#...TT..T...T.....T.T.....#",
    "#..........................#...#..........T~~~~~~T.......#",
    "#..####........####..####..#...#...........~~~~~~...T....#",
    "#..####...##...####..####..#...#.........TT~~~~~~........#",
    "#..####........####..####..#.....T.......T.~~~~~~.T...T..#",
    "#..........................#...#.........................#",
    "#..........................#...#......T.....T.TTTT.......#",
    "#..####..####..####..####..#...#.................T.......#",
    "#..####..####..####..####..#...#.......T..............T..#",
    "#..####..####..####..####......#..T.............T.B......#",
    "#..........................#...#.....T.T..T.T.T..........#",
    "#..........................#...#.T.....T.................#",
    "#..#########..###########..#...#.........................#",
    "#..#########..###########..#...######.############.#######",
    "#............................S...........................#",
    "#........................................................#",
    "#..............................#.........................#",
    "#.############..############...#.###.###.###.###.###.###.#",
    "#.#..........#..#..........#...#.###.###.###.###.###.###.#",
    "#.#.##.......#..#..#######.#...#.........................#",
    "#.#.##.......#..#.......##.#.....###.###.###.###.###.###.#",
    "#.#....P.....#........P....#...#.###.###.###.###.###.###.#",
    "#.#......##..#..#..........#...#...............D.........#",
    "#.#......##..#..#..######..#...#.###.###.............###.#",
    "#.#..........#..#..........#...#.###.###.............###.#",
    "#.######.#####..############...#.............##..........#",
    "##.............................#.###.###.............###.#",
    "##.............................#.###.###.............###.#",
    "##############.#############...#.........................#",
    "###........................#...#.###.###.###.###.###.###.#",
    "###.######.................#...#.###.###.###.###.###.###.#",
    "###........................#.............................#",
    "###...#....#....#....#.........#.###.###.###.###.###.###.#",
    "###...#....#....#....#..##.#...#.###.###.###.###.###.###.#",
    "###...#....#....#....#..##.#...#.........................#",
    "###.........P..............#...#.###.###.###.###.###.###.#",
    "###...............#######..#...#.###.###.###.###.###.###.#",
    "###.########...............#...#.........................#",
    "############################...#........................D#",
    "##########################################################",
)
BLOCKED = "#T~"
FREE = ".PDSAB"
#: Region name -> (first row, last row, first col, last col), inclusive; cells outside every
#: rectangle belong to the avenues (region 0).
REGIONS: dict[str, tuple[int, int, int, int]] = {
    "downtown": (1, 19, 1, 27),
    "park": (1, 19, 31, 56),
    "industrial": (23, 44, 1, 27),
    "residential": (23, 44, 31, 56),
}
REGION_NAMES: tuple[str, ...] = ("avenue", *REGIONS)
HEADINGS: tuple[str, ...] = ("N", "E", "S", "W")
#: (d_row, d_col) of a step along each heading.
STEPS: tuple[tuple[int, int], ...] = ((-1, 0), (0, 1), (1, 0), (0, -1))
ACTION_NAMES: tuple[str, ...] = (
    "GoForward", "GoBack", "TurnLeft", "TurnRight", "PickUp", "DropOff",
)
GO_FORWARD, GO_BACK, TURN_LEFT, TURN_RIGHT, PICK_UP, DROP_OFF = range(6)
N_HEADINGS = 4
N_LOADS = 3
EMPTY, CARRYING, DELIVERED = range(N_LOADS)
STEP_REWARD = -1.0
GOAL_REWARD = 100.0


def parse_map(rows: tuple[str, ...]) -> np.ndarray:
    """The map as a ``(H, W)`` array of characters, checked for shape and alphabet."""
    widths = {len(r) for r in rows}
    if len(widths) != 1:
        raise MapError(f"urban map rows have different widths {sorted(widths)}; pad them")
    grid = np.array([list(r) for r in rows])
    unknown = sorted(set(grid.ravel()) - set(BLOCKED + FREE))
    if unknown:
        raise MapError(f"urban map has unknown characters {unknown}; use one of {BLOCKED + FREE!r}")
    border = np.concatenate([grid[0], grid[-1], grid[:, 0], grid[:, -1]])
    if np.isin(border, list(FREE)).any():
        raise MapError("urban map border has a free cell; close the border with '#'")
    return grid


class Urban(Domain):
    """A city map with poses (cell x heading) and an object to fetch and deliver: 20,004 states.

    Args:
        gamma: discount factor of the named tasks (0.95 by default).
        goal_reward: reward added on arrival at a goal (100, as in the seed's game domain).
    """

    name = "urban"
    description = (
        "pose-based city navigation with pickup and drop-off (stand-in for the 20,000-state "
        "game domain)"
    )
    source = "dissertation sections 5.1.5 and 5.2, Fig. 5.11 (map reconstructed; see docs)"
    default_task = "navigate"

    def __init__(self, *, gamma: float = 0.95, goal_reward: float = GOAL_REWARD) -> None:
        if not 0.0 < gamma <= 1.0:
            raise TaskError(f"gamma = {gamma!r} is outside (0, 1]; urban uses 0.95 by default")
        self.gamma = float(gamma)
        self.goal_reward = float(goal_reward)
        self.grid = parse_map(MAP)
        self.free = np.isin(self.grid, list(FREE))
        self.cells = np.argwhere(self.free)  # (C, 2) row-major (row, col) of free cells
        index = np.full(self.free.shape, -1, dtype=np.int64)
        index[self.free] = np.arange(len(self.cells))
        self.cell_index = index

    # ------------------------------------------------------------------------------- layout
    @property
    def n_cells(self) -> int:
        return len(self.cells)

    def sites(self, char: str) -> np.ndarray:
        """``(k, 2)`` (row, col) of the cells marked ``char`` (a site letter, ``T`` or ``~``)."""
        return np.argwhere(self.grid == char)

    def location(self, char: str) -> dict[str, int]:
        """The ``{"x": col, "y": row}`` feature spec of the single cell marked ``char``."""
        (row, col), = self.sites(char)
        return {"x": int(col), "y": int(row)}

    def cell_regions(self) -> np.ndarray:
        """``(C,)`` region id of every free cell (index into :data:`REGION_NAMES`)."""
        rows, cols = self.cells[:, 0], self.cells[:, 1]
        region = np.zeros(self.n_cells, dtype=np.int64)
        for i, (r0, r1, c0, c1) in enumerate(REGIONS.values(), start=1):
            inside = (rows >= r0) & (rows <= r1) & (cols >= c0) & (cols <= c1)
            region[inside] = i
        return region

    def encode(self, cell: np.ndarray, heading: np.ndarray, load: np.ndarray) -> np.ndarray:
        """State index ``(cell * 4 + heading) * 3 + load``."""
        return (np.asarray(cell) * N_HEADINGS + heading) * N_LOADS + load

    def decode(self, state: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(cell, heading, load)`` of state indices (inverse of :meth:`encode`)."""
        s = np.asarray(state)
        return s // (N_HEADINGS * N_LOADS), (s // N_LOADS) % N_HEADINGS, s % N_LOADS

    def _neighbours(self) -> np.ndarray:
        """``(C, 4)`` cell reached by one step along each heading (itself when blocked)."""
        rows, cols = self.cells[:, 0], self.cells[:, 1]
        out = np.empty((self.n_cells, N_HEADINGS), dtype=np.int64)
        for h, (dr, dc) in enumerate(STEPS):
            target = self.cell_index[rows + dr, cols + dc]  # the border is closed: in bounds
            out[:, h] = np.where(target >= 0, target, np.arange(self.n_cells))
        return out

    # ----------------------------------------------------------------------------- dynamics
    def successors(self) -> np.ndarray:
        """``(A, S)`` deterministic successor of every (action, state), vectorised over states."""
        S = self.n_cells * N_HEADINGS * N_LOADS
        cell, heading, load = self.decode(np.arange(S))
        nbr = self._neighbours()
        rows, cols = self.cells[cell, 0], self.cells[cell, 1]
        at_pickup = self.grid[rows, cols] == "P"
        at_drop = self.grid[rows, cols] == "D"
        picked = np.where(at_pickup & (load != CARRYING), CARRYING, load)
        dropped = np.where(at_drop & (load == CARRYING), DELIVERED, load)
        return np.stack([
            self.encode(nbr[cell, heading], heading, load),
            self.encode(nbr[cell, (heading + 2) % N_HEADINGS], heading, load),
            self.encode(cell, (heading - 1) % N_HEADINGS, load),
            self.encode(cell, (heading + 1) % N_HEADINGS, load),
            self.encode(cell, heading, picked),
            self.encode(cell, heading, dropped),
        ])

    def _build_dynamics(self) -> Dynamics:
        succ = self.successors()
        A, S = succ.shape
        P = sp.csr_array(
            (np.ones(A * S), succ.reshape(-1), np.arange(A * S + 1)), shape=(A * S, S)
        )
        cell, heading, load = self.decode(np.arange(S))
        features = {
            "x": self.cells[cell, 1].astype(np.int64),
            "y": self.cells[cell, 0].astype(np.int64),
            "heading": heading.astype(np.int64),
            "load": load.astype(np.int64),
            "carrying": (load == CARRYING).astype(np.int64),
            "delivered": (load == DELIVERED).astype(np.int64),
            "region": self.cell_regions()[cell],
        }
        start = (cell == self.cell_index[tuple(self.sites("S")[0])]) & (load == EMPTY)
        return Dynamics(
            P=P,
            action_names=ACTION_NAMES,
            action_costs=np.full(A, STEP_REWARD),
            features=features,
            admissible=None,
            start=start / start.sum(),
        )

    # -------------------------------------------------------------------------------- tasks
    def tasks(self) -> Mapping[str, TaskFactory | GoalSpec]:
        """The five tasks of section 5.2's sequence (goals in the module docstring)."""
        start = {**self.location("S"), "load": EMPTY}
        common = {"goal_reward": self.goal_reward, "gamma": self.gamma}
        return {
            "navigate": GoalSpec(goal=self.location("A"), start=start, name="navigate", **common),
            "navigate-pickup": GoalSpec(
                goal={"load": CARRYING}, start=start, name="navigate-pickup", **common
            ),
            "navigate-2": GoalSpec(goal=self.location("B"), start=start, name="navigate-2",
                                   **common),
            "navigate-dropoff": GoalSpec(
                goal={"load": DELIVERED}, start={**start, "load": CARRYING},
                name="navigate-dropoff", **common,
            ),
            "pickup-dropoff": GoalSpec(
                goal={"load": DELIVERED}, start=start, name="pickup-dropoff", **common
            ),
        }

    # ------------------------------------------------------------------------------ drawing
    def layout(self) -> np.ndarray:
        """``(1, H, W)`` bool map of free cells (trees and water count as blocked)."""
        return self.free[None].copy()

    def draw_extras(self, ax: Axes, floor: int) -> None:
        """Mark trees, water, the sites (P, D, S, A, B) and the region names."""
        for char, color in (("T", "forestgreen"), ("~", "steelblue")):
            rc = self.sites(char)
            ax.scatter(rc[:, 1], rc[:, 0], marker="s", s=14, color=color, zorder=4)
        colors = {"P": "tab:orange", "D": "tab:purple", "S": "black", "A": "tab:red",
                  "B": "tab:red"}
        for char, color in colors.items():
            for r, c in self.sites(char):
                ax.text(c, r, char, color=color, fontsize=8, fontweight="bold", ha="center",
                        va="center", zorder=6)
        for name, (r0, _, c0, c1) in REGIONS.items():
            ax.text((c0 + c1) / 2, r0 + 0.5, name, fontsize=7, ha="center", va="center",
                    color="black", zorder=6,
                    bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.7})

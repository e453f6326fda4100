"""The grid map language: ASCII maps of one or more floors, compiled into sparse dynamics.

Every grid domain of the dissertation (two rooms, Fig. 4.2; the three-floor worlds, Figs. 5.1
and 5.6; Parr's maze, Fig. 6.1) and Sutton, Precup & Singh's four rooms is written in this
language and compiled by :func:`grid_dynamics` into a reward-free
:class:`~adpart.envs.base.Dynamics`.

Map syntax (one character per cell; blank lines are ignored, trailing spaces are stripped and a
common indentation is removed, so maps can sit in indented Python strings):

====  =====================================================================================
char  meaning
====  =====================================================================================
``#`` wall (also: obstacle); a move into it, or off the map, leaves the agent where it is
``.`` free cell
``D`` free cell flagged as a door / hallway (feature ``door`` = 1)
``S`` free cell where episodes start (the default start distribution is uniform over them)
``G`` free cell flagged as goal (feature ``goal`` = 1; the named tasks use it)
``H`` stair: joins the same ``(x, y)`` on the floor above and/or below, which must be ``H`` too
``0``-``9`` free cell holding object site ``k`` (sites must be numbered 0..K-1, each once)
====  =====================================================================================

Floors are separated by a line starting with ``---`` (e.g. ``--- floor 1 ---``); the first
floor needs no header. Every floor has the same width and height. Coordinates: ``x`` is the
column and ``y`` the row counted from the top (row 0 is the top row), ``floor`` counts from 0.

Stairs: ``GoUp`` in a stair cell on floor ``f`` moves to the same ``(x, y)`` on floor ``f + 1``
when that cell is a stair too; ``GoDown`` likewise to ``f - 1``. Both are deterministic and are
*admissible only where they move* (the admissible mask is False elsewhere), so they never act
as a no-op. A stair cell is also an ordinary free cell for the compass moves.

States are factored as cell x arm x object: ``s = (obj * n_arm + arm) * C + cell`` where
``cell`` is the free cell's index in floor-major, row-major order (so a map without objects has
``s = cell``, e.g. four-rooms' hallways are states 25, 51, 62, 88), ``arm`` is 0 = closed,
1 = open (only with ``arm=True``), and ``obj`` is the object's site ``0..K-1`` or ``K`` = held.
"""

from __future__ import annotations

import textwrap
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from adpart.envs.base import Domain, Dynamics
from adpart.errors import MapError

if TYPE_CHECKING:
    from matplotlib.axes import Axes

WALL, FREE, DOOR, START, GOAL, STAIR = "#", ".", "D", "S", "G", "H"
SITES = "0123456789"
KNOWN = WALL + FREE + DOOR + START + GOAL + STAIR + SITES
FLOOR_SEPARATOR = "---"
LEGEND = "# wall, . free, D door, S start, G goal, H stair, 0-9 object site"

#: Compass moves clockwise from north, as (name, dx, dy) with y growing downwards.
MOVES_4 = (("GoNorth", 0, -1), ("GoEast", 1, 0), ("GoSouth", 0, 1), ("GoWest", -1, 0))
MOVES_8 = (
    ("GoNorth", 0, -1), ("GoNorthEast", 1, -1), ("GoEast", 1, 0), ("GoSouthEast", 1, 1),
    ("GoSouth", 0, 1), ("GoSouthWest", -1, 1), ("GoWest", -1, 0), ("GoNorthWest", -1, -1),
)


@dataclass(frozen=True, eq=False)
class GridMap:
    """A parsed map: the character of every cell plus where it came from in the source text.

    Attributes:
        chars: ``(F, H, W)`` array of single characters.
        lines: ``(F, H)`` 1-based source line of every row, for error messages.
    """

    chars: np.ndarray
    lines: np.ndarray

    @classmethod
    def parse(cls, text: str) -> GridMap:
        """Parse map text (see the module docstring); raise :class:`MapError` on bad input."""
        floors: list[list[tuple[int, str]]] = [[]]
        separators = [0]
        for number, raw in enumerate(textwrap.dedent(text).splitlines(), start=1):
            line = raw.rstrip()
            if not line:
                continue
            if line.lstrip().startswith(FLOOR_SEPARATOR):
                floors.append([])
                separators.append(number)
                continue
            floors[-1].append((number, line))
        if len(floors) > 1 and not floors[0]:  # a header before the first floor
            floors.pop(0)
            separators.pop(0)
        if not any(floors):
            raise MapError(f"the map is empty (no rows); write rows of cells using {LEGEND}")
        for f, rows in enumerate(floors):
            if not rows:
                raise MapError(
                    f"floor {f} (after the separator on line {separators[f]}) has no rows; "
                    "remove the separator or draw the floor"
                )
        first_no, first = floors[0][0]
        for rows in floors:
            for number, line in rows:
                bad = next((i for i, ch in enumerate(line) if ch not in KNOWN), None)
                if bad is not None:
                    raise MapError(
                        f"map line {number}, column {bad + 1}: unknown character {line[bad]!r}; "
                        f"use {LEGEND}"
                    )
                if len(line) != len(first):
                    raise MapError(
                        f"map line {number} has {len(line)} cells but line {first_no} has "
                        f"{len(first)}: rows are ragged; every row of every floor must have the "
                        "same width (pad with # walls)"
                    )
        heights = {len(rows) for rows in floors}
        if len(heights) != 1:
            raise MapError(
                f"floors have different heights {[len(r) for r in floors]} (rows per floor); "
                "every floor must have the same number of rows (pad with # walls)"
            )
        chars = np.array([[list(line) for _, line in rows] for rows in floors], dtype="<U1")
        lines = np.array([[n for n, _ in rows] for rows in floors], dtype=np.int64)
        gmap = cls(chars=chars, lines=lines)
        gmap._validate()
        return gmap

    # --- geometry ------------------------------------------------------------------------------

    @property
    def shape(self) -> tuple[int, int, int]:
        """``(floors, height, width)``."""
        return self.chars.shape  # type: ignore[return-value]

    @cached_property
    def free(self) -> np.ndarray:
        """``(F, H, W)`` bool, True for every non-wall cell."""
        return self.chars != WALL

    @cached_property
    def cell_index(self) -> np.ndarray:
        """``(F, H, W)`` int64 cell id of each free cell (floor-major, row-major), -1 on walls."""
        idx = np.full(self.shape, -1, dtype=np.int64)
        idx[self.free] = np.arange(int(self.free.sum()))
        return idx

    @cached_property
    def cell_coords(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(floor, y, x)`` int64 arrays of length C, in cell-id order."""
        f, y, x = np.nonzero(self.free)
        return f.astype(np.int64), y.astype(np.int64), x.astype(np.int64)

    @property
    def n_cells(self) -> int:
        return int(self.free.sum())

    def cells_with(self, char: str) -> np.ndarray:
        """``(C,)`` bool mask of the free cells drawn with ``char``."""
        return self.chars[self.free] == char

    @cached_property
    def object_sites(self) -> np.ndarray:
        """``(K,)`` cell ids of object sites ``0..K-1`` (empty when the map has none)."""
        digits = self.chars[self.free]
        found = np.flatnonzero(np.char.isdigit(digits))
        order = np.argsort(digits[found].astype(np.int64))
        return found[order]

    def where(self, cell: int) -> str:
        """``"line L, column C (x=.., y=.., floor=..)"`` of a cell id, for messages."""
        f, y, x = (int(a[cell]) for a in self.cell_coords)
        return f"line {self.lines[f, y]}, column {x + 1} (x={x}, y={y}, floor={f})"

    def _where_fyx(self, f: int, y: int, x: int) -> str:
        return f"line {self.lines[f, y]}, column {x + 1} (x={x}, y={y}, floor={f})"

    # --- validation ----------------------------------------------------------------------------

    def _validate(self) -> None:
        if not self.free.any():
            raise MapError(
                "the map has no free cell; mark at least one cell with . (or S, G, D, H, 0-9)"
            )
        digits = self.chars[self.free]
        found = digits[np.char.isdigit(digits)].astype(np.int64)
        values, counts = np.unique(found, return_counts=True)
        if values.size and counts.max() > 1:
            twice = int(values[counts > 1][0])
            raise MapError(f"object site {twice} appears {counts.max()} times; number each once")
        if values.size and not np.array_equal(values, np.arange(values.size)):
            missing = sorted(set(range(int(values.max()) + 1)) - set(values.tolist()))
            raise MapError(
                f"object sites must be numbered 0..K-1 without gaps; site {missing[0]} is missing"
            )
        stair = self.chars == STAIR
        above = np.zeros_like(stair)
        below = np.zeros_like(stair)
        above[:-1] = stair[1:]
        below[1:] = stair[:-1]
        lonely = np.argwhere(stair & ~above & ~below)
        if lonely.size:
            f, y, x = (int(v) for v in lonely[0])
            raise MapError(
                f"map {self._where_fyx(f, y, x)}: stair H has no partner; the same (x, y) on the "
                "floor above or below must also be H (or draw this cell as .)"
            )

    @cached_property
    def stair_links(self) -> tuple[np.ndarray, np.ndarray]:
        """``(up, down)``: ``(C,)`` int64 cell reached by GoUp / GoDown, -1 where it cannot move."""
        f, y, x = self.cell_coords
        stair = self.chars == STAIR
        F = self.shape[0]
        up = np.full(self.n_cells, -1, dtype=np.int64)
        down = np.full(self.n_cells, -1, dtype=np.int64)
        here = stair[f, y, x]
        can_up = here & (f + 1 < F)
        can_up[can_up] = stair[f[can_up] + 1, y[can_up], x[can_up]]
        up[can_up] = self.cell_index[f[can_up] + 1, y[can_up], x[can_up]]
        can_down = here & (f > 0)
        can_down[can_down] = stair[f[can_down] - 1, y[can_down], x[can_down]]
        down[can_down] = self.cell_index[f[can_down] - 1, y[can_down], x[can_down]]
        return up, down

    def neighbours(self, moves: tuple[tuple[str, int, int], ...]) -> np.ndarray:
        """``(M, C)`` int64 cell reached by each deterministic move (itself if blocked)."""
        f, y, x = self.cell_coords
        _, H, W = self.shape
        out = np.empty((len(moves), self.n_cells), dtype=np.int64)
        own = np.arange(self.n_cells)
        for m, (_, dx, dy) in enumerate(moves):
            tx, ty = x + dx, y + dy
            inside = (tx >= 0) & (tx < W) & (ty >= 0) & (ty < H)
            target = np.full(self.n_cells, -1, dtype=np.int64)
            target[inside] = self.cell_index[f[inside], ty[inside], tx[inside]]
            out[m] = np.where(target >= 0, target, own)
        return out

    def check_reachable(self, moves: tuple[tuple[str, int, int], ...]) -> None:
        """Raise :class:`MapError` if a goal or object site cannot be reached from a start cell.

        Moves and stairs are symmetric, so reachability is connected components of the cell graph.
        """
        starts = np.flatnonzero(self.cells_with(START))
        if starts.size == 0:
            return
        C = self.n_cells
        nb = self.neighbours(moves)
        up, _ = self.stair_links
        src = np.concatenate([np.tile(np.arange(C), len(moves)), np.flatnonzero(up >= 0)])
        dst = np.concatenate([nb.ravel(), up[up >= 0]])
        graph = sp.coo_array((np.ones(src.size), (src, dst)), shape=(C, C))
        _, comp = csgraph.connected_components(graph, directed=False)
        reached = np.isin(comp, comp[starts])
        for char, what in ((GOAL, "goal G"), (None, "object site")):
            mask = np.char.isdigit(self.chars[self.free]) if char is None else self.cells_with(char)
            bad = np.flatnonzero(mask & ~reached)
            if bad.size:
                raise MapError(
                    f"map {self.where(int(bad[0]))}: {what} cannot be reached from the start S at "
                    f"{self.where(int(starts[0]))}; open a door (. or D) in the wall between them"
                )


@dataclass(frozen=True)
class Slip:
    """How a compass move can go astray.

    ``deterministic``: the intended move always. ``perpendicular``: the intended move w.p. ``p``,
    the two moves at +-90 degrees w.p. ``(1-p)/2`` each (Parr's maze, the three-floor arm world).
    ``uniform``: the intended move w.p. ``p``, each other move w.p. ``(1-p)/(M-1)`` (four rooms:
    p = 2/3, 1/9 each).
    """

    kind: str = "deterministic"
    p: float = 1.0

    def outcome_matrix(self, n_moves: int) -> np.ndarray:
        """``(M, M)`` probability of the actual move (column) given the intended one (row)."""
        if not 0.0 < self.p <= 1.0:
            raise MapError(f"slip probability p = {self.p} is outside (0, 1]")
        eye = np.eye(n_moves)
        if self.kind == "deterministic":
            return eye
        if self.kind == "perpendicular":
            quarter = n_moves // 4
            side = np.roll(eye, quarter, axis=1) + np.roll(eye, -quarter, axis=1)
            return self.p * eye + (1.0 - self.p) / 2.0 * side
        if self.kind == "uniform":
            return self.p * eye + (1.0 - self.p) / (n_moves - 1) * (1.0 - eye)
        raise MapError(
            f"unknown slip model {self.kind!r}; use 'deterministic', 'perpendicular' or 'uniform'"
        )


def grid_dynamics(
    gmap: GridMap,
    *,
    connectivity: int = 4,
    slip: Slip = Slip(),
    default_cost: float = -1.0,
    costs: Mapping[str, float] | None = None,
    arm: bool = False,
) -> Dynamics:
    """Compile a map into reward-free dynamics, vectorised (no Python loop over states).

    Actions, in order: the compass moves (4 or 8), then ``GoUp``/``GoDown`` if the map has more
    than one floor, then ``OpenArm``/``CloseArm`` if ``arm``, then ``Pickup``/``Drop`` if the map
    has object sites. ``Pickup`` takes the object when the agent is on its site (and, with an
    arm, the arm is open); ``Drop`` puts a held object down on the site the agent stands on; both
    are no-ops otherwise. ``OpenArm``/``CloseArm`` set the arm state and always succeed.

    Args:
        gmap: the parsed map.
        connectivity: 4 (compass) or 8 (compass and diagonal) moves; a diagonal move needs only
            its target cell free (no corner-cutting check).
        slip: the noise of the compass moves; stairs and arm actions are deterministic.
        default_cost: reward of every action not named in ``costs``.
        costs: action name -> reward (e.g. -1.2 for diagonals).
        arm: add the arm factor (closed/open) and its actions.
    """
    if connectivity not in (4, 8):
        raise MapError(f"connectivity must be 4 or 8, got {connectivity}")
    moves = MOVES_4 if connectivity == 4 else MOVES_8
    gmap.check_reachable(moves)
    C = gmap.n_cells
    K = gmap.object_sites.size
    n_arm = 2 if arm else 1
    n_obj = K + 1 if K else 1
    S = C * n_arm * n_obj
    state = np.arange(S)
    cell, cfg = state % C, state // C
    arm_s, obj_s = cfg % n_arm, cfg // n_arm

    def compose(c: np.ndarray, a: np.ndarray, o: np.ndarray) -> np.ndarray:
        return (o * n_arm + a) * C + c

    names: list[str] = [m[0] for m in moves]
    blocks: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []  # (action-state rows, cols, p)
    admissible: list[np.ndarray] = []

    nb = gmap.neighbours(moves)
    outcome = slip.outcome_matrix(len(moves))
    for m in range(len(moves)):
        ds = np.flatnonzero(outcome[m] > 0)
        cols = compose(nb[ds][:, cell], arm_s[None, :], obj_s[None, :])
        blocks.append((np.broadcast_to(state, cols.shape), cols,
                       np.broadcast_to(outcome[m, ds, None], cols.shape)))
        admissible.append(np.ones(S, dtype=bool))

    def deterministic(name: str, target: np.ndarray, allowed: np.ndarray | None = None) -> None:
        names.append(name)
        blocks.append((state, target, np.ones(S)))
        admissible.append(np.ones(S, dtype=bool) if allowed is None else allowed)

    if gmap.shape[0] > 1:
        for name, link in zip(("GoUp", "GoDown"), gmap.stair_links, strict=True):
            moves_here = link[cell] >= 0
            target = np.where(moves_here, compose(link[cell], arm_s, obj_s), state)
            deterministic(name, target, moves_here)
    if arm:
        deterministic("OpenArm", compose(cell, np.ones_like(arm_s), obj_s))
        deterministic("CloseArm", compose(cell, np.zeros_like(arm_s), obj_s))
    if K:
        site_of_obj = np.append(gmap.object_sites, -1)  # held (obj = K) sits on no cell
        can_pick = (site_of_obj[obj_s] == cell) & ((arm_s == 1) if arm else True)
        deterministic("Pickup", np.where(can_pick, compose(cell, arm_s, np.full(S, K)), state))
        site_at_cell = np.full(C, -1, dtype=np.int64)
        site_at_cell[gmap.object_sites] = np.arange(K)
        can_drop = (obj_s == K) & (site_at_cell[cell] >= 0)
        deterministic("Drop", np.where(can_drop, compose(cell, arm_s, site_at_cell[cell]), state))

    A = len(names)
    rows = np.concatenate([(a * S + r).ravel() for a, (r, _, _) in enumerate(blocks)])
    cols = np.concatenate([c.ravel() for _, c, _ in blocks])
    vals = np.concatenate([np.asarray(v, dtype=np.float64).ravel() for _, _, v in blocks])
    P = sp.csr_array(sp.coo_array((vals, (rows, cols)), shape=(A * S, S)))
    P.sum_duplicates()

    costs = dict(costs or {})
    unknown = sorted(set(costs) - set(names))
    if unknown:
        raise MapError(f"costs name unknown action(s) {unknown}; actions: {', '.join(names)}")
    action_costs = np.array([costs.get(n, default_cost) for n in names], dtype=np.float64)

    f, y, x = gmap.cell_coords
    chars = gmap.chars[gmap.free]
    features: dict[str, np.ndarray] = {
        "x": x[cell], "y": y[cell], "floor": f[cell],
        "door": (chars == DOOR).astype(np.int64)[cell],
        "stair": (chars == STAIR).astype(np.int64)[cell],
        "goal": (chars == GOAL).astype(np.int64)[cell],
    }
    if arm:
        features["arm"] = arm_s.astype(np.int64)
    if K:
        features["object"] = obj_s.astype(np.int64)
        features["holding"] = (obj_s == K).astype(np.int64)
    starts = gmap.cells_with(START)[cell] & (cfg == 0)
    if starts.any():
        start = starts / starts.sum()
    elif S != C:
        start = (cfg == 0) / C
    else:
        start = None
    return Dynamics(
        P=P,
        action_names=tuple(names),
        action_costs=action_costs,
        features=features,
        admissible=np.stack(admissible, axis=1),
        start=start,
    )


class GridDomain(Domain):
    """A :class:`Domain` drawn in the map language; subclasses set the class attributes below.

    Attributes:
        MAP: the map text (see the module docstring).
        CONNECTIVITY: 4 or 8 moves.
        SLIP: the move noise.
        COSTS: action name -> reward overriding ``DEFAULT_COST``.
        DEFAULT_COST: reward of every other action.
        ARM: whether the state has an arm factor.
    """

    MAP: str = ""
    CONNECTIVITY: int = 4
    SLIP: Slip = Slip()
    COSTS: Mapping[str, float] = {}
    DEFAULT_COST: float = -1.0
    ARM: bool = False

    @cached_property
    def grid(self) -> GridMap:
        return GridMap.parse(self.MAP)

    def _build_dynamics(self) -> Dynamics:
        return grid_dynamics(
            self.grid,
            connectivity=self.CONNECTIVITY,
            slip=self.SLIP,
            default_cost=self.DEFAULT_COST,
            costs=self.COSTS,
            arm=self.ARM,
        )

    def layout(self) -> np.ndarray:
        """``(floors, H, W)`` bool, True on free cells (the renderer draws the rest as walls)."""
        return self.grid.free

    def cell_state(self, x: int, y: int, floor: int = 0) -> int:
        """The state id of cell ``(x, y, floor)`` with the object at site 0 and the arm closed."""
        F, H, W = self.grid.shape
        if not (0 <= floor < F and 0 <= y < H and 0 <= x < W) or not self.grid.free[floor, y, x]:
            raise MapError(f"({x}, {y}) on floor {floor} is not a free cell of {self.name}")
        return int(self.grid.cell_index[floor, y, x])

    def draw_extras(self, ax: Axes, floor: int) -> list[tuple[str, str, str]]:
        """Mark the stairs (up/down arrows) and letter the object-site cells; the start and goal
        letters come from the task drawn (:func:`adpart.envs.render.render_domain`). Returns
        the legend entries ``(symbol, colour, meaning)`` of what it drew on this floor."""
        chars = self.grid.chars[floor]
        F = self.grid.shape[0]
        small = max(chars.shape) <= 40
        meanings = {"↕": "stairs up and down", "↑": "stairs up", "↓": "stairs down"}
        entries: dict[str, tuple[str, str, str]] = {}
        for y, x in np.argwhere(chars == STAIR):
            up = floor + 1 < F and self.grid.chars[floor + 1, y, x] == STAIR
            down = floor > 0 and self.grid.chars[floor - 1, y, x] == STAIR
            mark = {(True, True): "↕", (True, False): "↑", (False, True): "↓"}[(up, down)]
            ax.text(x, y, mark, ha="center", va="center", color="tab:red",
                    fontsize=8 if small else 5, fontweight="bold", gid="stairs")
            entries[mark] = (mark, "tab:red", meanings[mark])
        if not small:
            return list(entries.values())
        for char in SITES:
            for y, x in np.argwhere(chars == char):
                ax.text(x, y, char, ha="center", va="center", color="tab:blue", fontsize=8,
                        fontweight="bold", gid="site")
                entries[char] = (char, "tab:blue", f"object site {char}")
        return list(entries.values())

"""The room structure of Parr's maze, derived from its layout (dissertation ch. 6; Dietterich
2000 sec. 7.3; Parr & Russell 1998).

Chapter 6: "The maze is structured as a series of rooms, each containing a 12x12 block of states
(and various obstacles). Some rooms are parts of hallways because they contain walls on two
opposite sides, and they are open on the other two sides. Other rooms are intersections where
two or more hallways meet." The MAXQ subtasks Go(d, r), ExitInter(d, r) and ExitHall(d, r) need
exactly this structure, so it is computed here from the free cells alone (no hand-written room
table):

* **room** of a cell ``(x, y)``: the 12 x 12 block ``(by, bx) = ((y - o) // 12, (x - o) // 12)``
  with ``o = 1`` (the layout's outer wall); its index is ``by * n_block_cols + bx``. The
  86 x 86 layout is 1 + 7 * 12 + 1 cells wide, so the blocks tile it exactly; a block without
  free cells is no room.
* **door** of room ``r`` in direction ``d``: some free cell of ``r`` whose ``d``-neighbour is a
  free cell of the adjacent block (an opening across the block boundary).
* **hallway**: doors on exactly two opposite sides (N and S, or E and W) - walls on the other
  two; every other room (a corner, a T, a crossing, a dead end) is an **intersection**.
* **corridor** ``Go(d, r)``: from room ``r`` step through the ``d``-door into the next room and
  keep going while that room is a hallway along ``d``; the first intersection reached is the
  target. ``Go(d, r)`` exists when ``r`` has a ``d``-door and is an intersection or a hallway
  along ``d``.
* **hall** of a hallway room: the maximal run of hallway rooms along its axis that contains it;
  its exits are the intersections at its two ends.

On the shipped reconstruction (BaRL_Envs) this gives 30 rooms in a 7 x 7 block grid - 20
hallways and 10 intersections (eight corners, among them the start and goal rooms, and two
crossings) - and 16 rooms on the mini maze; ``tests/learning/test_maxq_parr_rooms.py`` checks
it against the layout text.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from adpart.errors import MapError

__all__ = ["DIRECTIONS", "OFFSET", "OPPOSITE", "PERPENDICULAR", "RoomMap"]

#: Compass directions in the order of the maze's actions (GoNorth, GoEast, GoSouth, GoWest).
DIRECTIONS = ("N", "E", "S", "W")
#: ``(dx, dy)`` of one step; north is ``y - 1`` (row 0 is the top of the layout).
OFFSET = {"N": (0, -1), "E": (1, 0), "S": (0, 1), "W": (-1, 0)}
OPPOSITE = {"N": "S", "S": "N", "E": "W", "W": "E"}
PERPENDICULAR = {"N": ("E", "W"), "S": ("E", "W"), "E": ("N", "S"), "W": ("N", "S")}


@dataclass(frozen=True, eq=False)
class RoomMap:
    """Rooms, doors, hallways and corridors of a block-structured maze.

    Attributes:
        room_size: side of a room block (12).
        origin: coordinate of the first room cell (1: inside the outer wall).
        n_cols: number of block columns.
        x, y: ``(n,)`` coordinates of the free cells (one per maze state).
        room: ``(n,)`` room index of each cell.
        rooms: sorted room indices that contain free cells.
        doors: room -> set of directions with a door.
        wall: direction -> ``(n,)`` bool, the cell's neighbour in that direction is not free.
    """

    room_size: int
    origin: int
    n_cols: int
    x: np.ndarray
    y: np.ndarray
    room: np.ndarray
    rooms: tuple[int, ...]
    doors: Mapping[int, frozenset[str]]
    wall: Mapping[str, np.ndarray]

    @classmethod
    def from_cells(cls, x: np.ndarray, y: np.ndarray, room_size: int = 12,
                   origin: int = 1) -> RoomMap:
        """Derive the structure from the free cells' coordinates (vectorised)."""
        x = np.asarray(x, dtype=np.int64)
        y = np.asarray(y, dtype=np.int64)
        if x.shape != y.shape or x.ndim != 1 or x.size == 0:
            raise MapError("RoomMap needs two equal-length 1-D coordinate arrays of free cells")
        if x.min() < origin or y.min() < origin:
            raise MapError(f"free cells lie left of / above the room origin {origin}; the maze "
                           "must be surrounded by its outer wall")
        width = int(x.max()) + 2
        free = np.zeros((int(y.max()) + 2, width), dtype=bool)
        free[y, x] = True
        bx, by = (x - origin) // room_size, (y - origin) // room_size
        n_cols = int(bx.max()) + 1
        room = by * n_cols + bx
        doors: dict[int, set[str]] = {int(r): set() for r in np.unique(room)}
        wall: dict[str, np.ndarray] = {}
        for d in DIRECTIONS:
            dx, dy = OFFSET[d]
            nx, ny = x + dx, y + dy
            inside = (nx >= 0) & (ny >= 0) & (nx < free.shape[1]) & (ny < free.shape[0])
            ok = np.zeros(x.size, dtype=bool)
            ok[inside] = free[ny[inside], nx[inside]]
            wall[d] = ~ok
            n_room = ((ny - origin) // room_size) * n_cols + (nx - origin) // room_size
            crossing = ok & (n_room != room)
            for r in np.unique(room[crossing]):
                doors[int(r)].add(d)
        return cls(room_size=room_size, origin=origin, n_cols=n_cols, x=x, y=y, room=room,
                   rooms=tuple(sorted(doors)),
                   doors={r: frozenset(v) for r, v in doors.items()}, wall=wall)

    @classmethod
    def from_layout(cls, text: str, room_size: int = 12, origin: int = 1) -> RoomMap:
        """From map text (``#`` = wall, anything else free), as in ``adpart/envs/data``."""
        lines = [ln for ln in text.splitlines() if ln.strip()]
        ys, xs = zip(*[(i, j) for i, ln in enumerate(lines) for j, ch in enumerate(ln)
                       if ch != "#"], strict=True)
        return cls.from_cells(np.array(xs), np.array(ys), room_size, origin)

    # ------------------------------------------------------------------------ structure
    def neighbour(self, r: int, d: str) -> int | None:
        """The room through ``r``'s ``d``-door, or None without a door."""
        if d not in self.doors.get(r, ()):
            return None
        dx, dy = OFFSET[d]
        return r + dy * self.n_cols + dx

    def is_hallway(self, r: int) -> bool:
        """Doors on exactly two opposite sides."""
        return self.doors[r] in (frozenset("NS"), frozenset("EW"))

    def along(self, r: int, d: str) -> bool:
        """``r`` is a hallway whose open sides are ``d`` and its opposite."""
        return self.is_hallway(r) and d in self.doors[r]

    def corridor(self, d: str, r: int) -> tuple[tuple[int, ...], int] | None:
        """``(rooms Go(d, r) may run in, target intersection)`` or None if Go(d, r) is
        undefined (no ``d``-door, a hallway across ``d``, or a hallway run that dead-ends)."""
        if self.is_hallway(r) and not self.along(r, d):
            return None
        path = [r]
        nxt = self.neighbour(r, d)
        while nxt is not None and nxt in self.doors and self.along(nxt, d):
            path.append(nxt)
            nxt = self.neighbour(nxt, d)
        if nxt is None or nxt not in self.doors:
            return None
        return tuple(path), nxt

    def hall(self, r: int) -> tuple[int, ...]:
        """The maximal run of hallway rooms along ``r``'s axis containing hallway ``r``."""
        axis = "NS" if "N" in self.doors[r] else "EW"
        out = {r}
        for d in axis:
            nxt = self.neighbour(r, d)
            while nxt is not None and nxt in self.doors and self.along(nxt, d):
                out.add(nxt)
                nxt = self.neighbour(nxt, d)
        return tuple(sorted(out))

    def hall_exit(self, r: int, d: str) -> int | None:
        """The intersection at the ``d`` end of ``r``'s hall (None if the hall is not along
        ``d`` or ends without one)."""
        if not self.along(r, d):
            return None
        found = self.corridor(d, r)
        return None if found is None else found[1]

    def intersections(self) -> tuple[int, ...]:
        return tuple(r for r in self.rooms if not self.is_hallway(r))

    def hallways(self) -> tuple[int, ...]:
        return tuple(r for r in self.rooms if self.is_hallway(r))

    def axis_coordinate(self, d: str) -> np.ndarray:
        """``(n,)`` the cell coordinate that moves along ``d`` (``y`` for N/S, ``x`` for E/W)."""
        return self.y if d in "NS" else self.x

"""Room structure of Parr's maze derived from the shipped layouts (RoomMap), checked against
the layout text read independently here (block scan of the character grid)."""

from __future__ import annotations

from importlib import resources

import numpy as np
import pytest

from adpart.envs.domains.parr_maze import LAYOUT, MINI_LAYOUT, ParrMaze
from adpart.errors import MapError
from adpart.learning.maxq.parr_rooms import RoomMap


def grid(filename: str) -> np.ndarray:
    text = (resources.files("adpart") / "envs" / "data" / filename).read_text()
    return np.array([list("".join(ln.split())) for ln in text.splitlines() if ln.strip()])


def scan_doors(g: np.ndarray) -> dict[tuple[int, int], set[str]]:
    """Independent oracle: for every pair of adjacent 12x12 blocks, is there a free cell on
    each side of their shared boundary line?"""
    free = g != "#"
    n = (g.shape[0] - 2) // 12
    out: dict[tuple[int, int], set[str]] = {}
    for by in range(n):
        for bx in range(n):
            ys, xs = 1 + 12 * by, 1 + 12 * bx
            if not free[ys:ys + 12, xs:xs + 12].any():
                continue
            doors = set()
            if by > 0 and (free[ys, xs:xs + 12] & free[ys - 1, xs:xs + 12]).any():
                doors.add("N")
            if by < n - 1 and (free[ys + 11, xs:xs + 12] & free[ys + 12, xs:xs + 12]).any():
                doors.add("S")
            if bx > 0 and (free[ys:ys + 12, xs] & free[ys:ys + 12, xs - 1]).any():
                doors.add("W")
            if bx < n - 1 and (free[ys:ys + 12, xs + 11] & free[ys:ys + 12, xs + 12]).any():
                doors.add("E")
            out[(by, bx)] = doors
    return out


@pytest.mark.parametrize("filename,n_rooms", [(LAYOUT, 30), (MINI_LAYOUT, 16)])
def test_rooms_and_doors_match_a_block_scan_of_the_layout(filename, n_rooms):
    g = grid(filename)
    assert g.shape[0] == g.shape[1] == 2 + 12 * ((g.shape[0] - 2) // 12)
    rm = RoomMap.from_layout("\n".join("".join(r) for r in g))
    oracle = scan_doors(g)
    assert len(rm.rooms) == len(oracle) == n_rooms
    for (by, bx), doors in oracle.items():
        assert rm.doors[by * rm.n_cols + bx] == frozenset(doors)
    # classification: straight rooms are hallways, the rest intersections
    for r in rm.rooms:
        assert rm.is_hallway(r) == (rm.doors[r] in ({"N", "S"}, {"E", "W"}))


def test_full_maze_structure():
    rm = RoomMap.from_layout("\n".join("".join(r) for r in grid(LAYOUT)))
    assert len(rm.hallways()) == 20 and len(rm.intersections()) == 10
    assert rm.doors[0] == {"E", "S"}                      # the start room is a corner
    assert rm.doors[2 * 7 + 4] == set("NESW")             # a crossing
    assert rm.corridor("E", 0) == ((0, 1, 2, 3), 4)      # along the top hallway
    assert rm.corridor("S", 0) == ((0, 7, 14, 21), 28)
    assert rm.corridor("N", 0) is None                    # no door north
    assert rm.corridor("N", 1) is None                    # a hallway across N
    assert rm.hall(2) == (1, 2, 3) and rm.hall_exit(2, "W") == 0
    assert rm.neighbour(48, "N") == 41                    # goal room (6, 6) opens north


def test_room_map_agrees_with_the_domain_states():
    mdp = ParrMaze(mini=True).mdp()
    rm = RoomMap.from_cells(mdp.features["x"], mdp.features["y"])
    text = RoomMap.from_layout("\n".join("".join(r) for r in grid(MINI_LAYOUT)))
    assert rm.doors == text.doors
    x, y = mdp.features["x"], mdp.features["y"]
    np.testing.assert_array_equal(rm.room, ((y - 1) // 12) * rm.n_cols + (x - 1) // 12)
    # a wall flag is set exactly when the neighbour is not one of the maze's cells
    cells = set(zip(x.tolist(), y.tolist(), strict=True))
    expect = np.array([(xx, yy - 1) not in cells for xx, yy in zip(x, y, strict=True)])
    np.testing.assert_array_equal(rm.wall["N"], expect)


def test_bad_cells():
    with pytest.raises(MapError, match="equal-length"):
        RoomMap.from_cells(np.array([1, 2]), np.array([1]))
    with pytest.raises(MapError, match="outer wall"):
        RoomMap.from_cells(np.array([0]), np.array([3]))

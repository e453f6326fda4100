"""Models shared by the benchmarks: the rooms grid the issue's peers measure on.

``rooms_grid_mdp(n)`` is a grid of ``k x k`` square rooms (``room`` x ``room`` cells, ``k =
round(sqrt(n) / room)``) separated by one-cell walls with one doorway in the middle of every wall
segment; states are the free cells (about ``n``). Four moves; the intended move succeeds with
probability 0.8 and slips to each
perpendicular direction with 0.1; a move into a wall or off the grid stays put. Every step costs
-1; the south-east free cell is the single goal (terminal, absorbing); episodes start uniformly
on the other cells. Value therefore spreads from one cell, one cell per backup -- the hard case
for value iteration that the solver benchmark is about.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import shortest_path

from adpart.mdp.generate import GRID_ACTION_NAMES, GRID_MOVES, _canonical_csr
from adpart.mdp.model import FiniteMDP


def rooms_grid_mdp(
    n_states: int, *, room: int = 10, slip: float = 0.2, gamma: float = 0.95
) -> FiniteMDP:
    """The rooms grid described in the module docstring, with about ``n_states`` free cells."""
    rooms = max(1, round(math.sqrt(n_states) / room))  # rooms per side: whole rooms only
    side = rooms * (room + 1) - 1
    r, c = np.divmod(np.arange(side * side, dtype=np.int64), side)
    wall_r, wall_c = (r % (room + 1)) == room, (c % (room + 1)) == room
    door_r = (c % (room + 1)) == room // 2  # doorway through a horizontal wall
    door_c = (r % (room + 1)) == room // 2
    wall = (wall_r & ~door_r) | (wall_c & ~door_c)
    wall |= wall_r & wall_c
    free = ~wall
    cell_id = np.full(side * side, -1, dtype=np.int64)
    cells = np.flatnonzero(free)
    n = cells.size
    cell_id[cells] = np.arange(n)
    row, col = r[cells], c[cells]

    def step(move: int) -> np.ndarray:
        dr, dc = GRID_MOVES[move]
        rr, cc = row + dr, col + dc
        inside = (rr >= 0) & (rr < side) & (cc >= 0) & (cc < side)
        target = np.where(inside, cell_id[np.clip(rr, 0, side - 1) * side
                                          + np.clip(cc, 0, side - 1)], -1)
        return np.where(target >= 0, target, np.arange(n))

    succ = [step(m) for m in range(4)]
    cols = np.empty((4, n, 3), dtype=np.int64)
    for a in range(4):  # the four moves only; every state at once
        cols[a, :, 0], cols[a, :, 1], cols[a, :, 2] = succ[a], succ[(a + 1) % 4], succ[(a + 3) % 4]
    probs = np.broadcast_to(np.array([1.0 - slip, slip / 2, slip / 2]), (4 * n, 3))
    P = _canonical_csr(cols.reshape(4 * n, 3), np.ascontiguousarray(probs), n)
    terminal = np.zeros(n, dtype=bool)
    terminal[n - 1] = True
    initial = np.where(terminal, 0.0, 1.0 / (n - 1))
    R = np.full((n, 4), -1.0)
    return FiniteMDP(P, R, gamma, terminal=terminal, initial=initial,
                     features={"row": row, "col": col}, action_names=GRID_ACTION_NAMES,
                     name=f"rooms-grid-{n}")


def distance_policy(mdp: FiniteMDP) -> np.ndarray:
    """The policy greedy on the breadth-first distance to the nearest terminal state: in each
    state the action whose expected next distance is least (ties to the lowest action). Optimal
    for a deterministic grid with step cost -1; computed in one BFS, where value iteration at
    10^6 states with gamma near 1 would dominate a benchmark."""
    S, A = mdp.n_states, mdp.n_actions
    P = mdp.P.tocoo()
    graph = sp.csr_array((np.ones(P.nnz), (P.row % S, P.col)), shape=(S, S))
    goals = np.flatnonzero(mdp.terminal)
    distance = shortest_path(graph.T, unweighted=True, indices=goals, directed=True)
    expected = (mdp.P @ np.atleast_2d(distance).min(axis=0)).reshape(A, S)
    return expected.argmin(axis=0).astype(np.int64)

"""The section 4.2.2 setting: a walled grid with four "repeat the move until a wall" options."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from adpart.mdp.model import SMDPModel

MOVES = {"up": (-1, 0), "right": (0, 1), "down": (1, 0), "left": (0, -1)}


def slide_options(rows: list[str], gamma: float = 0.95, step_reward: float = -1.0,
                  goal_reward: float = 20.0):
    """SMDPModel of the four sliding options on a map ('#' wall cell, 'G' goal, '.' free).

    Option ``d`` moves in direction ``d`` until the next cell is a wall/border, or until it arrives
    at the goal (terminal: the episode ends on arrival). It takes ``k`` moves, earns -1 per move
    (+20 for the move into the goal instead) discounted, and F puts ``gamma^k`` on the landing cell.
    Against its wall (``k = 0``) the option bumps once: no move, reward 0, ``F = gamma`` on the
    cell itself. Every option is admissible everywhere; the goal is terminal (zero rows).

    Returns ``(model, cells, termination, goal)`` with ``cells`` the (row, col) of each state and
    ``termination`` (S, 4) the beta = 1 states of each option (cells against that wall, the goal).
    """
    cells = [(r, c) for r, line in enumerate(rows) for c, ch in enumerate(line) if ch != "#"]
    index = {rc: i for i, rc in enumerate(cells)}
    goal = index[next((r, c) for r, line in enumerate(rows) for c, ch in enumerate(line)
                      if ch == "G")]
    S = len(cells)
    R = np.zeros((S, 4))
    adm = np.zeros((S, 4), dtype=bool)
    term = np.zeros((S, 4), dtype=bool)
    F_rows, F_cols, F_vals = [], [], []
    for o, (dr, dc) in enumerate(MOVES.values()):
        for s, (r, c) in enumerate(cells):
            if s == goal:
                adm[s, o] = True
                term[s, o] = True
                continue
            k, rr, cc, ret = 0, r, c, 0.0
            while (rr + dr, cc + dc) in index:
                rr, cc = rr + dr, cc + dc
                ret += gamma**k * (goal_reward if index[(rr, cc)] == goal else step_reward)
                k += 1
                if index[(rr, cc)] == goal:
                    break
            adm[s, o] = True
            if k == 0:  # against the wall: one bump, no move, no reward, terminate
                term[s, o] = True
                k, ret = 1, 0.0
            R[s, o] = ret
            F_rows.append(o * S + s)
            F_cols.append(index[(rr, cc)])
            F_vals.append(gamma**k)
    F = sp.csr_array((F_vals, (F_rows, F_cols)), shape=(4 * S, S))
    return SMDPModel(R=R, F=F, admissible=adm), cells, term, goal


def as_grid(rows: list[str], cells: list[tuple[int, int]], labels: np.ndarray) -> list[str]:
    """Render block labels on the map, one character per cell ('#' for walls)."""
    out = [list(line) for line in rows]
    alphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789"
    for (r, c), b in zip(cells, labels, strict=True):
        out[r][c] = alphabet[b]
    return ["".join(line) for line in out]

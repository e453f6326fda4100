"""Small MDPs for the learning tests: a deterministic corridor and a slippery grid."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from adpart.mdp.model import FiniteMDP


def corridor(n: int = 6, gamma: float = 0.9) -> FiniteMDP:
    """States 0..n-1 in a row, actions left/right (deterministic, walls at both ends).

    Arriving at state n-1 (terminal) pays +1; every other step pays 0. Episodes start at 0.
    """
    S = n
    P = np.zeros((S, 2, S))
    R = np.zeros((S, 2))
    for s in range(S):
        P[s, 0, max(s - 1, 0)] = 1.0
        P[s, 1, min(s + 1, S - 1)] = 1.0
    R[S - 2, 1] = 1.0
    terminal = np.zeros(S, dtype=bool)
    terminal[-1] = True
    initial = np.zeros(S)
    initial[0] = 1.0
    return FiniteMDP.from_dense(P, R, gamma, terminal=terminal, initial=initial,
                                action_names=("left", "right"), name="corridor")


def slippery_grid(side: int = 4, slip: float = 0.2, gamma: float = 0.95) -> FiniteMDP:
    """A side x side grid, moves N/E/S/W succeed w.p. 1 - slip and slip to each side w.p. slip/2.

    Every step costs -1; the bottom-right cell is terminal; episodes start top-left.
    """
    S = side * side
    moves = ((-1, 0), (0, 1), (1, 0), (0, -1))
    P = np.zeros((S, 4, S))
    for s in range(S):
        r, c = divmod(s, side)
        for a in range(4):
            for m, p in ((a, 1 - slip), ((a + 1) % 4, slip / 2), ((a + 3) % 4, slip / 2)):
                rr, cc = r + moves[m][0], c + moves[m][1]
                t = rr * side + cc if 0 <= rr < side and 0 <= cc < side else s
                P[s, a, t] += p
    R = np.full((S, 4), -1.0)
    terminal = np.zeros(S, dtype=bool)
    terminal[-1] = True
    initial = np.zeros(S)
    initial[0] = 1.0
    per_action = [sp.csr_array(P[:, a, :]) for a in range(4)]
    return FiniteMDP(per_action, R, gamma, terminal=terminal, initial=initial, name="slippery")


@pytest.fixture
def corridor_mdp() -> FiniteMDP:
    return corridor()


@pytest.fixture
def grid_mdp() -> FiniteMDP:
    return slippery_grid()


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(1234)

"""Fickle Taxi (Dietterich 2000, sec. 7.1): the destination change is *in the model*.

Oracles: a hand-computed transition row, and a Monte Carlo simulator of the process as the paper
describes it (written here directly on (row, col, passenger, destination, moved-yet) tuples).
"""

from __future__ import annotations

import numpy as np
import pytest

from adpart.envs.domains.taxi import (
    EAST,
    IN_TAXI,
    LANDMARKS,
    MOVES,
    N_STATES,
    N_STATES_FICKLE,
    NORTH,
    PERPENDICULAR,
    PICKUP,
    SOUTH,
    WEST,
    FickleTaxi,
    Taxi,
    _walls,
    encode,
)
from adpart.envs.registry import load_class
from adpart.errors import TaskError


@pytest.fixture(scope="module")
def mdp():
    return Taxi(fickle=True).mdp()


def pending(landmark: int, dest: int) -> int:
    return N_STATES + 4 * landmark + dest


def test_state_count_and_rows_stochastic(mdp):
    assert mdp.n_states == N_STATES_FICKLE == 516
    sums = np.asarray(mdp.P.sum(axis=1)).ravel()
    np.testing.assert_allclose(sums, 1.0, atol=1e-12)
    assert mdp.initial[N_STATES:].sum() == 0.0
    assert mdp.terminal.sum() == 4
    assert mdp.features["pending"][N_STATES:].all() and not mdp.features["pending"][:N_STATES].any()


def test_hand_computed_row_of_a_pending_state(mdp):
    # passenger just picked up at R = (0, 0), destination G; action South.
    # South w.p. 0.8 -> (1, 0); East w.p. 0.1 -> (0, 1); West w.p. 0.1 blocked -> stays pending.
    # A move that leaves the cell keeps the destination w.p. 0.7, else 0.1 to each other one.
    s = pending(0, 1)
    expected = {s: 0.1, encode(1, 0, IN_TAXI, 1): 0.8 * 0.7, encode(0, 1, IN_TAXI, 1): 0.1 * 0.7}
    for d in (0, 2, 3):
        expected[encode(1, 0, IN_TAXI, d)] = 0.8 * 0.1
        expected[encode(0, 1, IN_TAXI, d)] = 0.1 * 0.1
    cols, probs = mdp.transition_row(s, SOUTH)
    assert dict(zip(cols.tolist(), probs.tolist(), strict=True)) == pytest.approx(expected)


def test_change_happens_only_when_leaving_the_source_once(mdp):
    S = mdp.n_states
    P = mdp.P.toarray().reshape(6, S, S)
    dest = mdp.features["destination"]
    # outside the pending states no transition ever changes the destination
    base = np.arange(N_STATES)
    for a in range(6):
        moved_to = np.nonzero(P[a][base])
        changed = dest[moved_to[1]] != dest[base][moved_to[0]]
        assert not changed.any()
    # a legal pickup from a start state enters the pending state of (source, destination)
    s = encode(0, 0, 0, 3)
    np.testing.assert_array_equal(np.flatnonzero(P[PICKUP][s]), [pending(0, 3)])
    assert mdp.R[s, PICKUP] == -1.0 and mdp.R[pending(0, 3), PICKUP] == -10.0
    # the destination-change mass 0.3 sits exactly on the cell-leaving outcomes
    for landmark in range(4):
        p = pending(landmark, (landmark + 1) % 4)
        for a in (SOUTH, NORTH, EAST, WEST):
            row = P[a][p]
            d_next = dest[np.arange(S)]
            leave = row.copy()
            leave[p] = 0.0
            changed = leave[d_next != dest[p]].sum()
            assert changed == pytest.approx(0.3 * leave.sum())


def simulate(rng, row, col, passenger, dest, fresh, action):
    """One step of fickle Taxi as described in the paper (moves only; 0.8 / 0.1 / 0.1)."""
    east_open, west_open = _walls()
    u = rng.random()
    move = action if u < 0.8 else PERPENDICULAR[action][0 if u < 0.9 else 1]
    dr, dc = MOVES[move]
    if move == EAST:
        ok = east_open[row, col]
    elif move == WEST:
        ok = west_open[row, col]
    else:
        ok = 0 <= row + dr < 5
    r2, c2 = (row + dr, col + dc) if ok else (row, col)
    if fresh and (r2, c2) != (row, col):
        fresh = False
        if rng.random() < 0.3:
            dest = int(rng.choice([d for d in range(4) if d != dest]))
    if fresh:
        return N_STATES + 4 * LANDMARKS.index((row, col)) + dest
    return int(encode(r2, c2, passenger, dest))


@pytest.mark.parametrize(("landmark", "dest", "action"),
                         [(0, 1, SOUTH), (3, 2, NORTH), (1, 2, WEST), (2, 0, EAST)])
def test_monte_carlo_simulation_agrees_with_model(mdp, landmark, dest, action):
    rng = np.random.default_rng(7)
    n = 20_000
    row, col = LANDMARKS[landmark]
    counts = np.bincount(
        [simulate(rng, row, col, IN_TAXI, dest, True, action) for _ in range(n)],
        minlength=mdp.n_states,
    ) / n
    cols, probs = mdp.transition_row(pending(landmark, dest), action)
    model = np.zeros(mdp.n_states)
    model[cols] = probs
    sd = np.sqrt(model * (1 - model) / n) + 1e-12
    assert np.all(np.abs(counts - model) <= 5 * sd + 1e-9)
    assert counts[model == 0].sum() == 0


def test_registered_class_and_bad_combinations():
    assert FickleTaxi().mdp().n_states == 516
    assert load_class("adpart.envs.domains.taxi:FickleTaxi")().name == "taxi-fickle"
    assert Taxi().mdp().n_states == 500 and "pending" not in Taxi().dynamics().features
    with pytest.raises(TaskError, match="putdown='dietterich'"):
        Taxi(fickle=True, putdown="gymnasium")
    with pytest.raises(TaskError, match="noisy moves"):
        Taxi(fickle=True, slip=False)
    with pytest.raises(TaskError, match="fickle_probability"):
        Taxi(fickle=True, fickle_probability=1.5)

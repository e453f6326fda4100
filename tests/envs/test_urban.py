"""Urban: state count, dynamics semantics, V* against an independent BFS shortest-path oracle."""

from __future__ import annotations

import time
from collections import deque

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order

from adpart.envs.domains.urban import (
    ACTION_NAMES,
    CARRYING,
    DELIVERED,
    DROP_OFF,
    EMPTY,
    MAP,
    PICK_UP,
    TURN_LEFT,
    TURN_RIGHT,
    Urban,
    parse_map,
)
from adpart.envs.registry import get_domain
from adpart.errors import MapError, TaskError
from adpart.mdp.solvers import solve

TASKS = ("navigate", "navigate-pickup", "navigate-2", "navigate-dropoff", "pickup-dropoff")


@pytest.fixture(scope="module")
def urban():
    return Urban()


def test_exact_state_count(urban):
    n_free = sum(ch in ".PDSAB" for row in MAP for ch in row)
    assert n_free == 1667
    assert urban.n_states == n_free * 4 * 3 == 20_004
    assert urban.dynamics().action_names == ACTION_NAMES


def test_mdp_constructs_fast_and_rows_are_stochastic():
    t0 = time.perf_counter()
    mdp = Urban().mdp("navigate")  # FiniteMDP validates that every row sums to 1
    elapsed = time.perf_counter() - t0
    assert elapsed < 1.0
    assert mdp.n_states == 20_004 and mdp.n_actions == 6
    np.testing.assert_allclose(mdp.P.sum(axis=1), 1.0)


# ---------------------------------------------------------------- independent pose oracle
STEP = {0: (-1, 0), 1: (0, 1), 2: (1, 0), 3: (0, -1)}


def oracle_step(pose, action):
    """One action on ``(row, col, heading, load)``, straight from the map text."""
    r, c, h, load = pose
    here = MAP[r][c]
    if action in (0, 1):
        dr, dc = STEP[h if action == 0 else (h + 2) % 4]
        if MAP[r + dr][c + dc] in ".PDSAB":
            return (r + dr, c + dc, h, load)
        return pose
    if action == 2:
        return (r, c, (h + 3) % 4, load)
    if action == 3:
        return (r, c, (h + 1) % 4, load)
    if action == 4 and here == "P" and load != 1:
        return (r, c, h, 1)
    if action == 5 and here == "D" and load == 1:
        return (r, c, h, 2)
    return pose


def test_transitions_equal_the_pose_oracle(urban):
    succ = urban.successors()
    f = urban.dynamics().features
    S = urban.n_states
    rng = np.random.default_rng(0)
    for s in rng.choice(S, size=400, replace=False):
        pose = (int(f["y"][s]), int(f["x"][s]), int(f["heading"][s]), int(f["load"][s]))
        for a in range(6):
            s2 = succ[a, s]
            got = (int(f["y"][s2]), int(f["x"][s2]), int(f["heading"][s2]), int(f["load"][s2]))
            assert got == oracle_step(pose, a), (pose, ACTION_NAMES[a])


def test_navigate_values_equal_bfs_shortest_paths(urban):
    mdp = urban.mdp("navigate")
    f = mdp.features
    goal_r, goal_c = next((r, c) for r, row in enumerate(MAP) for c, ch in enumerate(row)
                          if ch == "A")
    # BFS over poses (row, col, heading) backwards from the goal cell, on oracle_step's graph
    poses = [(r, c, h) for r, row in enumerate(MAP) for c, ch in enumerate(row) if ch in ".PDSAB"
             for h in range(4)]
    preds: dict[tuple[int, int, int], list[tuple[int, int, int]]] = {p: [] for p in poses}
    for p in poses:
        for a in range(4):
            q = oracle_step((*p, 0), a)[:3]
            preds[q].append(p)
    dist = {p: 0 for p in poses if p[:2] == (goal_r, goal_c)}
    queue = deque(dist)
    while queue:
        q = queue.popleft()
        for p in preds[q]:
            if p not in dist:
                dist[p] = dist[q] + 1
                queue.append(p)
    assert len(dist) == len(poses)  # the city is connected
    g = mdp.gamma
    d = np.array([dist[(int(r), int(c), int(h))] for r, c, h in zip(f["y"], f["x"], f["heading"],
                                                                  strict=True)], dtype=float)
    # d costs of -1, plus 100 on the arriving step; goal states are terminal (value 0)
    expected = np.where(d == 0, 0.0, -(1 - g**d) / (1 - g) + 100.0 * g ** (d - 1))
    V = solve(mdp, epsilon=1e-9).V
    np.testing.assert_allclose(np.where(mdp.terminal, 0.0, V), expected, atol=1e-7)


@pytest.mark.parametrize("name", TASKS)
def test_every_goal_is_reachable_from_every_start(urban, name):
    mdp = urban.mdp(name)
    S, A = mdp.n_states, mdp.n_actions
    # reverse graph: s' -> s for every transition s -(a)-> s'
    rows = np.repeat(np.arange(A * S) % S, np.diff(mdp.P.indptr))
    graph = sp.csr_array((np.ones(rows.size), (mdp.P.indices, rows)), shape=(S + 1, S + 1))
    hub = sp.csr_array((np.ones(int(mdp.terminal.sum())), (np.full(int(mdp.terminal.sum()), S),
                                                           np.flatnonzero(mdp.terminal))),
                       shape=(S + 1, S + 1))
    reaches_goal = np.zeros(S + 1, dtype=bool)
    reaches_goal[breadth_first_order(graph + hub, S, directed=True, return_predecessors=False)] = 1
    starts = np.flatnonzero(mdp.initial > 0)
    assert starts.size == 4 and not mdp.terminal[starts].any()
    assert reaches_goal[starts].all()
    V = solve(mdp, epsilon=1e-6).V
    assert (V[starts] > -1 / (1 - mdp.gamma) + 1).all()  # the goal's reward is felt at the start


def test_turning_four_times_returns_to_the_same_pose(urban):
    dyn = urban.dynamics()
    S = dyn.n_states
    eye = sp.eye_array(S, format="csr")
    left = dyn.P[TURN_LEFT * S:(TURN_LEFT + 1) * S]
    right = dyn.P[TURN_RIGHT * S:(TURN_RIGHT + 1) * S]
    for T in (left, right):
        assert (T @ T @ T @ T != eye).nnz == 0
        assert not T.diagonal().any()  # one turn changes every state's heading
        assert ((T @ T) != eye).nnz == 2 * S  # two turns are not the identity either
    assert ((left @ right) != eye).nnz == 0


def test_pickup_and_dropoff_semantics(urban):
    succ = urban.successors()
    f = urban.dynamics().features
    S = urban.n_states
    s = np.arange(S)
    char = np.array([MAP[r][c] for r, c in zip(f["y"], f["x"], strict=True)])
    load = f["load"]
    picked, dropped = succ[PICK_UP], succ[DROP_OFF]
    works = (char == "P") & (load != CARRYING)
    np.testing.assert_array_equal(f["load"][picked[works]], CARRYING)
    np.testing.assert_array_equal(picked[~works], s[~works])  # no effect elsewhere
    for key in ("x", "y", "heading"):
        np.testing.assert_array_equal(f[key][picked], f[key])
    works = (char == "D") & (load == CARRYING)
    np.testing.assert_array_equal(f["load"][dropped[works]], DELIVERED)
    np.testing.assert_array_equal(dropped[~works], s[~works])
    assert (char == "P").sum() == 3 * 4 * 3 and (char == "D").sum() == 3 * 4 * 3
    mdp = urban.mdp("navigate-pickup")
    np.testing.assert_array_equal(mdp.R[~mdp.terminal & (load == EMPTY) & (char != "P")], -1.0)
    at_p = np.flatnonzero((char == "P") & (load == EMPTY))
    np.testing.assert_array_equal(mdp.R[at_p, PICK_UP], 99.0)


def test_tasks_goals_and_regions(urban):
    assert tuple(urban.tasks()) == TASKS
    f = urban.dynamics().features
    nav2 = urban.mdp("navigate-2")
    nav = urban.mdp("navigate")
    region_of = {int(r) for r in f["region"][nav.terminal]}
    region2 = {int(r) for r in f["region"][nav2.terminal]}
    assert region_of == {1} and region2 == {2}  # A downtown, B in the park
    assert set(np.unique(f["region"]).tolist()) == {0, 1, 2, 3, 4}
    drop = urban.mdp("navigate-dropoff")
    assert (f["load"][drop.initial > 0] == CARRYING).all()
    assert (f["load"][drop.terminal] == DELIVERED).all()
    assert urban.layout().shape == (1, len(MAP), len(MAP[0]))
    assert int(urban.layout().sum()) == 1667


def test_registry_custom_goal_and_errors():
    dom = get_domain("urban")
    assert isinstance(dom, Urban)
    task = dom.task("goal:x=29,y=21,heading=0")
    assert task.terminal.sum() == 3
    with pytest.raises(TaskError, match="gamma"):
        Urban(gamma=1.5)
    with pytest.raises(MapError, match="unknown characters"):
        parse_map(("###", "#x#", "###"))
    with pytest.raises(MapError, match="widths"):
        parse_map(("###", "#.", "###"))
    with pytest.raises(MapError, match="border"):
        parse_map(("#.#", "#.#", "###"))

"""The five built-in grid domains: sizes, tasks, and optimal values against independent oracles.

Oracles: for deterministic domains, V* from breadth-first shortest-path distances on a cell graph
built here from the map characters (not from the compiled P); for two-rooms with its -1.2
diagonals, the linear-programming form of the Bellman optimality equations (scipy's HiGHS).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import linprog
from scipy.sparse import csgraph

from adpart.envs.base import Domain, GoalSpec
from adpart.envs.domains.four_rooms import FourRooms
from adpart.envs.domains.parr_maze import ParrMaze
from adpart.envs.domains.three_floor import ThreeFloor, ThreeFloorArm
from adpart.envs.domains.two_rooms import TwoRooms
from adpart.envs.registry import BUILTIN_DOMAINS, get_domain, load_class
from adpart.mdp.model import FiniteMDP
from adpart.mdp.solvers import solve

EXPECTED = {
    "two-rooms": (TwoRooms, 55, 8),
    "four-rooms": (FourRooms, 104, 4),
    "three-floor": (ThreeFloor, 2900, 6),
    "three-floor-arm": (ThreeFloorArm, 3600, 10),
    "parr-maze": (ParrMaze, 3710, 4),
}


@pytest.fixture(scope="module")
def domains() -> dict[str, Domain]:
    return {name: get_domain(name) for name in EXPECTED}


def reachable_from_start(mdp: FiniteMDP) -> np.ndarray:
    S = mdp.n_states
    graph = sp.csr_array(
        sum(mdp.P[a * S:(a + 1) * S] for a in range(mdp.n_actions)) != 0, dtype=np.float64
    )
    starts = np.flatnonzero(mdp.initial)
    order = csgraph.breadth_first_order(graph, int(starts[0]), return_predecessors=False)
    out = np.zeros(S, dtype=bool)
    out[order] = True
    return out


def bfs_cell_distances(domain, goal_cells: np.ndarray, stairs: bool) -> np.ndarray:
    """Steps from every cell to the nearest goal cell, on a graph built from the characters."""
    chars = domain.grid.chars
    F, H, W = chars.shape
    ids = {}
    for f in range(F):
        for y in range(H):
            for x in range(W):
                if chars[f, y, x] != "#":
                    ids[f, y, x] = len(ids)
    edges = []
    steps = [(0, -1), (1, 0), (0, 1), (-1, 0)]
    if domain.CONNECTIVITY == 8:
        steps += [(1, -1), (1, 1), (-1, 1), (-1, -1)]
    for (f, y, x), i in ids.items():
        for dx, dy in steps:
            j = ids.get((f, y + dy, x + dx))
            if j is not None:
                edges.append((i, j))
        if stairs and chars[f, y, x] == "H" and f + 1 < F and chars[f + 1, y, x] == "H":
            edges += [(i, ids[f + 1, y, x]), (ids[f + 1, y, x], i)]
    src, dst = np.array(edges).T
    graph = sp.csr_array((np.ones(src.size), (dst, src)), shape=(len(ids), len(ids)))
    dist = csgraph.shortest_path(graph, unweighted=True, indices=goal_cells, directed=True)
    return dist.min(axis=0)


def discounted_value(d: np.ndarray, gamma: float, cost: float, goal_reward: float) -> np.ndarray:
    """Value of d steps of ``cost``, the last one arriving at the goal with ``goal_reward``."""
    return cost * (1 - gamma**d) / (1 - gamma) + goal_reward * gamma ** (d - 1)


@pytest.mark.parametrize("name", list(EXPECTED))
def test_size_registry_and_model(name: str, domains) -> None:
    cls, n_states, n_actions = EXPECTED[name]
    assert load_class(BUILTIN_DOMAINS[name]) is cls
    d = domains[name]
    assert isinstance(d, cls) and d.name == name and d.source and d.description
    assert d.default_task in d.tasks()
    for task in d.tasks():
        mdp = d.mdp(task)  # the constructor validates row sums and shapes
        assert (mdp.n_states, mdp.n_actions) == (n_states, n_actions)
        assert mdp.terminal.any()
        assert (reachable_from_start(mdp) & mdp.terminal).any(), f"{name}/{task}: goal unreachable"
        for key in ("x", "y", "floor"):
            assert mdp.features[key].shape == (n_states,)


def test_two_rooms_layout_and_rewards(domains) -> None:
    d = domains["two-rooms"]
    assert d.grid.shape == (1, 6, 10)
    mdp = d.mdp()
    f = mdp.features
    (start,) = np.flatnonzero(mdp.initial)
    (goal,) = np.flatnonzero(mdp.terminal)
    assert (f["x"][start], f["y"][start]) == (0, 5)  # lower-left corner
    assert f["x"][goal] >= 5 and f["y"][goal] <= 1  # upper right
    assert sorted(set(d.dynamics().action_costs.tolist())) == [-1.2, -1.0]
    assert mdp.gamma == 0.95


def test_two_rooms_uniform_costs_match_bfs(domains) -> None:
    d = domains["two-rooms"]
    mdp = d.mdp(GoalSpec(goal={"goal": 1}, goal_reward=10.0, gamma=0.95, step_costs=(-1.0,) * 8))
    V = solve(mdp, 1e-10).V
    dist = bfs_cell_distances(d, np.flatnonzero(mdp.terminal), stairs=False)
    expected = np.where(mdp.terminal, 0.0, discounted_value(dist, 0.95, -1.0, 10.0))
    assert np.allclose(V, expected, atol=1e-7)


def lp_values(mdp: FiniteMDP) -> np.ndarray:
    """V* as the solution of min sum V s.t. V(s) >= R(s,a) + gamma P V for admissible pairs."""
    S, A = mdp.n_states, mdp.n_actions
    live = ~mdp.terminal
    P = mdp.P.toarray().reshape(A, S, S)[:, :, :] * live[None, None, :]
    rows, rhs = [], []
    for a in range(A):
        for s in np.flatnonzero(live & mdp.admissible[:, a]):
            row = mdp.gamma * P[a, s]
            row[s] -= 1.0
            rows.append(row)
            rhs.append(-mdp.R[s, a])
    bounds = [(0, 0) if t else (None, None) for t in mdp.terminal]
    res = linprog(np.ones(S), A_ub=np.array(rows), b_ub=np.array(rhs), bounds=bounds,
                  method="highs")
    assert res.status == 0
    return res.x


def test_two_rooms_values_match_linear_program(domains) -> None:
    mdp = domains["two-rooms"].mdp()
    assert np.allclose(solve(mdp, 1e-10).V, lp_values(mdp), atol=1e-6)


def test_three_floor_values_match_bfs(domains) -> None:
    d = domains["three-floor"]
    for task in ("reach-goal", "reach-top-west"):
        mdp = d.mdp(task)
        V = solve(mdp, 1e-9).V
        dist = bfs_cell_distances(d, np.flatnonzero(mdp.terminal), stairs=True)
        assert np.isfinite(dist).all()  # every cell reaches the goal
        expected = np.where(mdp.terminal, 0.0, discounted_value(dist, 0.99, -1.0, 100.0))
        assert np.allclose(V, expected, atol=1e-6)


def test_three_floor_subgoal_features(domains) -> None:
    d = domains["three-floor"]
    dyn = d.dynamics()
    f = dyn.features
    assert f["doorway"].sum() == (d.grid.chars == "D").sum() > 30
    assert f["stair"].sum() == (d.grid.chars == "H").sum() == 8
    assert set(np.unique(f["floor"]).tolist()) == {0, 1, 2}
    up = dyn.action_names.index("GoUp")
    can_up = dyn.admissible[:, up]
    assert np.all(f["stair"][can_up] == 1) and np.all(f["floor"][can_up] < 2)
    assert can_up.sum() == 4  # two stairways from floor 0 to 1, two from 1 to 2
    assert len(d.tasks()) >= 3


def test_four_rooms_exact_facts(domains) -> None:
    d = domains["four-rooms"]
    dyn = d.dynamics()
    assert d.grid.shape == (1, 13, 13)
    assert np.flatnonzero(dyn.features["hallway"]).tolist() == [25, 51, 62, 88]
    for s, (row, col) in zip([25, 51, 62, 88], [(3, 6), (6, 2), (7, 9), (10, 6)], strict=True):
        assert (dyn.features["y"][s], dyn.features["x"][s]) == (row, col)
    s = d.cell_state(x=3, y=3)  # the middle of the north-west room: all four moves possible
    S = dyn.n_states
    for a in range(4):
        row = dyn.P[[a * S + s]].toarray().ravel()
        assert np.allclose(np.sort(row[row > 0]), [1 / 9, 1 / 9, 1 / 9, 2 / 3])
    corner = d.cell_state(x=1, y=1)  # north and west blocked: they stay put
    north = dyn.P[[0 * S + corner]].toarray().ravel()
    assert np.isclose(north[corner], 2 / 3 + 1 / 9)
    mdp = d.mdp("G1")
    assert mdp.gamma == 0.9 and np.flatnonzero(mdp.terminal).tolist() == [62]
    g2 = d.mdp("G2")
    (goal,) = np.flatnonzero(g2.terminal)
    assert dyn.features["hallway"][goal] == 0


def test_four_rooms_values_are_paper_values_over_gamma(domains) -> None:
    """Paper convention: the goal is an ordinary state whose every action pays +1 and leads to an
    extra absorbing state; then V_paper = gamma * V_here on non-goal states."""
    mdp = domains["four-rooms"].mdp("G1")
    S, A, g = mdp.n_states, mdp.n_actions, mdp.gamma
    P = mdp.P.toarray().reshape(A, S, S)
    paper = np.zeros((A, S + 1, S + 1))
    paper[:, :S, :S] = P
    paper[:, 62, :] = 0.0
    paper[:, 62, S] = 1.0
    paper[:, S, S] = 1.0
    R = np.zeros((S + 1, A))
    R[62] = 1.0
    terminal = np.zeros(S + 1, dtype=bool)
    terminal[S] = True
    V_paper = solve(FiniteMDP.from_dense(paper.transpose(1, 0, 2), R, g, terminal=terminal),
                    1e-12).V[:S]
    V_here = solve(mdp, 1e-12).V
    live = ~mdp.terminal
    assert np.allclose(V_paper[live], g * V_here[live], atol=1e-9)
    assert np.allclose(V_here, lp_values(mdp), atol=1e-7)


def test_parr_maze_counts_and_noise(domains) -> None:
    d = domains["parr-maze"]
    dyn = d.dynamics()
    assert d.grid.shape == (1, 86, 86)
    assert d.grid.n_cells == dyn.n_states == 3710
    assert dyn.features["goal"].sum() == 143
    mdp = d.mdp()
    assert mdp.terminal.sum() == 143 and mdp.gamma == 0.99
    (start,) = np.flatnonzero(mdp.initial)
    assert (dyn.features["x"][start], dyn.features["y"][start]) == (1, 1)
    assert reachable_from_start(mdp).all()  # all 3,710 free cells are reachable from S
    assert np.allclose(mdp.R[~mdp.terminal], -1.0)
    open_cell = d.cell_state(x=2, y=2)
    row = dyn.P[[0 * dyn.n_states + open_cell]].toarray().ravel()
    assert np.allclose(np.sort(row[row > 0]), [0.1, 0.1, 0.8])


def test_parr_mini_layout_loads() -> None:
    mini = ParrMaze(mini=True)
    assert mini.n_states == 1988 and mini.name == "parr-maze-mini"


def test_three_floor_arm_tasks(domains) -> None:
    d = domains["three-floor-arm"]
    dyn = d.dynamics()
    f = dyn.features
    assert d.grid.n_cells == 600
    assert set(np.unique(f["object"]).tolist()) == {0, 1, 2}
    assert set(np.unique(f["arm"]).tolist()) == {0, 1}
    assert np.array_equal(f["holding"], (f["object"] == 2).astype(f["holding"].dtype))
    north = dyn.P[[d.cell_state(x=2, y=3, floor=0)]].toarray().ravel()  # GoNorth from open cell
    assert sorted(north[north > 0].tolist()) == [0.25, 0.25, 0.5]
    mdp = d.mdp("deliver")
    assert np.all(f["object"][mdp.terminal] == 1)
    (start,) = np.flatnonzero(mdp.initial)
    assert (f["object"][start], f["arm"][start], f["floor"][start]) == (0, 0, 0)
    V = solve(mdp, 1e-6).V
    # better than wandering forever (-1/(1-gamma) = -100): the optimal policy delivers
    assert V[start] > -100.0 + 1.0
    nav = d.mdp("navigate")
    assert solve(nav, 1e-6).V[start] > -100.0 + 1.0


def test_a_moved_goal_on_three_floor_pays_what_its_named_tasks_pay():
    """``goal:`` on three-floor takes the domain's own scale (+100, gamma 0.99), so moving
    reach-top-west's goal to its own cell gives reach-top-west itself."""
    import numpy as np

    from adpart.envs import get_domain

    domain = get_domain("three-floor")
    moved, named = domain.mdp("goal:x=1,y=1,floor=2"), domain.mdp("reach-top-west")
    assert moved.gamma == named.gamma == 0.99
    assert np.array_equal(moved.R, named.R) and np.array_equal(moved.terminal, named.terminal)
    two = get_domain("two-rooms").task("goal:x=9,y=5")  # no scale of its own: the generic one
    assert two.spec["goal_reward"] == 10.0 and two.gamma == 0.95

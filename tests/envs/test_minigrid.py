"""MiniGrid layouts as exact MDPs (adpart.envs.minigrid_adapter), checked against oracles that do
not use the adapter: counts by hand, a fresh environment driven along recorded action paths, and
shortest paths from a breadth-first search over (cell, direction) with the moves written out here.
"""

from __future__ import annotations

import subprocess
import sys
from collections import deque

import numpy as np
import pytest

pytest.importorskip(
    "minigrid",
    reason="the optional minigrid extra is not installed (pip install 'adpart[minigrid]')",
)

import gymnasium
from click.testing import CliRunner

from adpart.cli import cli
from adpart.envs.minigrid_adapter import ACTION_NAMES, MiniGridDomain
from adpart.envs.registry import get_domain, parse_minigrid_name
from adpart.errors import ModelError, TaskError, UnknownNameError
from adpart.mdp.solvers import solve

GAMMA = 0.99
#: MiniGrid's directions, written out: 0 east, 1 south, 2 west, 3 north (x right, y down).
STEP = {0: (1, 0), 1: (0, 1), 2: (-1, 0), 3: (0, -1)}


@pytest.fixture(scope="module")
def empty5() -> MiniGridDomain:
    return MiniGridDomain("MiniGrid-Empty-5x5-v0")


@pytest.fixture(scope="module")
def doorkey5() -> MiniGridDomain:
    return MiniGridDomain("MiniGrid-DoorKey-5x5-v0")


def fresh(env_id: str, seed: int = 0):
    env = gymnasium.make(env_id, disable_env_checker=True).unwrapped
    env.reset(seed=seed)
    return env


def static_map(env) -> dict[tuple[int, int], str]:
    """``(x, y) -> type`` of every non-empty cell of a freshly reset environment."""
    out = {}
    for y in range(env.height):
        for x in range(env.width):
            cell = env.grid.get(x, y)
            if cell is not None:
                out[(x, y)] = cell.type
    return out


def shortest_actions(env, goal_cells: set[tuple[int, int]]) -> dict[tuple, int]:
    """For an object-free layout: the fewest actions (left, right, forward) from each reachable
    ``(x, y, dir)`` to enter a cell of ``goal_cells``, by a BFS of our own over the moves
    (turning is a step; forward enters any cell but a wall; goal and lava end the episode)."""
    cells = static_map(env)
    start = (int(env.agent_pos[0]), int(env.agent_pos[1]), int(env.agent_dir))
    ends = {t for c, t in cells.items() if t in ("goal", "lava")}
    assert ends <= {"goal", "lava"}

    def successors(s):
        x, y, d = s
        dx, dy = STEP[d]
        ahead = (x + dx, y + dy)
        yield (x, y, (d - 1) % 4)
        yield (x, y, (d + 1) % 4)
        yield (*ahead, d) if cells.get(ahead) != "wall" else s

    seen, order, queue = {start}, [], deque([start])
    while queue:  # forward BFS: the states an episode can occupy
        s = queue.popleft()
        order.append(s)
        for t in successors(s):
            if (t[0], t[1]) in goal_cells or cells.get((t[0], t[1])) in ("goal", "lava"):
                continue
            if t not in seen:
                seen.add(t)
                queue.append(t)
    dist = {s: 1 for s in order if any((t[0], t[1]) in goal_cells for t in successors(s))}
    changed = True
    while changed:  # Bellman-Ford on unit steps (small graphs)
        changed = False
        for s in order:
            best = min((dist[t] + 1 for t in successors(s) if t in dist), default=None)
            if best is not None and best < dist.get(s, 1 << 30):
                dist[s] = best
                changed = True
    return dist


# ------------------------------------------------------------------------- state counts
def test_empty_5x5_state_count_by_hand(empty5):
    """3x3 interior, agent at (1,1) facing east, goal at (3,3). The 8 other cells in 4
    directions are 32 states; the goal cell is entered only by forward from (2,3) facing east or
    from (3,2) facing south, and its arrival copy keeps that direction: 2 terminal states."""
    dyn = empty5.dynamics()
    assert dyn.n_states == 8 * 4 + 2
    f = dyn.features
    running = f["outcome"] == 0
    assert set(zip(f["x"][running], f["y"][running], strict=True)) == {
        (x, y) for x in (1, 2, 3) for y in (1, 2, 3)} - {(3, 3)}
    done = ~running
    assert sorted(zip(f["x"][done], f["y"][done], f["dir"][done], strict=True)) == [
        (3, 3, 0), (3, 3, 1)]
    assert dyn.action_names == ("left", "right", "forward")  # the others never change a state
    assert np.flatnonzero(dyn.start) == [0] and (f["x"][0], f["y"][0], f["dir"][0]) == (1, 1, 0)


@pytest.mark.parametrize("env_id", ["MiniGrid-Empty-8x8-v0", "MiniGrid-LavaGapS5-v0",
                                    "MiniGrid-LavaGapS7-v0"])
def test_state_count_equals_an_independent_bfs(env_id):
    env = fresh(env_id)
    cells = static_map(env)
    goal = {c for c, t in cells.items() if t == "goal"}
    lava = {c for c, t in cells.items() if t == "lava"}
    dist = shortest_actions(env, goal)
    # arrivals in goal or lava: (cell, direction) pairs one forward step away from an occupied state
    arrivals = set()
    start = (int(env.agent_pos[0]), int(env.agent_pos[1]), int(env.agent_dir))
    occupied, queue = {start}, deque([start])
    while queue:
        x, y, d = queue.popleft()
        for t in ((x, y, (d - 1) % 4), (x, y, (d + 1) % 4),
                  (x + STEP[d][0], y + STEP[d][1], d)):
            if (t[0], t[1]) in goal | lava:
                arrivals.add(t)
            elif cells.get((t[0], t[1])) != "wall" and t not in occupied:
                occupied.add(t)
                queue.append(t)
    dyn = MiniGridDomain(env_id).dynamics()
    assert dyn.n_states == len(occupied) + len(arrivals)
    assert set(dist) <= occupied


# ------------------------------------------------------------------------- transitions
def _path(space, s: int) -> list[int]:
    actions = []
    while space.parent[s] >= 0:
        actions.append(int(space.parent_action[s]))
        s = int(space.parent[s])
    return actions[::-1]


def _describe(env) -> tuple:
    """What an environment's state is, read from the environment alone."""
    carried = env.carrying.encode() if env.carrying is not None else None
    return (int(env.agent_pos[0]), int(env.agent_pos[1]), int(env.agent_dir), carried,
            env.grid.encode().tobytes())


@pytest.mark.parametrize(("env_id", "n"), [("MiniGrid-DoorKey-5x5-v0", 200),
                                           ("MiniGrid-MultiRoom-N2-S4-v0", 60),
                                           ("MiniGrid-LavaGapS5-v0", 40)])
def test_sampled_transitions_match_a_fresh_environment(env_id, n):
    """Each sampled (state, action): a fresh env reset with the same seed is driven to the state
    along its recorded BFS path, then steps the action; its position, direction, carried object,
    full grid encoding, termination and reward sign must be the model's successor."""
    domain = MiniGridDomain(env_id)
    space = domain.space
    A = space.succ.shape[1]
    rng = np.random.default_rng(7)
    running = np.flatnonzero(space.keys % 3 == 0)
    pairs = [(int(rng.choice(running)), int(rng.integers(A))) for _ in range(n)]
    oracle = fresh(env_id)
    feats = domain.dynamics().features
    for s, a in pairs:
        oracle.reset(seed=0)
        for b in _path(space, s):
            *_, terminated, truncated, _ = oracle.step(b)
            assert not terminated and not truncated
        _, reward, terminated, _, _ = oracle.step(a)
        t = int(space.succ[s, a])
        outcome = int(space.keys[t] % 3)
        assert terminated == (outcome != 0), (s, ACTION_NAMES[a])
        assert (reward > 0) == (outcome == 1)
        space.restore(int(space.keys[t]))
        assert _describe(oracle) == _describe(space.env), (s, ACTION_NAMES[a])
        # the exposed features, read from the fresh environment
        assert (feats["x"][t], feats["y"][t], feats["dir"][t]) == _describe(oracle)[:3]
        carried = oracle.carrying
        assert feats["carrying"][t] == (carried.encode()[0] if carried is not None else 0)
    space.restore(space.start_key)


def test_p_is_the_successor_table_on_the_kept_actions(doorkey5):
    dyn = doorkey5.dynamics()
    space = doorkey5.space
    S, A = dyn.n_states, dyn.n_actions
    assert dyn.P.shape == (A * S, S)
    np.testing.assert_array_equal(dyn.P.sum(axis=1), np.ones(A * S))
    kept = [ACTION_NAMES.index(a) for a in dyn.action_names]
    assert dyn.action_names == ("left", "right", "forward", "pickup", "drop", "toggle")
    for k, a in enumerate(kept):
        rows = dyn.P[[k * S + s for s in range(S)]]
        np.testing.assert_array_equal(rows.indices, space.succ[:, a])
    done = ACTION_NAMES.index("done")
    np.testing.assert_array_equal(space.succ[:, done], np.arange(S))  # done: no effect here


# ------------------------------------------------------------------------- values
@pytest.mark.parametrize("env_id", ["MiniGrid-Empty-8x8-v0", "MiniGrid-FourRooms-v0"])
def test_v_star_is_the_discounted_shortest_path(env_id):
    """V*(s) = gamma^(d - 1) for d the fewest actions (turns count) to enter the goal."""
    domain = MiniGridDomain(env_id)
    mdp = domain.mdp("reward")
    V = solve(mdp, 1e-9).V
    env = fresh(env_id)
    goal = {c for c, t in static_map(env).items() if t == "goal"}
    dist = shortest_actions(env, goal)
    f = domain.dynamics().features
    running = np.flatnonzero(f["outcome"] == 0)
    assert len(running) == len(dist)
    for s in running:
        d = dist[(int(f["x"][s]), int(f["y"][s]), int(f["dir"][s]))]
        assert V[s] == pytest.approx(GAMMA ** (d - 1), abs=1e-7)
    assert np.all(V[f["outcome"] != 0] == 0)


def _greedy_path(domain: MiniGridDomain, task: str = "reward") -> tuple[list[str], int]:
    dyn = domain.dynamics()
    sol = solve(domain.mdp(task), 1e-9)
    terminal = domain.task(task).terminal
    S = dyn.n_states
    s, names = 0, []
    while not terminal[s] and len(names) < S:
        a = int(sol.policy[s])
        names.append(dyn.action_names[a])
        s = int(dyn.P[[a * S + s]].indices[0])
    return names, s


def test_doorkey_needs_the_key_and_the_door(doorkey5):
    """The optimal path from the start picks the key up, then opens the door, then ends on the
    goal; V*(start) is gamma^(its length - 1)."""
    names, end = _greedy_path(doorkey5)
    f = doorkey5.dynamics().features
    assert f["outcome"][end] == 1
    assert "pickup" in names and "toggle" in names
    assert names.index("pickup") < names.index("toggle")
    assert f["door0"][0] == 2  # locked at the start
    V = solve(doorkey5.mdp("reward"), 1e-9).V
    assert V[0] == pytest.approx(GAMMA ** (len(names) - 1), abs=1e-7)
    # no state past the door has it locked (it may be closed again behind the agent)
    door = [c is not None and c.type == "door" for c in doorkey5.layout_grid].index(True)
    beyond = f["x"] > door % doorkey5.env.width
    assert beyond.any() and np.all(f["door0"][beyond] != 2)
    assert np.all(f["door0"][f["x"] == door % doorkey5.env.width] == 0)  # in the doorway: open


# ------------------------------------------------------------------------- tasks
def test_goal_spec_moves_the_goal(empty5):
    task = empty5.task("goal:x=1,y=3")
    f = empty5.dynamics().features
    np.testing.assert_array_equal(task.terminal, (f["x"] == 1) & (f["y"] == 3))
    assert task.terminal.sum() == 4  # every direction at that cell
    assert not task.terminal[(f["x"] == 3) & (f["y"] == 3)].any()  # the old goal is not a goal
    assert task.gamma == GAMMA
    V = solve(empty5.mdp(task), 1e-9).V
    assert V[0] == pytest.approx(GAMMA ** 2)  # right (face south), forward, forward: 3 actions
    with pytest.raises(TaskError, match="feature 'z'"):
        empty5.task("goal:z=1")


def test_reward_task_is_state_based(doorkey5):
    task = doorkey5.task("reward")
    f = doorkey5.dynamics().features
    np.testing.assert_array_equal(task.terminal, f["outcome"] != 0)
    assert set(np.unique(task.reward)) == {0.0, 1.0}
    assert task.gamma == GAMMA


def test_lava_ends_the_episode_with_nothing():
    domain = MiniGridDomain("MiniGrid-LavaGapS5-v0")
    f = domain.dynamics().features
    env = fresh("MiniGrid-LavaGapS5-v0")
    lava = {c for c, t in static_map(env).items() if t == "lava"}
    failed = f["outcome"] == 2
    assert failed.any()
    assert {(int(x), int(y)) for x, y in zip(f["x"][failed], f["y"][failed], strict=True)} <= lava
    V = solve(domain.mdp("reward"), 1e-9).V
    assert np.all(V[failed] == 0)


# ------------------------------------------------------------------------- names and errors
def test_names_seeds_and_arguments():
    assert parse_minigrid_name("minigrid:MiniGrid-DoorKey-5x5-v0[seed=3]") == (
        "MiniGrid-DoorKey-5x5-v0", {"seed": 3})
    assert get_domain("minigrid:MiniGrid-DoorKey-5x5-v0[seed=0]").name == (
        "minigrid:MiniGrid-DoorKey-5x5-v0")
    d3 = get_domain("minigrid:MiniGrid-DoorKey-5x5-v0[seed=3]")
    assert d3.name == "minigrid:MiniGrid-DoorKey-5x5-v0[seed=3]"
    assert get_domain(d3.name).dynamics().content_hash == d3.dynamics().content_hash
    every = get_domain("minigrid:MiniGrid-Empty-5x5-v0[actions=all]")
    assert every.dynamics().action_names == ACTION_NAMES
    assert every.dynamics().n_states == 34
    big = get_domain("minigrid:MiniGrid-Empty-5x5-v0[size=6]")
    assert big.dynamics().n_states == 15 * 4 + 2
    with pytest.raises(UnknownNameError, match=r"minigrid:ID\[key=value"):
        parse_minigrid_name("minigrid:MiniGrid-Empty-5x5-v0[seed=1")
    with pytest.raises(ModelError, match="rejected the arguments"):
        get_domain("minigrid:MiniGrid-Empty-5x5-v0[no_such_argument=1]")


@pytest.mark.parametrize(("name", "error", "words"), [
    ("minigrid:MiniGrid-FourRoom-v0", UnknownNameError, "Did you mean minigrid:MiniGrid-FourRooms"),
    ("minigrid:Taxi-v4", UnknownNameError, "MiniGrid has no environment 'Taxi-v4'"),
    ("minigrid:MiniGrid-DoorKey-5x5-v0[max_states=100]", ModelError, "more than 100 reachable"),
    ("minigrid:MiniGrid-Dynamic-Obstacles-5x5-v0", ModelError, "draws random numbers"),
    ("minigrid:BabyAI-GoToRedBall-v0", ModelError, "BabyAI level"),
])
def test_refusals_name_the_problem(name, error, words):
    with pytest.raises(error, match=words):
        get_domain(name).dynamics()


def _cli(*args: str):
    return CliRunner().invoke(cli, list(args))


def test_cli_env_show_reports_the_state_count():
    import json

    out = _cli("env", "show", "minigrid:MiniGrid-FourRooms-v0", "--json")
    assert out.exit_code == 0, out.output
    info = json.loads(out.output)
    assert info["states"] == MiniGridDomain("MiniGrid-FourRooms-v0").n_states
    assert info["actions"] == ["left", "right", "forward"]


def test_cli_errors_are_one_line(monkeypatch):
    out = _cli("env", "show", "minigrid:MiniGrid-FourRoom-v0")
    assert out.exit_code == 2
    assert len(out.output.strip().splitlines()) == 1
    assert out.output.startswith("Error:") and "minigrid:MiniGrid-FourRooms-v0" in out.output
    monkeypatch.setitem(sys.modules, "minigrid", None)  # as if the extra were not installed
    out = _cli("env", "show", "minigrid:MiniGrid-Empty-5x5-v0")
    assert out.exit_code == 2
    assert len(out.output.strip().splitlines()) == 1
    assert "pip install 'adpart[minigrid]'" in out.output


def test_the_adapter_imports_minigrid_only_when_a_name_is_resolved():
    probe = ("import sys, adpart.envs.registry, adpart.envs.minigrid_adapter, "
             "adpart.workflows.resolve as r; r.resolve_domain('two-rooms'); "
             "print('minigrid' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False"


# ------------------------------------------------------------------------- drawing
def test_render_puts_the_objects_and_overlays_on_the_grid(tmp_path, doorkey5):
    f = doorkey5.dynamics().features
    path = tmp_path / "doorkey.png"
    fig = doorkey5.render(str(path), values=solve(doorkey5.mdp(), 1e-6).V,
                          marked=f["carrying"] > 0, labels=f["door0"])
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    letters = {t.get_text() for t in fig.axes[0].texts if t.get_gid() == "minigrid-object"}
    assert letters == {"K", "L"}  # the key and the locked door where they start
    shown = fig.axes[0].images[-1].get_array()  # one value per cell: the max over its states
    V = solve(doorkey5.mdp(), 1e-6).V
    cell = (int(f["y"][0]), int(f["x"][0]))
    at = (f["x"] == cell[1]) & (f["y"] == cell[0])
    assert shown[cell] == pytest.approx(V[at].max())
    free = doorkey5.layout()[0]
    assert not free[0].any() and free[1, 1]  # the border is wall

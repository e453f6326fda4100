"""move-goal:, set-reward:, reward-table: - later tasks that keep the environment's own rewards.

The expected arrays are built by hand from the environments' own transition tables (Gymnasium's
``env.unwrapped.P``, the grid's deterministic moves), not by the code under test.
"""

from __future__ import annotations

import json

import gymnasium
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import scipy.sparse as sp
from click.testing import CliRunner

from adpart.cli import cli
from adpart.cli.pipeline_cmd import split_tasks
from adpart.envs.base import Domain, Dynamics, Task
from adpart.envs.task_language import goal_mask, goal_states
from adpart.errors import TaskError
from adpart.partition.layer import step_baseline
from adpart.workflows import resolve
from adpart.workflows.resolve import resolve_domain

LAKE = "gym:FrozenLake-v1[map_name=4x4,is_slippery=false]"
# SFFF / FHFH / FFFH / HFFG: state = 4 * row + col
HOLES = [5, 7, 11, 12]
OLD_GOAL, NEW_GOAL = 15, 3


def gym_table(env_id, **kwargs):
    """``{s: {a: [(p, s', r, done)]}}`` straight from Gymnasium."""
    env = gymnasium.make(env_id, **kwargs)
    try:
        return env.unwrapped.P
    finally:
        env.close()


def expected_rewards(table, n_states, n_actions, arrival):
    """``R(s, a) = sum_k p_k r'_k`` with ``r' = arrival(s', r)`` (the hand-built oracle)."""
    R = np.zeros((n_states, n_actions))
    for s in range(n_states):
        for a in range(n_actions):
            for p, s2, r, _done in table[s][a]:
                R[s, a] += p * arrival(s2, r)
    return R


def lake():
    return resolve_domain(LAKE)


# -------------------------------------------------------------------------------- move-goal


def test_move_goal_on_frozenlake_keeps_the_holes_and_pays_the_lakes_own_plus_one():
    domain = lake()
    base, task = domain.task(), domain.task("move-goal:row=0,col=3")
    table = gym_table("FrozenLake-v1", map_name="4x4", is_slippery=False)
    # arriving at (0,3) pays the old goal's +1; at the old goal (3,3) the step's 0; holes 0
    R = expected_rewards(table, 16, 4, lambda s2, r: 1.0 if s2 == NEW_GOAL else
                         (0.0 if s2 == OLD_GOAL else r))
    np.testing.assert_array_equal(task.reward, R)
    terminal = np.zeros(16, bool)
    terminal[[*HOLES, NEW_GOAL]] = True
    np.testing.assert_array_equal(task.terminal, terminal)
    assert not task.terminal[OLD_GOAL] and base.terminal[OLD_GOAL]
    assert task.gamma == base.gamma == 0.99
    np.testing.assert_array_equal(task.initial, base.initial)
    assert task.name == "move-goal:col=3,row=0"
    assert task.spec["kind"] == "move-goal" and task.spec["goal_bonus"] == 1.0
    assert task.spec["from"] == "reward" and task.spec["base"]["kind"] == "gym-reward"
    # the step reward it reads is the partition layer's step baseline (mode rule)
    reading = goal_states(domain.dynamics(), base).reading
    adm = np.ones((16, 4), bool)
    assert reading.baseline == step_baseline(base.reward, adm, base.terminal, rule="mode") == 0
    # the map letters the new goal, not the holes
    assert np.flatnonzero(goal_mask(domain, task)).tolist() == [NEW_GOAL]


def test_move_goal_on_a_slippery_lake_moves_the_expected_reward_exactly():
    domain = resolve_domain("gym:FrozenLake-v1[map_name=4x4]")
    task = domain.task("move-goal:row=0,col=3")
    table = gym_table("FrozenLake-v1", map_name="4x4", is_slippery=True)
    R = expected_rewards(table, 16, 4, lambda s2, r: 1.0 if s2 == NEW_GOAL else
                         (0.0 if s2 == OLD_GOAL else r))
    np.testing.assert_allclose(task.reward, R, atol=1e-12)


def test_move_goal_on_cliffwalking_keeps_the_steps_and_the_cliff():
    domain = resolve_domain("gym:CliffWalking-v1")
    base, task = domain.task(), domain.task("move-goal:row=0,col=11")
    table = gym_table("CliffWalking-v1")
    # a cost-to-go task: the goal (3,11) pays the step's -1 and ends the costs; (0,11) now does
    R = expected_rewards(table, 48, 4, lambda s2, r: r)
    np.testing.assert_array_equal(task.reward, R)
    assert set(np.unique(R)) == {-1.0, -100.0}
    cliff_moves = sum(1 for s in range(48) for a in range(4) if table[s][a][0][2] == -100)
    assert (task.reward == -100).sum() == cliff_moves > 0
    assert np.flatnonzero(task.terminal).tolist() == [11]  # 0 * 12 + 11; (3,11) = 47 is not
    assert base.terminal[47] and task.gamma == base.gamma
    assert task.spec["goal_bonus"] == 0.0 and task.spec["step_reward"] == -1.0


def deterministic_arrival(domain, goal_state):
    """``(S, A)`` cost(a) + 10 on arriving at ``goal_state``, from the grid's own moves."""
    dyn = domain.dynamics()
    P = sp.csr_array(dyn.P)
    S, A = dyn.n_states, dyn.n_actions
    R = np.zeros((S, A))
    for a in range(A):
        for s in range(S):
            row = P[[a * S + s], :].toarray().ravel()
            (nxt,) = np.flatnonzero(row)  # two-rooms moves are deterministic
            R[s, a] = dyn.action_costs[a] + (10.0 if nxt == goal_state else 0.0)
    return R


def test_move_goal_on_two_rooms_pays_the_domains_own_goal_reward():
    domain = resolve_domain("two-rooms")
    dyn = domain.dynamics()
    moved, generic = domain.task("move-goal:x=9,y=5"), domain.task("goal:x=9,y=5")
    (cell,) = np.flatnonzero((dyn.features["x"] == 9) & (dyn.features["y"] == 5))
    R = deterministic_arrival(domain, cell)  # -1 straight, -1.2 diagonal, +10 on arrival
    np.testing.assert_allclose(moved.reward, R, atol=1e-12)
    assert np.flatnonzero(moved.terminal).tolist() == [cell]
    assert moved.gamma == domain.task("reach-goal").gamma == 0.95
    # two-rooms sets no goal_defaults, and the generic goal: scheme (+10, gamma 0.95, the step
    # costs) happens to be reach-goal's own: the arrays agree; only name and spec differ
    np.testing.assert_allclose(generic.reward, moved.reward, atol=1e-12)
    assert generic.gamma == moved.gamma
    assert generic.spec["kind"] == "goal" and moved.spec["kind"] == "move-goal"
    assert moved.spec["from"] == "reach-goal" and moved.spec["goal_bonus"] == 10.0


def test_move_goal_on_four_rooms_keeps_g1s_plus_one_and_gamma_where_goal_does_not():
    domain = resolve_domain("four-rooms")
    dyn = domain.dynamics()
    moved, generic = domain.task("move-goal:x=1,y=1"), domain.task("goal:x=1,y=1")
    new = (dyn.features["x"] == 1) & (dyn.features["y"] == 1)
    S, A = dyn.n_states, dyn.n_actions
    arrive = (sp.csr_array(dyn.P) @ new.astype(float)).reshape(A, S).T  # stochastic moves
    np.testing.assert_allclose(moved.reward, dyn.action_costs[None, :] + 1.0 * arrive,
                               atol=1e-12)
    assert moved.gamma == domain.task("G1").gamma == 0.9
    # goal: replaces them with the generic +10 and gamma 0.95
    np.testing.assert_allclose(generic.reward, dyn.action_costs[None, :] + 10.0 * arrive,
                               atol=1e-12)
    assert generic.gamma == 0.95


# ----------------------------------------------------------------------- set-reward, tables

SET = "set-reward:row=0,col=2=-1;row=3,col=3=0"


def test_set_reward_adds_a_penalty_state_and_removes_a_reward():
    domain = lake()
    base, task = domain.task(), domain.task(SET)
    table = gym_table("FrozenLake-v1", map_name="4x4", is_slippery=False)
    R = expected_rewards(table, 16, 4, lambda s2, r: -1.0 if s2 == 2 else
                         (0.0 if s2 == OLD_GOAL else r))
    np.testing.assert_array_equal(task.reward, R)
    np.testing.assert_array_equal(task.terminal, base.terminal)  # without ;terminal: as before
    assert task.gamma == base.gamma
    terminal = domain.task(SET.replace("=-1;", "=-1;terminal;"))
    assert terminal.terminal[2] and terminal.terminal.sum() == base.terminal.sum() + 1
    np.testing.assert_array_equal(terminal.reward, task.reward)
    nonterminal = domain.task("set-reward:row=3,col=3=0;nonterminal")
    assert not nonterminal.terminal[OLD_GOAL]


def write_tables(tmp_path, columns):
    csv_path, parquet_path = tmp_path / "rewards.csv", tmp_path / "rewards.parquet"
    names = list(columns)
    lines = [",".join(names)] + [
        ",".join("" if v is None else str(v).lower() for v in row)
        for row in zip(*columns.values(), strict=True)]
    csv_path.write_text("\n".join(lines) + "\n")
    pq.write_table(pa.table(columns), parquet_path)
    return csv_path, parquet_path


def same_task(a: Task, b: Task) -> None:
    np.testing.assert_array_equal(a.reward, b.reward)
    np.testing.assert_array_equal(a.terminal, b.terminal)
    np.testing.assert_array_equal(a.initial, b.initial)
    assert a.gamma == b.gamma


def test_a_reward_table_in_csv_or_parquet_is_the_equivalent_set_reward(tmp_path):
    domain = lake()
    csv_path, parquet_path = write_tables(tmp_path, {
        "row": [0, 3], "col": [2, 3], "reward": [-1.0, 0.0], "terminal": [True, None]})
    expected = domain.task("set-reward:row=0,col=2=-1;terminal;row=3,col=3=0")
    from_csv = domain.task(f"reward-table:{csv_path}")
    from_parquet = domain.task(f"reward-table:{parquet_path}")
    same_task(from_csv, expected)
    same_task(from_parquet, expected)
    # the spec holds the rows and their hash, so the two files are one task's content
    assert from_csv.spec["rows"] == from_parquet.spec["rows"] == expected.spec["rows"]
    assert from_csv.spec["sha256"] == from_parquet.spec["sha256"]
    assert from_csv.name.endswith(";sha256:" + from_csv.spec["sha256"][:12])
    # a state column is the state index
    (tmp_path / "by-state").mkdir()
    by_state, _ = write_tables(tmp_path / "by-state", {"state": [2, 15], "reward": [-1, 0]})
    same_task(domain.task(f"reward-table:{by_state}"), domain.task(SET))


def test_a_changed_table_is_another_task_and_its_old_name_is_refused(tmp_path):
    domain = lake()
    csv_path, _ = write_tables(tmp_path, {"state": [2], "reward": [-1]})
    first = domain.task(f"reward-table:{csv_path}")
    csv_path.write_text("state,reward\n2,-2\n")
    second = domain.task(f"reward-table:{csv_path}")
    assert first.spec["sha256"] != second.spec["sha256"] and first.name != second.name
    with pytest.raises(TaskError, match="the file changed since the task was named"):
        domain.task(first.name)


@pytest.mark.parametrize(("columns", "message"), [
    ({"row": [0, 9], "col": [2, 1], "reward": [-1, 1]}, r"row 2: no state matches col=1,row=9"),
    ({"row": [0], "col": [2], "pay": [1]}, r"columns row, col, pay; the table needs a 'reward'"),
    ({"row": [0], "column": [2], "reward": [1]}, r"column 'column' is neither state"),
])
def test_a_bad_table_is_a_one_line_error_naming_the_row_or_column(tmp_path, columns, message):
    csv_path, parquet_path = write_tables(tmp_path, columns)
    for path in (csv_path, parquet_path):
        with pytest.raises(TaskError, match=message) as info:
            lake().task(f"reward-table:{path}")
        assert "\n" not in str(info.value)


# -------------------------------------------------------------------------- canonical names


@pytest.mark.parametrize("spellings", [
    ("move-goal:row=0,col=3", "move-goal:col=3.0,row=0", "move-goal:row=0,col=3;from:reward"),
    ("set-reward:row=0,col=2=-1;row=3,col=3=0", "set-reward:row=3,col=3=0.0;col=2,row=0=-1.0"),
    ("set-reward:row=0,col=2=-1;terminal", "set-reward:col=2,row=0=-1.000;terminal;from:reward"),
])
def test_two_spellings_are_one_task_and_the_name_resolves_to_it_again(spellings):
    domain = lake()
    tasks = [domain.task(s) for s in spellings]
    assert len({t.name for t in tasks}) == 1
    assert all(t.spec == tasks[0].spec for t in tasks)
    json.dumps(tasks[0].spec)  # JSON-able, as the knowledge base stores it
    again = domain.task(tasks[0].name)
    assert again.name == tasks[0].name and again.spec == tasks[0].spec
    same_task(again, tasks[0])
    assert again.description == tasks[0].description


def test_two_spellings_are_one_task_in_the_knowledge_base(tmp_path):
    from adpart.store import KnowledgeBase

    domain = lake()
    kb = KnowledgeBase.open(str(tmp_path / "kb"))
    try:
        env = kb.environment_for_mdp(domain.mdp(), LAKE)
        ids = {kb.put_task(env, t.name, spec={**t.spec, "name": t.name}, gamma=t.gamma).id
               for t in (domain.task("move-goal:row=0,col=3"),
                         domain.task("move-goal:col=3,row=0;from:reward"))}
        assert len(ids) == 1
    finally:
        kb.close()


# ------------------------------------------------------------------------------ bad input


class Chain(Domain):
    """Four cells in a row, left/right; ``wander`` has no terminal state, ``two-goals`` pays +1 at
    the left end and +2 at the right."""

    name = "chain-test"
    default_task = "wander"

    def _build_dynamics(self) -> Dynamics:
        rows, cols = [], []
        for a, d in enumerate((-1, 1)):
            for s in range(4):
                rows.append(a * 4 + s)
                cols.append(min(max(s + d, 0), 3))
        P = sp.csr_array((np.ones(8), (rows, cols)), shape=(8, 4))
        return Dynamics(P=P, action_names=("left", "right"), action_costs=np.zeros(2),
                        features={"x": np.arange(4)}, start=np.array([0.0, 1.0, 0.0, 0.0]))

    def tasks(self):
        return {"wander": self._wander, "two-goals": self._two_goals}

    def _wander(self, domain):
        return Task("wander", np.zeros((4, 2)), np.zeros(4, bool), self.dynamics().start, 0.9)

    def _two_goals(self, domain):
        R = np.array([[1.0, 0.0], [1.0, 0.0], [0.0, 2.0], [0.0, 2.0]])
        return Task("two-goals", R, np.array([True, False, False, True]),
                    self.dynamics().start, 0.9)


def test_a_base_task_without_goal_or_with_two_goal_rewards_is_refused_naming_the_fix():
    chain = Chain()
    with pytest.raises(TaskError, match=r"has no goal state.*set-reward:"):
        chain.task("move-goal:x=2")
    with pytest.raises(TaskError, match=r"different rewards on arrival \(1 at 1 state, 2 at 1 "
                       r"state\).*set-reward:"):
        chain.task("move-goal:x=2;from:two-goals")
    # set-reward needs no goal: it says what arriving pays
    assert chain.task("set-reward:x=2=5;terminal").reward[1, 1] == 5.0


@pytest.mark.parametrize(("task", "message"), [
    ("move-goal:rows=0,col=3", "'rows' is not a feature of this environment"),
    ("move-goal:row=9,col=3", "no state matches col=3,row=9 (col takes 0..3; row takes 0..3)"),
    ("move-goal:row=0,col=3;from:nothing", "has no task 'nothing'"),
    ("set-reward:row=0,col=2", "is not FEATURE=V,...=REWARD"),
    ("set-reward:terminal", ";terminal follows the clause it applies to"),
    ("set-reward:row=0,col=2=-1;row=0,col=2=-2", "which set it differently"),
    ("reward-table:no-such.csv", "no such file"),
])
def test_malformed_tasks_are_one_line_errors(task, message):
    with pytest.raises(TaskError) as info:
        lake().task(task)
    assert message in str(info.value) and "\n" not in str(info.value)


@pytest.mark.parametrize(("env", "tasks", "message"), [
    (LAKE, "reward,move-goal:rows=0,col=3", "'rows' is not a feature"),
    (LAKE, "reward,move-goal:row=9,col=3", "no state matches col=3,row=9"),
    ("chain-test", "wander,move-goal:x=2", "task 'wander' has no goal state"),
])
def test_a_bad_task_exits_2_with_one_line_and_stores_nothing(env, tasks, message, tmp_path,
                                                             monkeypatch):
    monkeypatch.setitem(resolve._BUILT, "chain-test", Chain())
    kb_dir = tmp_path / "kb"
    result = CliRunner().invoke(cli, ["pipeline", env, "--tasks", tasks, "--kb", str(kb_dir),
                                      "-q"])
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: --tasks: ") and message in lines[0]
    assert not kb_dir.exists()
    task = tasks.split(",", 1)[1]
    shown = CliRunner().invoke(cli, ["env", "show", env, "--task", task, "--json"])
    assert shown.exit_code == 2 and message in shown.output
    assert len(shown.output.strip().splitlines()) == 1


# ------------------------------------------------------------------------------------- CLI


def test_split_tasks_keeps_every_specs_commas_whole():
    text = ("reward,move-goal:row=0,col=3;from:reward,set-reward:row=1,col=1=-1;terminal;"
            "row=3,col=3=0,goal:x=1,y=2;start:x=0,y=0,reward-table:t.csv,reach-goal")
    assert split_tasks(text) == (
        "reward", "move-goal:row=0,col=3;from:reward",
        "set-reward:row=1,col=1=-1;terminal;row=3,col=3=0", "goal:x=1,y=2;start:x=0,y=0",
        "reward-table:t.csv", "reach-goal")
    assert split_tasks("reward,move-goal:row=0,col=3") == ("reward", "move-goal:row=0,col=3")


def test_env_show_resolves_and_draws_a_moved_goal(tmp_path):
    result = CliRunner().invoke(cli, ["env", "show", LAKE, "--task", "move-goal:row=0,col=3",
                                      "--json"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.output)["task"] == "move-goal:col=3,row=0"
    out = tmp_path / "lake.png"
    drawn = CliRunner().invoke(cli, ["env", "show", LAKE, "--task", "move-goal:row=0,col=3",
                                     "--out", str(out)])
    assert drawn.exit_code == 0, drawn.output
    assert out.read_bytes()[:4] == b"\x89PNG"


def test_the_pipeline_learns_a_moved_goal_after_the_environments_own_task(tmp_path):
    kb_dir, out = tmp_path / "kb", tmp_path / "out"
    # --regime true-model: the default learned-model regime stops on this fully explored
    # deterministic lake whatever the second task (goal:row=0,col=3 too): its estimated model
    # is the true one, and the option set is refused as another environment's
    result = CliRunner().invoke(cli, [
        "pipeline", LAKE, "--tasks", "reward,move-goal:row=0,col=3", "--regime", "true-model",
        "--runs", "3", "--first-episodes", "100", "--episodes", "50", "--kb", str(kb_dir),
        "--out", str(out), "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    tasks = list(dict.fromkeys(row["task"] for row in summary["tasks"]))
    assert tasks == ["reward", "move-goal:row=0,col=3"]  # the rows say the task as given
    listed = CliRunner().invoke(cli, ["kb", "ls", "--kb", str(kb_dir), "--json"])
    assert listed.exit_code == 0, listed.output
    assert "move-goal:col=3,row=0" in listed.output  # stored under its canonical name

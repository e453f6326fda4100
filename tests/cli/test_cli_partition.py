"""`adpart partition`: every phase stored, phase 1 reused, checker and value gap, bad input."""

from __future__ import annotations

import json

import numpy as np
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner

from adpart.cli import cli
from adpart.options.smdp import stack_models
from adpart.partition import Partition, check_stability, exact_lumping
from adpart.store import KnowledgeBase
from adpart.workflows.options import load_options, options_for_subgoals
from adpart.workflows.resolve import resolve_domain

GROUP = cli


def run(*args: str) -> object:
    return CliRunner().invoke(GROUP, list(args))


def run_json(*args: str) -> dict:
    result = run(*args, "--json")
    assert result.exit_code == 0, result.output
    return json.loads(result.output)


def ref_id(ref: str) -> int:
    return int(ref.split(":")[1])


@pytest.fixture
def kb_with_options(tmp_path):
    """two-rooms with a learned policy, subgoal set {27, 40} and its two stored options."""
    kb_dir = tmp_path / "kb"
    learned = run(
        "learn",
        "two-rooms",
        "--runs",
        "1",
        "--episodes",
        "5",
        "--out",
        str(tmp_path / "o"),
        "--kb",
        str(kb_dir),
        "--json",
        "-q",
    )
    assert learned.exit_code == 0, learned.output
    ids = json.loads(learned.output)["kb"]
    kb = KnowledgeBase.open(str(kb_dir))
    try:
        policy = kb.get("policy", ref_id(ids["policies"][0]))
        env = kb.get("environment", kb.get("task", policy.task_id).environment_id)
        subgoal_set = kb.put_subgoal_set(env, "hand", [27, 40], policy=policy)
        stored = options_for_subgoals(kb, subgoal_set)
    finally:
        kb.close()
    return kb_dir, subgoal_set.ref, [r.ref for r in stored.records]


def test_primitive_exact_partition_matches_exact_lumping_and_is_exported(tmp_path):
    kb_dir = str(tmp_path / "kb")
    plot = tmp_path / "blocks.png"
    out = run_json(
        "partition",
        "two-rooms",
        "--options",
        "primitive",
        "--delta",
        "0",
        "--reward-epsilon",
        "0",
        "--task",
        "reach-goal",
        "--kb",
        kb_dir,
        "--plot",
        str(plot),
    )
    mdp = resolve_domain("two-rooms").mdp("reach-goal")
    assert out["states"] == mdp.n_states
    assert len(out["phase1"]["partitions"]) == mdp.n_actions
    assert out["phase1"]["computed"] == mdp.n_actions and out["phase1"]["reused"] == 0
    assert out["check"] == {
        "ran": True,
        "ok": True,
        "max_mass_span": 0.0,
        "max_reward_span": 0.0,
        "violations": 0,
    }
    # oracle: the worklist lumping (another code path) of the primitive SMDP with rewards
    oracle = exact_lumping(mdp.as_smdp(), use_rewards=True)
    assert out["phase3"]["blocks"] == oracle.n_blocks == out["final"]["blocks"]
    assert out["value_gap"]["measured"] == pytest.approx(0.0, abs=1e-6)
    assert out["value_gap"]["bound"] == pytest.approx(2.0)
    assert plot.stat().st_size > 1000

    exported = tmp_path / "labels.parquet"
    result = run(
        "kb",
        "export",
        out["phase3"]["id"],
        "--field",
        "labels",
        "--out",
        str(exported),
        "--kb",
        kb_dir,
    )
    assert result.exit_code == 0, result.output
    table = pq.read_table(exported)
    assert table.num_rows == mdp.n_states
    labels = table.column(table.column_names[-1]).to_numpy()
    np.testing.assert_array_equal(labels, oracle.labels)

    kb = KnowledgeBase.open(kb_dir)
    try:
        p3 = kb.get("partition", ref_id(out["phase3"]["id"]))
        p2 = kb.get("partition", ref_id(out["phase2"]["id"]))
        assert p3.kind == "reward-refined" and p3.parent_ids == (p2.id,)
        assert p2.kind == "intersected"
        assert set(p2.parent_ids) == {ref_id(p["id"]) for p in out["phase1"]["partitions"]}
        assert p3.includes_primitives and p3.option_ids == ()
        assert kb.load(p3, "block_actions").shape == (p3.n_blocks, mdp.n_actions)
    finally:
        kb.close()
    # the same request again reuses every phase-1 partition
    again = run_json(
        "partition",
        "two-rooms",
        "--options",
        "primitive",
        "--delta",
        "0",
        "--reward-epsilon",
        "0",
        "--task",
        "reach-goal",
        "--kb",
        kb_dir,
    )
    assert again["phase1"]["reused"] == mdp.n_actions and again["phase1"]["computed"] == 0
    assert [p["id"] for p in again["phase1"]["partitions"]] == [
        p["id"] for p in out["phase1"]["partitions"]
    ]
    assert again["phase3"]["blocks"] == out["phase3"]["blocks"]


def test_options_phases_stored_phase1_reused_and_checked(kb_with_options):
    kb_dir, subgoal_set, option_refs = kb_with_options
    first = run_json(
        "partition",
        "two-rooms",
        "--options",
        subgoal_set,
        "--delta",
        "0.3",
        "--reward-epsilon",
        "10",
        "--task",
        "reach-goal",
        "--kb",
        str(kb_dir),
    )
    assert first["phase1"]["computed"] == 2 and first["check"]["ok"]
    assert not first["phase3"]["recomputed_option_models"]  # built under this very task
    assert first["value_gap"]["inside_interval"] == 1.0
    assert first["value_gap"]["measured"] <= first["value_gap"]["bound"]
    # a different option set: phase 1 of option 1 is reused, only phases 2-3 run
    single_set = run_json(
        "partition", "two-rooms", "--options", ",".join(option_refs), "--kb", str(kb_dir)
    )
    assert single_set["phase1"]["computed"] == 0 and single_set["phase1"]["reused"] == 2
    assert single_set["phase3"] is None and single_set["final"]["id"] == single_set["phase2"]["id"]
    other_delta = run_json(
        "partition", "two-rooms", "--options", subgoal_set, "--delta", "0", "--kb", str(kb_dir)
    )
    assert other_delta["phase1"]["computed"] == 2  # delta is part of the phase-1 key

    kb = KnowledgeBase.open(str(kb_dir))
    try:
        p3 = kb.get("partition", ref_id(first["phase3"]["id"]))
        records = [kb.get("option", i) for i in p3.option_ids]
        assert [r.ref for r in records] == option_refs and not p3.includes_primitives
        _, models = load_options(kb, records)
        labels = kb.load(p3, "labels")
        block_actions = kb.load(p3, "block_actions").astype(bool)
    finally:
        kb.close()
    # independent re-check of the stored partition against the options' model
    mdp = resolve_domain("two-rooms").mdp("reach-goal")
    smdp = stack_models(mdp, models, include_primitives=False)
    stored = Partition(labels, block_actions)
    assert check_stability(stored, smdp, delta=0.3, epsilon=10.0).ok
    assert stored.admissible.sum() > 0 and stored.admissible.any(axis=1).all()


def test_stored_models_are_recomputed_for_a_task_they_were_not_built_for(kb_with_options):
    kb_dir, _, _ = kb_with_options
    mdp = resolve_domain("two-rooms").mdp("reach-goal")
    kb = KnowledgeBase.open(str(kb_dir))
    try:
        env = kb.find_environment("two-rooms")
        rec = kb.records("option", environment=env)
        options, models = load_options(kb, rec)
        copies = [  # the same options, stored without a source task
            kb.put_option(
                env,
                f"copy-{o.name}",
                initiation=o.initiation,
                policy=o.policy,
                termination=o.beta,
                reward=m.R,
                transitions=m.F,
                gamma=mdp.gamma,
            )
            for o, m in zip(options, models, strict=True)
        ]
    finally:
        kb.close()
    refs = ",".join(c.ref for c in copies)
    args = ("--delta", "0", "--reward-epsilon", "0", "--task", "reach-goal", "--kb", str(kb_dir))
    copied = run_json("partition", "two-rooms", "--options", refs, *args)
    original = run_json("partition", "two-rooms", "--options", ",".join(r.ref for r in rec), *args)
    assert copied["phase3"]["recomputed_option_models"]
    assert not original["phase3"]["recomputed_option_models"]
    assert copied["phase3"]["blocks"] == original["phase3"]["blocks"]
    assert copied["value_gap"]["measured"] == pytest.approx(original["value_gap"]["measured"])


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--delta", "1.5"], "is outside [0, 1]"),
        (["--delta", "-0.1"], "is outside [0, 1]"),
        (["--reward-epsilon", "-1"], "must be >= 0"),
        (["--options", "option:99"], "option:99"),
        (["--options", "subgoal-set:99"], "subgoal-set:99"),
        (["--options", "policy:1"], "a option is needed"),
        (["--task", "no-such-task"], "no-such-task"),
    ],
)
def test_bad_input_is_one_line(kb_with_options, extra, message):
    kb_dir, subgoal_set, _ = kb_with_options
    args = ["partition", "two-rooms", "--options", subgoal_set, "--kb", str(kb_dir)]
    result = run(*args, *extra)
    assert result.exit_code == 2, result.output
    assert message in result.output
    assert "Traceback" not in result.output and len(result.output.strip().splitlines()) == 1


def test_options_of_another_environment_and_uncovered_states(kb_with_options):
    kb_dir, _, option_refs = kb_with_options
    other = run("partition", "four-rooms", "--options", option_refs[0], "--kb", str(kb_dir))
    assert other.exit_code == 2
    assert "belongs to environment 'two-rooms'" in other.output
    # one option leaves states (its own subgoal) that it cannot start from: the primitive
    # actions are offered there, and only there, as the layer's fallback
    alone = run(
        "partition", "two-rooms", "--options", option_refs[0], "--kb", str(kb_dir), "--json"
    )
    assert alone.exit_code == 0, alone.output
    summary = json.loads(alone.output)
    assert summary["check"]["ok"]
    kb = KnowledgeBase.open(str(kb_dir))
    try:
        rec = kb.get("partition", int(summary["final"]["id"].split(":")[1]))
        assert rec.includes_primitives and list(rec.option_ids) == [
            int(option_refs[0].split(":")[1])
        ]
        labels = kb.load(rec, "labels")
        actions = kb.load(rec, "block_actions")
    finally:
        kb.close()
    A = 8
    from adpart.workflows.resolve import resolve_domain

    terminal = resolve_domain("two-rooms").mdp("reach-goal").terminal
    live_blocks = np.unique(labels[~terminal])  # terminal states admit every column by convention
    with_primitives = live_blocks[actions[live_blocks, :A].any(axis=1)]
    assert with_primitives.size >= 1
    assert not actions[with_primitives, A:].any()  # fallback blocks: no option starts there
    assert np.isin(labels, with_primitives).sum() < labels.size // 4  # only a few states
    # options built under reach-goal skip its goal cell, which another task makes non-terminal:
    # it gets the fallback too
    moved = run(
        "partition",
        "two-rooms",
        "--options",
        ",".join(option_refs),
        "--task",
        "goal:x=1,y=1",
        "--kb",
        str(kb_dir),
        "--json",
    )
    assert moved.exit_code == 0, moved.output
    assert json.loads(moved.output)["check"]["ok"]


def test_phases_run_on_the_tasks_model_and_report_the_layer(kb_with_options):
    """Phase 1 is keyed by the task's terminal states; blocks are split by reachability."""
    kb_dir, subgoal_set, _ = kb_with_options
    common = ("--delta", "0.3", "--reward-epsilon", "10", "--kb", str(kb_dir))
    first = run_json("partition", "two-rooms", "--options", subgoal_set, "--task", "reach-goal",
                     *common)
    mdp = resolve_domain("two-rooms").mdp("reach-goal")
    for phase in ("phase2", "phase3"):
        layer = first["layer"][phase]
        assert layer["terminal"] == 1 and layer["terminal_states"] == int(mdp.terminal.sum())
        assert layer["reachable"] + layer["terminal"] + layer["unreachable"] == layer["blocks"]
    assert first["final"]["decision_blocks"] == first["layer"]["phase3"]["reachable"]
    assert first["reward_baseline"] == -1.2  # two-rooms: half the moves cost 1.2 (a tie: smaller)
    again = run_json("partition", "two-rooms", "--options", subgoal_set, "--task", "reach-goal",
                     *common)
    assert again["phase1"]["reused"] == 2 and again["phase3"]["id"] == first["phase3"]["id"]
    # another goal: other terminal states, so other option models and other phase-1 partitions
    other = run_json("partition", "two-rooms", "--options", subgoal_set, "--task",
                     "goal:x=2,y=2", *common)
    assert other["phase1"]["reused"] == 0 and other["layer"]["phase3"]["terminal"] == 1
    assert other["phase3"]["recomputed_option_models"]
    # the raw rewards: stored apart, and never fewer blocks than the decision rewards give
    raw = run_json("partition", "two-rooms", "--options", subgoal_set, "--task", "reach-goal",
                   "--reward-baseline", "none", *common)
    assert raw["phase3"]["id"] != first["phase3"]["id"] and raw["reward_baseline"] is None
    assert raw["phase3"]["blocks"] >= first["phase3"]["blocks"] and raw["check"]["ok"]
    text = run("partition", "two-rooms", "--options", subgoal_set, "--task", "reach-goal",
               *common)
    assert text.exit_code == 0, text.output
    assert "terminal" in text.output and "unreachable" in text.output
    bad = run("partition", "two-rooms", "--options", subgoal_set, "--task", "reach-goal",
              "--reward-baseline", "median", *common)
    assert bad.exit_code == 2 and "use mode, min, none or a number" in bad.output


def test_the_plot_marks_the_goal_of_the_task_partitioned_for(tmp_path, monkeypatch):
    """`partition --task goal:x=9,y=5 --plot` letters G at (9, 5), not at the map's default
    goal (8, 1); read back from the figure drawn."""
    from adpart.envs import render

    drawn = []
    original = render.render_domain

    def keep(*args, **kwargs):
        drawn.append(original(*args, **kwargs))
        return drawn[-1]

    monkeypatch.setattr(render, "render_domain", keep)
    run_json("partition", "two-rooms", "--options", "primitive", "--task", "goal:x=9,y=5",
             "--kb", str(tmp_path / "kb"), "--plot", str(tmp_path / "blocks.png"))
    (fig,) = drawn
    goals = [tuple(int(v) for v in t.get_position()) for t in fig.axes[0].texts
             if t.get_gid() == "G"]
    assert goals == [(9, 5)]
    (legend,) = fig.legends
    assert "goal of goal:x=9,y=5" in [t.get_text() for t in legend.get_texts()]

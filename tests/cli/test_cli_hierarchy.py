"""`adpart hierarchy` and `adpart pipeline --hierarchy`: layers stored, reused, errors one line."""

from __future__ import annotations

import json
from itertools import pairwise

import numpy as np
import pytest
from click.testing import CliRunner

from adpart.cli import cli
from adpart.cli.hierarchy_cmd import hierarchy_cmd
from adpart.store import KnowledgeBase

PIPELINE = [
    "pipeline", "two-rooms", "--tasks", "reach-goal,goal:x=9,y=5,goal:x=2,y=2",
    "--runs", "2", "--episodes", "100", "--first-episodes", "500", "--reward-epsilon", "1",
    "--flat-opt", "alpha=1", "--flat-opt", "epsilon=0.5",
    "--hier-opt", "alpha=1", "--hier-opt", "epsilon=0.3",
    "--hierarchy", "expected-learning-time", "--no-fallback", "--regime", "true-model",
]


@pytest.fixture(scope="module")
def pipeline_kb(tmp_path_factory):
    root = tmp_path_factory.mktemp("hier")
    kb_dir = root / "kb"
    first = CliRunner().invoke(cli, [*PIPELINE, "--kb", str(kb_dir), "--out", str(root / "o"),
                                     "--json"])
    assert first.exit_code == 0, first.output
    return kb_dir, json.loads(first.output), root


def counts(kb_dir):
    kb = KnowledgeBase.open(str(kb_dir))
    try:
        return kb.counts()
    finally:
        kb.close()


def test_pipeline_with_hierarchy_learns_each_task_on_the_built_layer_and_reuses_it(pipeline_kb):
    kb_dir, summary, root = pipeline_kb
    stages = [(s["stage"], s["task"]) for s in summary["stages"]]
    assert stages[3:] == [
        ("hierarchy", "goal:x=9,y=5"), ("learn-hierarchical", "goal:x=9,y=5"),
        ("learn-flat", "goal:x=9,y=5"), ("learn-known-dynamics", "goal:x=9,y=5"),
        ("hierarchy", "goal:x=2,y=2"), ("learn-hierarchical", "goal:x=2,y=2"),
        ("learn-flat", "goal:x=2,y=2"), ("learn-known-dynamics", "goal:x=2,y=2"),
    ]
    layers = [s for s in summary["stages"] if s["stage"] == "hierarchy"]
    # the first layer is built from the first task alone, the second from the first two
    assert [len(s["detail"]["tasks"]) for s in layers] == [1, 2]
    for s in layers:
        trace = s["detail"]["trace"]
        assert all(b <= a for a, b in pairwise(trace))  # never rises
    kb = KnowledgeBase.open(str(kb_dir))
    try:
        runs = {r.id: r for r in kb.records("run")}
        for _s, row in zip(layers, [r for r in summary["tasks"] if r["learner"] == "hierarchical"],
                          strict=True):
            part = kb.get("partition", int(row["partition"].split(":")[1]))
            assert part.kind == "hierarchy" and part.option_ids  # the learner needs an option
            assert row["partition_blocks"] == np.unique(kb.load(part, "labels")).size
            # offered the reward-state options, a block splits where they may not all start
            assert row["initial_blocks"] >= row["partition_blocks"]
        learned_on = {r.partition_id for r in runs.values() if r.learner == "hierarchical"}
        assert learned_on == {int(r["partition"].split(":")[1]) for r in summary["tasks"]
                              if r["learner"] == "hierarchical"}
    finally:
        kb.close()
    before = counts(kb_dir)
    again = CliRunner().invoke(cli, [*PIPELINE, "--kb", str(kb_dir), "--out", str(root / "o")])
    assert again.exit_code == 0, again.output
    assert again.output.count("reused") == 11
    assert counts(kb_dir) == before


def test_hierarchy_without_baseline_is_refused(tmp_path):
    res = CliRunner().invoke(cli, [*PIPELINE, "--no-baseline", "--kb", str(tmp_path / "kb")])
    assert res.exit_code == 2 and "--no-baseline" in res.output


def test_hierarchy_command_stores_the_layer_it_prints(pipeline_kb, tmp_path):
    kb_dir = pipeline_kb[0]
    res = CliRunner().invoke(hierarchy_cmd, ["two-rooms", "--tasks", "reach-goal,goal:x=9,y=5",
                                             "--kb", str(kb_dir), "--json",
                                             "--plot", str(tmp_path / "layer.png")])
    assert res.exit_code == 0, res.output
    out = json.loads(res.output)
    assert out["task_names"] == ["reach-goal", "goal:x=9,y=5"]
    assert all(b <= a for a, b in zip(out["trace"], out["trace"][1:], strict=False))
    # the stored layer (empty blocks given the primitive actions) is compared with flat
    assert out["flat_estimate"] == 55 * 55 * 8
    assert out["fallback"] == (out["flat_estimate"] <= out["estimate"])
    kb = KnowledgeBase.open(str(kb_dir))
    try:
        part = kb.get("partition", int(out["partition"].split(":")[1]))
        labels, adm = kb.load(part, "labels"), kb.load(part, "block_actions")
        names = list(kb.get("environment", part.environment_id).spec["actions"]) + [
            kb.get("option", i).name for i in part.option_ids]
    finally:
        kb.close()
    assert part.kind == "hierarchy" and part.provenance.plugin == "expected-learning-time"
    assert np.bincount(labels).tolist() == out["block_states"]
    assert [[names[k] for k in np.flatnonzero(row)] for row in adm] == out["block_columns"]
    assert [f"option:{i}" for i in part.option_ids] == out["options"]
    assert (tmp_path / "layer.png").stat().st_size > 1000
    if len(out["trace"]) > 1:
        assert (tmp_path / "layer_trace.png").stat().st_size > 1000
    text = CliRunner().invoke(hierarchy_cmd, ["two-rooms", "--estimator", "all-subgoals",
                                              "--kb", str(kb_dir)])
    assert text.exit_code == 0, text.output
    assert "by all-subgoals" in text.output and "E[t_learn]" in text.output
    assert "block 0" in text.output


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--estimator", "no-such"], "no-such"),
        (["--tasks", "not-learned"], "not-learned"),
        (["--c", "-1"], "--c must be >= 0.0"),
        (["--delta", "1.5"], "--delta must be <= 1.0; got 1.5"),
        (["--estimator", "all-subgoals", "--delta", "-0.1"], "--delta must be >= 0.0"),
        (["--estimator", "all-subgoals", "--delta", "none"], "all-subgoals refines"),
        (["--estimator", "all-subgoals", "--max-refinements", "3"],
         "--max-refinements is not a parameter of hierarchy-estimator 'all-subgoals'"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(pipeline_kb, args, needle):
    res = CliRunner().invoke(hierarchy_cmd, ["two-rooms", *args, "--kb", str(pipeline_kb[0])])
    assert res.exit_code == 2, res.output
    assert needle in res.output and "Traceback" not in res.output
    assert len(res.output.strip().splitlines()) == 1


def test_pipeline_falls_back_to_flat_where_the_abstraction_cannot_pay(tmp_path):
    """two-rooms' one doorway option fits none of the goals, so every layer Algorithm 3 can
    build costs more than learning the 55 states flat: the method learns flat, saying so."""
    args = [a for a in PIPELINE if a != "--no-fallback"]
    args[args.index("--tasks") + 1] = "reach-goal,goal:x=9,y=5"
    res = CliRunner().invoke(cli, [*args, "--kb", str(tmp_path / "kb"), "--out",
                                   str(tmp_path / "o"), "--json"])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.output)
    stages = [s["stage"] for s in summary["stages"]]
    assert "fallback" in stages and "learn-hierarchical" not in stages
    fb = next(s for s in summary["stages"] if s["stage"] == "fallback")
    assert fb["detail"]["flat_estimate"] == pytest.approx(55 * 55 * 8)
    assert fb["detail"]["estimate"] >= fb["detail"]["flat_estimate"]
    assert "will not pay" in fb["detail"]["reason"]
    rows = {r["learner"]: r for r in summary["tasks"] if r["task"] == "goal:x=9,y=5"}
    assert rows["flat-fallback"]["episodes_to_bound_median"] == (
        rows["flat"]["episodes_to_bound_median"])


def _learned_model_layers(root, later: str) -> tuple[list[dict], list[tuple[str, np.ndarray]]]:
    """The hierarchy stages and stored layers of a learned-model pipeline whose later tasks are
    ``later`` (two runs, short)."""
    args = [*PIPELINE[:3], f"reach-goal,{later}", *PIPELINE[4:-1], "learned-model",
            "--no-model-baseline", "--kb", str(root / "kb"), "--out", str(root / "o"), "--json"]
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 0, res.output
    layers = [s for s in json.loads(res.output)["stages"] if s["stage"] == "hierarchy"]
    kb = KnowledgeBase.open(str(root / "kb"))
    try:
        envs = {e.id: e.name for e in kb.records("environment")}
        parts = [kb.get("partition", int(s["result"].split(":")[1])) for s in layers]
        return layers, [(envs[p.environment_id], kb.load(p, "labels")) for p in parts]
    finally:
        kb.close()


def test_in_the_learned_model_regime_algorithm_3_builds_on_the_estimate_and_reads_no_new_task(
        tmp_path):
    """Each later task's layer is Algorithm 3 over the options and the earlier tasks' learned Q
    tables on the model the first task's runs estimated; so the first later task's layer is the
    same whichever task it is (nothing of it is read), and the next one is built from two."""
    layers_a, built_a = _learned_model_layers(tmp_path / "a", "goal:x=9,y=5,goal:x=2,y=2")
    _, built_b = _learned_model_layers(tmp_path / "b", "goal:x=3,y=3")
    assert [len(s["detail"]["tasks"]) for s in layers_a] == [1, 2]
    for env_name, _ in built_a + built_b:
        assert env_name.startswith("two-rooms@experience:run:")  # built on the estimate
    assert np.array_equal(built_a[0][1], built_b[0][1])  # another new task: the same layer

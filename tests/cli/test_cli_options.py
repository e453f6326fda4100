"""`adpart options`: options to a stored subgoal set, exact models stored and reused."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from adpart.cli import cli
from adpart.options.models import option_model
from adpart.options.subgoal_options import subgoal_options
from adpart.store import KnowledgeBase
from adpart.workflows.options import load_options
from adpart.workflows.resolve import resolve_domain


@pytest.fixture
def kb_with_subgoals(tmp_path):
    kb_dir = tmp_path / "kb"
    learned = CliRunner().invoke(
        cli, ["learn", "two-rooms", "--runs", "1", "--episodes", "5", "--out", str(tmp_path / "o"),
              "--kb", str(kb_dir), "--json"])
    assert learned.exit_code == 0, learned.output
    ids = json.loads(learned.output)["kb"]
    kb = KnowledgeBase.open(str(kb_dir))
    policy = kb.get("policy", int(ids["policies"][0].split(":")[1]))
    env = kb.get("environment", kb.get("task", policy.task_id).environment_id)
    subgoal_set = kb.put_subgoal_set(env, "hand", [27, 40], policy=policy)
    kb.close()
    return kb_dir, subgoal_set


def test_options_are_learned_stored_and_reused(kb_with_subgoals):
    kb_dir, subgoal_set = kb_with_subgoals
    args = ["options", "two-rooms", "--subgoals", subgoal_set.ref, "--kb", str(kb_dir), "--json"]
    first = CliRunner().invoke(cli, args)
    assert first.exit_code == 0, first.output
    result = json.loads(first.output)
    assert not result["reused"]
    assert [o["subgoal_state"] for o in result["options"]] == [27, 40]
    second = json.loads(CliRunner().invoke(cli, args).output)
    assert second["reused"] and [o["id"] for o in second["options"]] == [
        o["id"] for o in result["options"]
    ]

    kb = KnowledgeBase.open(str(kb_dir))
    try:
        records = [kb.get("option", int(o["id"].split(":")[1])) for o in result["options"]]
        options, models = load_options(kb, records)
    finally:
        kb.close()
    mdp = resolve_domain("two-rooms").mdp("reach-goal")
    fresh = subgoal_options(mdp, np.array([27, 40]))
    for stored, model, expected in zip(options, models, fresh, strict=True):
        np.testing.assert_array_equal(stored.initiation, expected.initiation)
        oracle = option_model(mdp, expected, duration=False)
        np.testing.assert_allclose(model.R, oracle.R, atol=1e-12)
        np.testing.assert_allclose(model.F.toarray(), oracle.F.toarray(), atol=1e-12)


def test_options_errors(kb_with_subgoals):
    kb_dir, subgoal_set = kb_with_subgoals
    wrong_env = CliRunner().invoke(
        cli, ["options", "four-rooms", "--subgoals", subgoal_set.ref, "--kb", str(kb_dir)])
    assert wrong_env.exit_code == 2
    assert "belongs to environment 'two-rooms'" in wrong_env.output
    wrong_kind = CliRunner().invoke(
        cli, ["options", "two-rooms", "--subgoals", "policy:1", "--kb", str(kb_dir)])
    assert wrong_kind.exit_code == 2 and "a subgoal-set is needed" in wrong_kind.output
    missing = CliRunner().invoke(
        cli, ["options", "two-rooms", "--subgoals", "99", "--kb", str(kb_dir)])
    assert missing.exit_code == 2 and "no subgoal-set:99" in missing.output


def test_learn_on_stored_options_with_smdp_q_and_hierarchical(kb_with_subgoals, tmp_path):
    kb_dir, subgoal_set = kb_with_subgoals
    built = CliRunner().invoke(
        cli, ["options", "two-rooms", "--subgoals", subgoal_set.ref, "--kb", str(kb_dir)])
    assert built.exit_code == 0, built.output
    smdp = CliRunner().invoke(cli, [
        "learn", "two-rooms", "--learner", "smdp-q", "--options", subgoal_set.ref,
        "--include-primitives", "true", "--runs", "2", "--episodes", "30",
        "--out", str(tmp_path / "s"),
        "--kb", str(kb_dir), "--json"])
    assert smdp.exit_code == 0, smdp.output
    summary = json.loads(smdp.output)
    assert summary["learner"] == "smdp-q" and summary["runs"] == 2
    import pyarrow.parquet as pq

    curve = pq.read_table(tmp_path / "s" / "curve.parquet").to_pydict()
    assert sum(curve["decisions"]) < sum(curve["steps"])  # options take several steps per decision

    hier = CliRunner().invoke(cli, [
        "learn", "two-rooms", "--learner", "hierarchical", "--options", subgoal_set.ref,
        "--runs", "1", "--episodes", "10", "--out", str(tmp_path / "h"), "--kb", str(kb_dir),
        "--json"])
    assert hier.exit_code == 0, hier.output

    missing = CliRunner().invoke(cli, [
        "learn", "two-rooms", "--learner", "smdp-q", "--options", "subgoal-set:1,", "--kb",
        str(kb_dir), "--out", str(tmp_path / "m")])
    assert missing.exit_code == 2

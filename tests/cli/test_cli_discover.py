"""`adpart discover`: subgoals of a stored policy, stored once, reused, plotted; errors."""

from __future__ import annotations

import json

from click.testing import CliRunner

from adpart.cli import cli
from adpart.store import KnowledgeBase

DOORWAY = 23  # two-rooms: the only gap in the wall (x = 5, y = 2)


def learned_kb(tmp_path):
    kb_dir = tmp_path / "kb"
    result = CliRunner().invoke(
        cli,
        [
            "learn",
            "two-rooms",
            "--runs",
            "1",
            "--episodes",
            "500",
            "--alpha",
            "1",
            "--epsilon",
            "0.5",
            "--kb",
            str(kb_dir),
            "--out",
            str(tmp_path / "o"),
            "--json",
        ],
    )
    assert result.exit_code == 0, result.output
    assert json.loads(result.output)["optimal_runs"] == 1
    return kb_dir


def test_discover_finds_the_doorway_stores_and_reuses(tmp_path):
    kb_dir = learned_kb(tmp_path)
    args = [
        "discover",
        "two-rooms",
        "--policy",
        "policy:1",
        "--kb",
        str(kb_dir),
        "--json",
        "--plot",
        str(tmp_path / "d.png"),
    ]
    first = json.loads(CliRunner().invoke(cli, args).output)
    assert first["subgoals"] == [DOORWAY]
    assert first["threshold"] > first["stats"]["ratio_mean"]
    assert not first["reused"]
    assert (tmp_path / "d.png").read_bytes()[:4] == b"\x89PNG"
    second = json.loads(CliRunner().invoke(cli, args).output)
    assert second["reused"] and second["subgoal_set"] == first["subgoal_set"]
    kb = KnowledgeBase.open(str(kb_dir))
    try:
        stored = kb.get("subgoal-set", int(first["subgoal_set"].split(":")[1]))
        assert list(stored.states) == [DOORWAY] and stored.policy_id == 1
        assert kb.load(stored, "scores").argmax() == DOORWAY
    finally:
        kb.close()


def test_discover_with_another_detector_and_errors(tmp_path):
    kb_dir = learned_kb(tmp_path)
    top = CliRunner().invoke(
        cli,
        [
            "discover",
            "two-rooms",
            "--policy",
            "1",
            "--kb",
            str(kb_dir),
            "--detector",
            "betweenness",
            "--select",
            "top",
            "--top",
            "1",
            "--json",
        ],
    )
    assert top.exit_code == 0, top.output
    assert json.loads(top.output)["subgoals"] == [DOORWAY]
    local = CliRunner().invoke(
        cli,
        ["discover", "two-rooms", "--policy", "1", "--kb", str(kb_dir), "--detector",
         "betweenness", "--json"],
    )
    assert local.exit_code == 0, local.output
    summary = json.loads(local.output)
    assert summary["subgoals"] == [DOORWAY]  # the only local maximum of the 8-connected rooms
    assert summary["params"]["select"] == "local-maxima"
    for args, message in [
        (["--top", "2"], "--top is not a parameter of subgoal-detector 'count-exhaustive'"),
        (["--p", "1.5"], "p"),
        (["--detector", "count"], "no subgoal-detector named 'count'"),
        (["--detector", "betweenness", "--select", "best"], "--select"),
    ]:
        bad = CliRunner().invoke(
            cli, ["discover", "two-rooms", "--policy", "1", "--kb", str(kb_dir), *args]
        )
        assert bad.exit_code == 2, bad.output
        assert message in bad.output
    other = CliRunner().invoke(
        cli, ["discover", "four-rooms", "--policy", "1", "--kb", str(kb_dir)]
    )
    assert other.exit_code == 2 and "belongs to environment 'two-rooms'" in other.output

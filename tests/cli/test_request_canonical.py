"""Equal work is found again whatever its spelling: requests are stored in canonical form."""

from __future__ import annotations

from click.testing import CliRunner

from adpart.cli import cli
from adpart.store import KnowledgeBase
from adpart.workflows.learning import LearnRequest, canonical_request, find_learning


def test_spellings_of_one_request_are_one_canonical_request():
    base = canonical_request(LearnRequest("two-rooms", runs=2, episodes=20))
    for same in (
        LearnRequest("two-rooms", task="reach-goal", runs=2, episodes=20),
        LearnRequest("two-rooms", params={"max-steps": "1000"}, runs=2, episodes=20),
        LearnRequest("two-rooms", params={"max_steps": 1000, "alpha": "1/n^0.8"}, runs=2,
                     episodes=20),
    ):
        assert canonical_request(same) == base
    assert canonical_request(LearnRequest("two-rooms", params={"max-steps": 999}, runs=2,
                                          episodes=20)) != base
    assert base["task"] == "reach-goal" and base["params"]["max_steps"] == 1000


def test_a_run_learned_by_the_cli_is_found_by_another_spelling(tmp_path):
    kb_dir = tmp_path / "kb"
    out = CliRunner().invoke(cli, ["learn", "two-rooms", "--runs", "2", "--episodes", "20",
                                   "--max-steps", "1000", "--kb", str(kb_dir), "-q",
                                   "--out", str(tmp_path / "out")])
    assert out.exit_code == 0, out.output
    with KnowledgeBase.open(kb_dir) as kb:
        # `adpart learn` took two-rooms' own alpha (1: every move is deterministic)
        found = find_learning(kb, LearnRequest("two-rooms", task="reach-goal", runs=2,
                                               episodes=20,
                                               params={"max_steps": "1000", "alpha": 1}))
        assert found is not None and found["run"] == "run:1"
        assert find_learning(kb, LearnRequest("two-rooms", runs=2, episodes=20,
                                              params={"max_steps": "1000"})) is None
        assert find_learning(kb, LearnRequest("two-rooms", runs=2, episodes=21)) is None

"""`adpart learn --model ENV@experience:run:N`: the estimated model from the command line."""

from __future__ import annotations

from click.testing import CliRunner

from adpart.cli import cli
from adpart.store import KnowledgeBase


def _run(*args: str):
    return CliRunner().invoke(cli, list(args))


def test_a_model_from_a_stored_runs_experience_is_given_to_the_learners_that_take_one(tmp_path):
    kb = str(tmp_path / "kb")
    first = _run("learn", "two-rooms", "--task", "reach-goal", "--runs", "2", "--episodes", "50",
                 "--kb", kb, "-q", "--out", str(tmp_path / "a"))
    assert first.exit_code == 0, first.output
    model = "two-rooms@experience:run:1"
    counted = _run("learn", "two-rooms", "--task", "goal:x=9,y=5", "--learner",
                   "estimated-dynamics", "--model", model, "--runs", "2", "--episodes", "20",
                   "--kb", kb, "-q", "--out", str(tmp_path / "b"))
    assert counted.exit_code == 0, counted.output
    with KnowledgeBase.open(kb) as base:
        run = base.get("run", 2)
        assert run.metrics["knowledge"]["dynamics"] == "estimated"
        assert "run:1 and its own steps" in run.metrics["knowledge"]["uses"][0]
        assert run.provenance.parameters["request"]["model"] == model
    flat = _run("learn", "two-rooms", "--task", "goal:x=9,y=5", "--model", model, "--kb", kb,
                "-q", "--out", str(tmp_path / "c"))
    assert flat.exit_code == 2
    assert "does not learn over a model estimated from experience; drop --model" in flat.output
    wrong = _run("learn", "four-rooms", "--learner", "estimated-dynamics", "--model", model,
                 "--kb", kb, "-q", "--out", str(tmp_path / "d"))
    assert wrong.exit_code == 2 and "is a model of 'two-rooms', not of 'four-rooms'" in (
        wrong.output)


def test_an_unknown_environment_is_refused_before_the_knowledge_base_is_made(tmp_path):
    result = _run("learn", "no-such-env", "--kb", str(tmp_path / "kb"))
    assert result.exit_code == 2 and "no-such-env" in result.output
    assert not (tmp_path / "kb").exists()
    result = _run("learn", "two-rooms", "--task", "no-such-task", "--kb", str(tmp_path / "kb"))
    assert result.exit_code == 2 and "no task 'no-such-task'" in result.output
    assert not (tmp_path / "kb").exists()

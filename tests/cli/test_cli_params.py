"""One parameter convention: typed plugin options with each plugin's default, one meaning a name."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from click.testing import CliRunner

from adpart.cli import cli

DOCS = Path(__file__).resolve().parents[2] / "docs" / "cli.md"


def _help(*command: str) -> str:
    out = CliRunner().invoke(cli, [*command, "--help"], terminal_width=80)
    assert out.exit_code == 0, out.output
    return out.output


def _option_line(text: str, option: str) -> str:
    """The help entry of ``option`` with its continuation lines, whitespace collapsed."""
    block = re.search(rf"^  {re.escape(option)}\b.*?(?=^  -|\Z)", text, re.MULTILINE | re.DOTALL)
    assert block, f"{option} not in help"
    return " ".join(block.group(0).split())


def test_learner_options_are_typed_and_show_each_plugins_default():
    text = _help("learn")
    assert _option_line(text, "--max-steps").startswith("--max-steps INTEGER")
    assert _option_line(text, "--q-init").startswith("--q-init FLOAT")
    assert "[default: 1/n^0.8]" in _option_line(text, "--alpha")  # the chosen learner's
    assert "[default: 0.1]" in _option_line(_help("learn", "--learner", "sarsa"), "--alpha")


def test_a_value_of_the_wrong_type_is_refused_before_anything_runs(tmp_path):
    out = CliRunner().invoke(cli, ["learn", "two-rooms", "--max-steps", "many",
                                   "--kb", str(tmp_path / "kb")])
    assert out.exit_code == 2, out.output
    assert out.output.strip() == ("Error: learner 'q-learning': --max-steps expects int, "
                                  "got 'many'")
    assert not (tmp_path / "kb").exists()


def test_one_meaning_per_option_name():
    assert "--epsilon " in _help("learn")
    discover = _help("discover", "--detector", "count-mc")
    assert "--count-epsilon" in discover and "--epsilon " not in discover
    for command in ("partition", "pipeline"):
        text = _help(command)
        assert "--reward-epsilon" in text and "--epsilon " not in text
    for command in ("pipeline", "transfer"):
        assert "--baseline / --no-baseline" in _help(command)


def test_hierarchy_takes_its_estimators_parameters_as_options():
    text = _help("hierarchy")
    assert _option_line(text, "--threshold-scale").startswith("--threshold-scale FLOAT")
    assert "--param" not in text


@pytest.fixture
def builtins_only(monkeypatch):
    """The registry of adpart's own plugins only: the excerpt documents the built-ins, and each
    installed third-party learner (the example package's sarsa) adds its own default to it."""
    from adpart.plugins import Registry, get_registry, manager

    builtins = Registry()
    for spec in get_registry().all():
        if spec.package == "adpart":
            builtins.add(spec)
    monkeypatch.setattr(manager, "_REGISTRY", builtins)


def test_the_documented_help_excerpt_is_what_learn_help_prints(builtins_only):
    block = re.search(r"```\n(  --graph.*?)```", DOCS.read_text(), re.DOTALL).group(1)
    assert " ".join(block.split()) in _option_line(_help("learn", "--learner", "maxq-q"),
                                                    "--graph")

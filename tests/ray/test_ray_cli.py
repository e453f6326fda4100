"""``adpart sweep --executor ray``: the plugin as registered by its entry point."""

from __future__ import annotations

import json

import click
import pytest
from click.testing import CliRunner

pytest.importorskip("ray")

from adpart.cli.group import LazyGroup
from adpart.cli.sweep import sweep_cmd
from adpart.plugins import reset_registry


@click.group(cls=LazyGroup)
def group() -> None:
    """The main group, as far as this command is concerned."""


group.add_command(sweep_cmd)


@pytest.fixture(autouse=True)
def fresh_registry():
    """A registry built anew, so the built-in ``ray`` executor is looked up as a user would."""
    reset_registry()
    yield
    reset_registry()


def test_ray_cli_unreachable_address_is_one_clear_line(small_sweep, tmp_path):
    result = CliRunner().invoke(group, ["sweep", str(small_sweep), "--kb", str(tmp_path / "kb"),
                                        "--executor", "ray", "--ray-address", "127.0.0.1:1"])
    assert result.exit_code == 2
    assert "cannot reach the Ray cluster at '127.0.0.1:1'" in result.output
    assert "ray start --head --port=1" in result.output
    assert "Traceback" not in result.output


@pytest.mark.slow
def test_ray_cli_sweep_runs_on_the_cluster(ray_cluster, small_sweep, tmp_path):
    kb = str(tmp_path / "kb")
    args = ["sweep", str(small_sweep), "--kb", kb, "--executor", "ray", "--json"]
    first = CliRunner().invoke(group, args, catch_exceptions=False)
    assert first.exit_code == 0, first.output
    # the summary is stdout; under load a Ray thread once wrote a crash dump to stderr
    assert json.loads(first.stdout)["stored"] == 8
    again = json.loads(CliRunner().invoke(group, args, catch_exceptions=False).stdout)
    assert (again["stored"], again["skipped"]) == (0, 8)

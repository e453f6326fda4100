"""``adpart sweep`` through click (serial executor; no Ray needed)."""

from __future__ import annotations

import json

import click
import pytest
from click.testing import CliRunner

from adpart.cli.group import LazyGroup
from adpart.cli.sweep import sweep_cmd

GRID = """
runs = 1
episodes = 10
eval_every = 5
seeds = [0, 1]
environments = ["two-rooms"]
[params]
alpha = ["0.1", "0.5"]
"""


@click.group(cls=LazyGroup)
def group() -> None:
    """The main group, as far as this command is concerned."""


group.add_command(sweep_cmd)


@pytest.fixture
def grid(tmp_path):
    path = tmp_path / "grid.toml"
    path.write_text(GRID)
    return path


def _run(*args: str):
    return CliRunner().invoke(group, ["sweep", *args], catch_exceptions=False)


def test_sweep_cli_runs_then_resumes(grid, tmp_path):
    kb = str(tmp_path / "kb")
    dry = _run(str(grid), "--kb", kb, "--dry-run")
    assert dry.exit_code == 0, dry.output
    assert "would run 4, skipped 0" in dry.output
    first = _run(str(grid), "--kb", kb, "--executor", "serial")
    assert first.exit_code == 0, first.output
    assert "stored 4, skipped 0" in first.output
    assert first.output.splitlines()[0].split() == ["#", "cell", "status", "gap", "optimal", "run"]
    again = _run(str(grid), "--kb", kb, "--executor", "serial", "--json")
    data = json.loads(again.output)
    assert (data["stored"], data["skipped"], data["cells"]) == (0, 4, 4)
    assert {r["status"] for r in data["results"]} == {"skipped"}


def test_sweep_cli_local_executor_with_options(grid, tmp_path):
    result = _run(str(grid), "--kb", str(tmp_path / "kb"), "--executor", "local",
                  "--executor-opt", "workers=1", "--json")
    assert result.exit_code == 0, result.output
    assert json.loads(result.output)["stored"] == 4


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--executor", "serial", "--ray-address", "127.0.0.1:1"], "--ray-address applies"),
        (["--executor", "local", "--executor-opt", "workers"], "KEY=VALUE"),
        (["--executor", "local", "--executor-opt", "cores=2"], "no parameter --cores"),
        (["--executor", "locl"], "Did you mean 'local'"),
    ],
)
def test_sweep_cli_executor_errors_are_one_line(grid, tmp_path, args, message):
    result = _run(str(grid), "--kb", str(tmp_path / "kb"), *args)
    assert result.exit_code == 2
    assert message in result.output


def test_sweep_cli_config_error_names_the_key(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text('seeds = 1\nenvironments = ["two-rooms"]\nepisode = 3\n')
    result = _run(str(path), "--kb", str(tmp_path / "kb"))
    assert result.exit_code == 2
    assert "`episode` is not a sweep setting" in result.output
    assert "Did you mean `episodes`" in result.output


def test_sweep_cli_failed_cells_exit_nonzero(tmp_path, monkeypatch):
    import adpart.workflows.sweep as sweep_mod
    from adpart.errors import TaskError

    real = sweep_mod.run_learning

    def fail_alpha_05(request, **kwargs):  # a cell failing in its worker (serial: in-process)
        if request.params.get("alpha") == "0.5":
            raise TaskError("simulated failure of a cell")
        return real(request, **kwargs)

    monkeypatch.setattr(sweep_mod, "run_learning", fail_alpha_05)
    path = tmp_path / "grid.toml"
    path.write_text(GRID)
    result = _run(str(path), "--kb", str(tmp_path / "kb"), "--executor", "serial")
    assert result.exit_code == 1
    assert "failed 2" in result.output

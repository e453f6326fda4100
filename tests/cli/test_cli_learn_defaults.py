"""`adpart learn` and `adpart transfer` take the environment's defaults, as the pipeline does.

With the learners' own defaults (alpha 1/n^0.8, 1,000 steps an episode) `adpart learn
three-floor` for 1,500 episodes ended 0/10 runs optimal (gap 87.3); with the environment's (alpha
1 where every move is deterministic, max(1000, 2|S|) steps) it ends 10/10 optimal.
"""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from adpart.cli import cli
from adpart.workflows.pipeline import episode_defaults
from adpart.workflows.resolve import resolve_domain


def learn(tmp_path, *args: str) -> dict:
    res = CliRunner().invoke(cli, ["learn", *args, "--runs", "1", "--episodes", "1",
                                   "--no-store", "--json", "-q", "--out", str(tmp_path / "o")])
    assert res.exit_code == 0, res.output
    return json.loads(res.output)


@pytest.mark.parametrize("env", ["three-floor", "two-rooms", "four-rooms"])
def test_learn_takes_the_environments_defaults(tmp_path, env):
    params = learn(tmp_path, env)["params"]
    dyn = resolve_domain(env).dynamics()
    deterministic = all(len(dyn.P[[r]].indices) <= 1 for r in range(dyn.P.shape[0]))
    assert params["alpha"] == ("1" if deterministic else "1/n^0.8")
    assert params["max_steps"] == max(1000, 2 * dyn.n_states)
    assert {"alpha": params["alpha"], "max-steps": params["max_steps"]} == episode_defaults(env)


def test_the_command_line_overrides_them(tmp_path):
    params = learn(tmp_path, "three-floor", "--alpha", "0.5", "--max-steps", "100")["params"]
    assert params["alpha"] == "0.5" and params["max_steps"] == 100


@pytest.mark.slow
def test_learn_three_floor_with_the_defaults_ends_optimal(tmp_path):
    res = CliRunner().invoke(cli, ["learn", "three-floor", "--runs", "10", "--episodes", "1500",
                                   "--no-store", "--json", "-q", "--out", str(tmp_path / "o")])
    assert res.exit_code == 0, res.output
    assert json.loads(res.output)["optimal_runs"] == 10

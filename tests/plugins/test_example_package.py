"""The example plugin package (examples/adpart-plugin-example), installed like any third party.

It must be discovered through its entry points, pass adpart.testing's checks, pass its own test
suite, and work from the command line: `adpart learn` with its learner on its environment,
`adpart discover` with its detector on a stored policy, and `adpart pipeline` with both. The
command blocks of docs/plugin-authoring.md are run here too and their output compared.
"""

from __future__ import annotations

import importlib.metadata
import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner

from adpart.cli import cli
from adpart.plugins import build_registry, get_registry, make_plugin_manager, reset_registry
from adpart.testing import check_plugin

ROOT = Path(__file__).resolve().parents[2]
PACKAGE_DIR = ROOT / "examples" / "adpart-plugin-example"
GUIDE = ROOT / "docs" / "plugin-authoring.md"
DIST = "adpart-plugin-example"
PLUGINS = [("environment", "three-rooms-line"), ("subgoal-detector", "doorways"),
           ("learner", "sarsa"), ("partition-criterion", "capped-blocks")]
ENTRY_POINTS = {"plugin-example-environment", "plugin-example-detector",
                "plugin-example-learner", "plugin-example-criterion"}
DOORS = [35, 41]  # the door cells (5, 2) and (11, 2) of three-rooms-line


def _installed() -> bool:
    try:
        importlib.metadata.distribution(DIST)
    except importlib.metadata.PackageNotFoundError:
        return False
    return True


pytestmark = pytest.mark.skipif(
    not _installed(),
    reason=f"{DIST} is not installed; `make .venv/.installed-dev` installs it "
           f"(pip install -e {PACKAGE_DIR.relative_to(ROOT)})",
)


def run(*args: str, env: dict[str, str] | None = None):
    result = CliRunner().invoke(cli, list(args), env=env)
    assert result.exception is None or isinstance(result.exception, SystemExit), result.output
    return result


# --------------------------------------------------------------------------- discovery


def test_discovered_through_its_entry_points():
    pm = make_plugin_manager()
    # a third-party entry point is registered as "<package>:<name>"
    assert {name for name, (pkg, _) in pm.sources.items() if pkg == DIST} == {
        f"{DIST}:{ep}" for ep in ENTRY_POINTS}
    reg = build_registry(pm)
    for kind, name in PLUGINS:
        spec = reg.get(kind, name)
        assert (spec.package, spec.version) == (DIST, importlib.metadata.version(DIST))
        assert spec.factory.__module__.startswith("adpart_plugin_example.")


@pytest.mark.parametrize(("kind", "name"), PLUGINS, ids=[n for _, n in PLUGINS])
def test_each_plugin_passes_its_conformance_check(kind, name):
    check_plugin(get_registry().get(kind, name))


def test_disabling_one_entry_point_removes_only_its_plugin(monkeypatch):
    monkeypatch.setenv("ADPART_DISABLE_PLUGINS", "plugin-example-learner")
    reg = build_registry(make_plugin_manager())
    assert "sarsa" not in reg.names("learner") and "q-learning" in reg.names("learner")
    assert "doorways" in reg.names("subgoal-detector")
    assert "three-rooms-line" in reg.names("environment")


def test_the_packages_own_tests_pass():
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    out = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "tests"],
        check=False, cwd=PACKAGE_DIR, env=env, capture_output=True, text=True, timeout=600,
    )
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-2000:]
    assert re.search(r"\b\d+ passed\b", out.stdout) and "skipped" not in out.stdout


# --------------------------------------------------------------------------- the CLI


@pytest.fixture(scope="module")
def learned(tmp_path_factory):
    """`adpart learn three-rooms-line --learner sarsa` into a fresh knowledge base."""
    tmp = tmp_path_factory.mktemp("example")
    kb, out = tmp / "kb", tmp / "learn"
    result = run("learn", "three-rooms-line", "--learner", "sarsa", "--runs", "3",
                 "--episodes", "120", "--alpha", "0.5", "--epsilon", "exp:0.3,0.97",
                 "--eval-every", "20", "--max-steps", "500", "--executor", "serial",
                 "--kb", str(kb), "--out", str(out), "--json", "-q")
    assert result.exit_code == 0, result.output
    return kb, out, json.loads(result.output)


def test_learn_with_the_example_learner_on_the_example_environment(learned):
    _, out, summary = learned
    assert summary["env"] == "three-rooms-line" and summary["task"] == "reach-east"
    assert summary["learner"] == "sarsa" and summary["learner_package"] == DIST
    assert summary["params"] == {"alpha": "0.5", "epsilon": "exp:0.3,0.97", "max_steps": 500,
                                 "q_init": 0.0}
    assert (summary["runs"], summary["episodes"]) == (3, 120)
    assert (summary["states"], summary["actions"]) == (77, 4)
    # V* at the start: 18 steps of -1 through both doors, +10 on arrival (gamma 0.95)
    g = 0.95
    assert summary["v_star_start"] == pytest.approx(-(1 - g**18) / (1 - g) + 10 * g**17)
    assert set(summary["final_value_gap"]) == {"mean", "max"}
    assert 0 <= summary["final_value_gap"]["mean"] <= summary["final_value_gap"]["max"]
    assert summary["kb"]["policies"] == ["policy:1", "policy:2", "policy:3"]
    curve = pq.read_table(out / "curve.parquet")
    assert curve.num_rows == 3 * 120
    assert {"run", "episode", "steps", "value_gap"} <= set(curve.column_names)
    gaps = curve["value_gap"].to_numpy().reshape(3, 120)
    evaluated = [e - 1 for e in range(20, 121, 20)]
    assert np.isfinite(gaps[:, evaluated]).all() and (gaps[:, evaluated] >= -1e-9).all()
    assert np.isnan(np.delete(gaps, evaluated, axis=1)).all()  # scored like the built-ins
    assert summary["total_steps"] == int(curve["steps"].to_numpy().sum())


def test_discover_with_the_example_detector_on_a_stored_policy(learned):
    kb, _, _ = learned
    result = run("discover", "three-rooms-line", "--policy", "policy:1", "--detector",
                 "doorways", "--kb", str(kb), "--json")
    assert result.exit_code == 0, result.output
    found = json.loads(result.output)
    assert found["detector"] == "doorways" and found["policy"] == "policy:1"
    assert found["subgoals"] == DOORS
    assert found["params"] == {"min_size": 2, "narrowest": True}
    assert found["threshold"] == 2.0 and found["subgoal_set"].startswith("subgoal-set:")
    assert {"cut_vertices", "candidates", "edges"} <= set(found["stats"])
    # its parameters are typed options of `discover`
    wide = json.loads(run("discover", "three-rooms-line", "--policy", "policy:1",
                          "--detector", "doorways", "--narrowest", "false", "--kb", str(kb),
                          "--json").output)
    assert len(wide["subgoals"]) == 6 and set(DOORS) <= set(wide["subgoals"])


def test_a_refused_value_is_one_error_line_naming_the_option(tmp_path):
    result = run("learn", "three-rooms-line", "--learner", "sarsa", "--alpha", "2", "--kb",
                 str(tmp_path / "kb"))
    assert result.exit_code == 2
    assert "Error: learner 'sarsa': --alpha '2'" in result.output
    assert not (tmp_path / "kb").exists()


def test_a_learner_that_records_no_experience_is_refused_in_the_learned_model_regime(tmp_path):
    result = run("pipeline", "three-rooms-line", "--tasks", "reach-east,reach-middle",
                 "--flat-learner", "sarsa", "--kb", str(tmp_path / "kb"), "-q")
    assert result.exit_code == 2
    assert "does not record the transitions" in result.output
    assert "--regime true-model" in result.output
    assert not (tmp_path / "kb").exists()  # refused before anything is learned or stored


def test_pipeline_with_the_example_learner_and_detector(tmp_path):
    result = run("pipeline", "three-rooms-line", "--tasks", "reach-east,reach-middle",
                 "--detector", "doorways", "--detector-opt", "min-size=3",
                 "--flat-learner", "sarsa", "--flat-opt", "alpha=0.5",
                 "--flat-opt", "epsilon=exp:0.3,0.97", "--runs", "2", "--first-episodes", "100",
                 "--episodes", "60", "--eval-every", "20", "--kb", str(tmp_path / "kb"),
                 "--out", str(tmp_path / "out"), "--json", "-q", "--regime", "true-model")
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    config = summary["config"]
    assert (config["flat_learner"], config["detector"]) == ("sarsa", "doorways")
    assert config["detector_params"] == {"min-size": "3"}  # as given; converted by the plugin
    assert config["flat_params"] == {"alpha": "0.5", "epsilon": "exp:0.3,0.97"}
    stages = [(s["stage"], s["task"]) for s in summary["stages"]]
    assert stages[:3] == [("learn-flat", "reach-east"), ("discover", "reach-east"),
                          ("options", None)]
    assert ("learn-flat", "reach-middle") in stages  # the flat baseline
    discover = summary["stages"][1]
    assert discover["detail"]["subgoals"] == DOORS
    assert summary["stages"][2]["result"] == "option:1,option:2"  # one option per door
    tasks = {(t["task"], t["learner"]): t for t in summary["tasks"]}
    assert set(tasks) >= {("reach-east", "flat"), ("reach-middle", "flat")}
    assert tasks[("reach-east", "flat")]["runs"] == 2
    for row in summary["tasks"]:
        assert {"final_gap_mean", "final_gap_max", "runs_within_bound"} <= set(row)
    assert [Path(f).name for f in summary["figures"]] == [
        "reach-east.png", "reach-middle.png", "subgoals_reach-east.png", "layer_reach-middle.png"]


# --------------------------------------------------------------------------- the guide

_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
_TIMINGS = {"seconds", "time_s"}


def _console_blocks(text: str) -> list[tuple[str, str]]:
    """``(command, expected output)`` of every ```console block (first line ``$ command``)."""
    blocks = re.findall(r"^```console\n(.*?)^```", text, re.MULTILINE | re.DOTALL)
    out = []
    for block in blocks:
        first, _, rest = block.partition("\n")
        assert first.startswith("$ "), f"a console block starts with '$ command': {first!r}"
        out.append((first[2:], rest))
    return out


def _shape(text: str, directory: Path) -> list[str]:
    text = text.replace(str(directory), "...")
    return [" ".join(_NUMBER.sub("#", line).split()) for line in text.strip().splitlines()]


def _without_timings(value):
    if isinstance(value, dict):
        return {k: _without_timings(v) for k, v in value.items() if k not in _TIMINGS}
    if isinstance(value, list):
        return [_without_timings(v) for v in value]
    return value


def _run_documented(command: str) -> str:
    """Run ``[VAR=value ...] adpart ARGS [| grep WORD]`` in-process; its output."""
    command, _, pattern = command.partition(" | grep ")
    words = shlex.split(command)
    env = {}
    while "=" in words[0]:
        key, _, value = words.pop(0).partition("=")
        env[key] = value
    assert words[0] == "adpart", f"documented commands run adpart: {command!r}"
    reset_registry()  # the environment may disable plugins; the registry is rebuilt for it
    try:
        output = CliRunner().invoke(cli, words[1:], env=env).output
    finally:
        reset_registry()
    if pattern:
        output = "".join(line for line in output.splitlines(keepends=True)
                         if pattern.strip() in line)
    return output


def test_the_guides_command_blocks_print_what_it_shows(tmp_path, monkeypatch):
    blocks = _console_blocks(GUIDE.read_text())
    commands = [c for c, _ in blocks]
    assert any(c.startswith("adpart learn three-rooms-line --learner sarsa") for c in commands)
    assert any("--detector doorways" in c and c.startswith("adpart discover") for c in commands)
    assert any(c.startswith("adpart pipeline") for c in commands)
    monkeypatch.chdir(tmp_path)
    for command, expected in blocks:
        got = _run_documented(command)
        if expected.lstrip().startswith("{"):
            assert _without_timings(json.loads(got)) == _without_timings(json.loads(expected)), \
                command
        else:
            assert _shape(got, tmp_path) == _shape(expected, tmp_path), command


def test_a_flat_option_is_checked_against_the_chosen_flat_learner(tmp_path):
    """--flat-opt is checked against --flat-learner: q-learning's kernel is no sarsa parameter."""
    result = run("pipeline", "three-rooms-line", "--tasks", "reach-east,reach-middle",
                 "--flat-learner", "sarsa", "--flat-opt", "kernel=numba",
                 "--kb", str(tmp_path / "kb"), "-q")
    assert result.exit_code == 2, result.output
    assert "learner 'sarsa' has no parameter --kernel" in result.output
    assert not (tmp_path / "kb").exists()


def _partition_stage(summary: dict) -> dict:
    return next(s for s in summary["stages"] if s["stage"] == "partition")


def test_a_third_party_criterion_changes_what_the_pipeline_builds(tmp_path):
    """`--criterion capped-blocks` refines every phase with the example package's criterion:
    the stored layer differs from the default's, and none of its blocks exceeds --size."""
    from adpart.store import KnowledgeBase
    from adpart.workflows.refs import parse_ref

    common = ("pipeline", "three-rooms-line", "--tasks", "reach-east,reach-middle",
              "--detector", "doorways", "--detector-opt", "min-size=3", "--hier-opt",
              "mode=inconsistency", "--no-fallback", "--no-baseline", "--runs", "2",
              "--first-episodes", "100", "--episodes", "20", "--eval-every", "10",
              "--kb", str(tmp_path / "kb"), "--json", "-q")
    default = run(*common, "--out", str(tmp_path / "a"))
    capped = run(*common, "--criterion", "capped-blocks", "--criterion-opt", "size=4",
                 "--out", str(tmp_path / "b"))
    assert default.exit_code == 0, default.output
    assert capped.exit_code == 0, capped.output
    first, second = (_partition_stage(json.loads(r.output)) for r in (default, capped))
    assert first["result"] != second["result"]
    assert second["detail"]["final_blocks"] > first["detail"]["final_blocks"]
    kb = KnowledgeBase.open(str(tmp_path / "kb"))
    try:
        record = kb.get("partition", parse_ref(second["result"], "partition"))
        labels = kb.load(record, "labels")
        assert record.provenance.parameters["criterion"] == "capped-blocks"
        assert record.provenance.parameters["criterion_params"]["size"] == "4"
    finally:
        kb.close()
    assert np.bincount(labels).max() <= 4
    refused = run(*common, "--criterion", "capped-blocks", "--criterion-opt", "size=0",
                  "--out", str(tmp_path / "c"))
    assert refused.exit_code == 2 and "--size must be >= 1" in refused.output

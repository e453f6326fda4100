"""CliRunner tests for `adpart --version`, `plugins`, `envs`, `env show` and `learn`."""

from __future__ import annotations

import json

import numpy as np
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner

from adpart import __version__
from adpart.cli import cli
from adpart.envs.registry import get_domain
from adpart.plugins import reset_registry
from tests.plugins.conftest import install_fake_distribution

FAKE_LEARNER = '''
import numpy as np
from adpart.plugins import Param, hookimpl
from adpart.learning.curves import LearningCurve


class Result:
    def __init__(self, Q, curve, seed):
        self.Q, self.curve, self.seed = Q, curve, seed
        self.v_star_start = 0.0
        self.parameters = {}


class UniformLearner:
    """Learns nothing: Q = constant. Exercises the third-party learner path end to end."""

    name = "constant-q"
    description = "returns a constant Q table (test plugin)"
    params = (Param("level", "float", 1.0, "the constant"),)

    def __init__(self, level=1.0):
        self.level = level

    def learn(self, mdp, *, runs, episodes, seed, eval_every, progress=None):
        Q = np.full((runs, mdp.n_states, mdp.n_actions), self.level)
        ones = np.ones((runs, episodes), dtype=np.int64)
        nan = np.full((runs, episodes), np.nan)
        curve = LearningCurve.from_matrices(steps=ones, decisions=ones, returns=nan,
                                            discounted_returns=nan,
                                            eval_value=np.zeros((runs, episodes)),
                                            value_gap=np.zeros((runs, episodes)))
        return Result(Q, curve, seed)


@hookimpl
def register_learners(register):
    register(UniformLearner)
'''


def run(*args: str):
    return CliRunner().invoke(cli, list(args), catch_exceptions=False)


def test_version():
    result = run("--version")
    assert result.exit_code == 0
    assert __version__ in result.output


def test_plugins_json_lists_builtins_with_packages():
    result = run("plugins", "--json")
    assert result.exit_code == 0, result.output
    rows = json.loads(result.output)
    by_name = {(r["kind"], r["name"]): r for r in rows}
    assert by_name[("learner", "q-learning")]["package"] == "adpart"
    assert {"alpha", "epsilon"} <= {p["name"] for p in by_name[("learner", "q-learning")]["params"]}
    assert ("executor", "local") in by_name
    assert ("environment", "four-rooms") in by_name


def test_plugins_kind_filter_table():
    result = run("plugins", "--kind", "learner")
    assert result.exit_code == 0
    assert "q-learning" in result.output and "value-iteration" in result.output
    assert "local" not in result.output


def test_envs_json_reports_documented_sizes():
    result = run("envs", "--json")
    assert result.exit_code == 0, result.output
    rows = {r["name"]: r for r in json.loads(result.output)}
    assert rows["four-rooms"]["states"] == 104
    assert rows["taxi"]["states"] == 500
    assert "G1" in rows["four-rooms"]["tasks"]
    table = run("envs")
    assert "two-rooms" in table.output and "gym:Taxi-v4" in table.output


def test_env_show_writes_png_with_values(tmp_path):
    out = tmp_path / "maps" / "four.png"
    result = run("env", "show", "four-rooms", "--task", "G1", "--out", str(out), "--json")
    assert result.exit_code == 0, result.output
    info = json.loads(result.output)
    assert info["states"] == 104 and info["png"] == str(out)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_learn_writes_curve_policy_plot_summary(tmp_path):
    out = tmp_path / "run"
    result = run(
        "learn",
        "two-rooms",
        "--task",
        "reach-goal",
        "--runs",
        "3",
        "--episodes",
        "40",
        "--eval-every",
        "10",
        "--seed",
        "5",
        "--out",
        str(out),
        "--json",
        "--epsilon",
        "0.2",
    )
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    assert summary["runs"] == 3 and summary["episodes"] == 40 and summary["states"] == 55
    assert summary["params"]["epsilon"] == "0.2"
    curve = pq.read_table(out / "curve.parquet").to_pydict()
    assert len(curve["run"]) == 3 * 40
    policy = pq.read_table(out / "policy.parquet").to_pydict()
    assert len(policy["state"]) == 3 * 55
    assert (out / "curve.png").read_bytes()[:4] == b"\x89PNG"
    assert json.loads((out / "summary.json").read_text()) == summary
    # the final gaps equal an independent evaluation of the stored greedy policies: a dense
    # linear solve (I - gamma P_pi) V = R_pi per run against plain value iteration's V*
    mdp = get_domain("two-rooms").mdp("reach-goal")
    S, live = mdp.n_states, ~mdp.terminal
    mu = mdp.initial * live / (mdp.initial * live).sum()
    P = mdp.P.toarray().reshape(mdp.n_actions, S, S)
    V = np.zeros(S)
    for _ in range(10_000):
        V = np.where(live, np.max(np.where(mdp.admissible.T, mdp.R.T + mdp.gamma * P @ V,
                                           -np.inf), axis=0), 0.0)
    actions = np.array(policy["action"]).reshape(3, S)
    gaps = []
    for pi in actions:
        P_pi, R_pi = P[pi, np.arange(S)] * live[:, None], mdp.R[np.arange(S), pi] * live
        V_pi = np.linalg.solve(np.eye(S) - mdp.gamma * P_pi, R_pi)
        gaps.append(mu @ V - mu @ V_pi)
    stored = np.array(curve["value_gap"]).reshape(3, 40)[:, -1]
    np.testing.assert_allclose(stored, gaps, atol=1e-6)
    assert summary["final_value_gap"]["max"] == pytest.approx(max(gaps), abs=1e-6)


def test_learn_same_seed_is_bit_identical_and_batches_are_executor_independent(tmp_path):
    args = [
        "learn",
        "two-rooms",
        "--runs",
        "4",
        "--episodes",
        "20",
        "--seed",
        "3",
        "--json",
        "--runs-per-batch",
        "2",
    ]
    a = run(*args, "--out", str(tmp_path / "a"), "--executor", "serial")
    b = run(*args, "--out", str(tmp_path / "b"), "--executor", "local")
    assert a.exit_code == 0 and b.exit_code == 0, a.output + b.output
    ta = pq.read_table(tmp_path / "a" / "curve.parquet").to_pydict()
    tb = pq.read_table(tmp_path / "b" / "curve.parquet").to_pydict()
    assert ta.keys() == tb.keys()
    for column in ta:
        np.testing.assert_array_equal(np.array(ta[column]), np.array(tb[column]))
    assert json.loads(a.output)["batch_seeds"] == json.loads(b.output)["batch_seeds"]


def test_learn_value_iteration_reference(tmp_path):
    result = run(
        "learn",
        "four-rooms",
        "--task",
        "G1",
        "--learner",
        "value-iteration",
        "--episodes",
        "60",
        "--out",
        str(tmp_path / "vi"),
        "--json",
    )
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    assert summary["runs"] == 1
    assert summary["final_value_gap"]["max"] < 1e-6


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["learn", "five-rooms"],
            "no environment named 'five-rooms'.*Did you mean 'four-rooms'.*gym:<id>",
        ),
        (
            ["learn", "two-rooms", "--task", "reach-gaol"],
            "no task 'reach-gaol'.*Did you mean 'reach-goal'",
        ),
        (
            ["learn", "two-rooms", "--learner", "q-lerning"],
            "no learner named 'q-lerning'.*Did you mean 'q-learning'",
        ),
        (
            ["learn", "two-rooms", "--learner", "value-iteration", "--alpha", "0.1"],
            "--alpha is not a parameter of learner 'value-iteration'",
        ),
        (["learn", "two-rooms", "--max-steps", "many"], "--max-steps expects int, got 'many'"),
        (["learn", "two-rooms", "--alpha", "fast"], "cannot read a schedule from 'fast'"),
        (["learn", "two-rooms", "--kernel", "gpu"], "--kernel must be one of"),
        (["learn", "two-rooms", "--executor", "cluster"], "no executor named 'cluster'"),
        (["learn", "two-rooms", "--task", "goal:x=99"], "no state matches the goal"),
        (["env", "show", "gym:NoSuchEnv-v9"], "NoSuchEnv"),
    ],
)
def test_errors_exit_2_with_one_line(args, message, tmp_path):
    result = CliRunner().invoke(
        cli, [*args, "--out", str(tmp_path / "o")] if args[0] == "learn" else args
    )
    assert result.exit_code == 2, result.output
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1, result.output
    assert lines[0].startswith("Error: ")
    import re

    assert re.search(message, lines[0]), lines[0]


def test_third_party_learner_is_listed_and_used_by_learn(tmp_path, monkeypatch):
    site = tmp_path / "site"
    install_fake_distribution(site, "fake-adpart-learner", "fake_adpart_learner", FAKE_LEARNER)
    monkeypatch.syspath_prepend(str(site))
    reset_registry()
    try:
        listed = run("plugins", "--kind", "learner")
        assert "constant-q" in listed.output and "fake-adpart-learner 0.1" in listed.output
        # the default learner's help loads no third-party plugin: it says where to find them
        help_text = run("learn", "--help").output
        assert "--level" not in help_text and "adpart plugins --kind learner" in " ".join(
            help_text.split())
        help_text = run("learn", "--learner", "constant-q", "--help").output
        assert "--level" in help_text and "learner 'constant-q' takes --level" in help_text
        result = run(
            "learn",
            "two-rooms",
            "--learner",
            "constant-q",
            "--level",
            "2.5",
            "--runs",
            "2",
            "--episodes",
            "3",
            "--out",
            str(tmp_path / "o"),
            "--json",
        )
        assert result.exit_code == 0, result.output
        summary = json.loads(result.output)
        assert summary["learner_package"] == "fake-adpart-learner"
        assert summary["params"] == {"level": 2.5}
        values = pq.read_table(tmp_path / "o" / "policy.parquet")["value"].to_numpy()
        assert np.all(values == 2.5)
    finally:
        reset_registry()


def test_broken_plugin_shows_warning_and_cli_still_works(tmp_path, monkeypatch):
    site = tmp_path / "site"
    install_fake_distribution(
        site, "fake-adpart-broken2", "fake_adpart_broken2", "raise RuntimeError('bad build')\n"
    )
    monkeypatch.syspath_prepend(str(site))
    reset_registry()
    try:
        result = CliRunner().invoke(cli, ["plugins", "--kind", "learner"])
        assert result.exit_code == 0
        assert "Warning: plugin package 'fake-adpart-broken2' failed to import" in result.output
        assert "q-learning" in result.output
    finally:
        reset_registry()


def test_learn_records_policies_and_run_in_the_knowledge_base(tmp_path):
    kb_dir = tmp_path / "kb"
    result = run(
        "learn",
        "two-rooms",
        "--runs",
        "2",
        "--episodes",
        "15",
        "--seed",
        "4",
        "--out",
        str(tmp_path / "o"),
        "--kb",
        str(kb_dir),
        "--json",
    )
    assert result.exit_code == 0, result.output
    ids = json.loads(result.output)["kb"]
    assert len(ids["policies"]) == 2
    from adpart.store import KnowledgeBase

    kb = KnowledgeBase.open(str(kb_dir))
    try:
        run_rec = kb.get("run", int(ids["run"].split(":")[1]))
        assert run_rec.learner == "q-learning" and run_rec.seed == 4
        curve = kb.load(run_rec, "curve")
        assert curve.num_rows == 2 * 15
        policy = kb.get("policy", int(ids["policies"][1].split(":")[1]))
        stored_pi = kb.load(policy, "pi")
        written = pq.read_table(tmp_path / "o" / "policy.parquet").to_pydict()
        np.testing.assert_array_equal(
            stored_pi, np.array(written["action"])[np.array(written["run"]) == 1]
        )
        env = kb.get(
            "environment", run_rec.task_id and kb.get("task", run_rec.task_id).environment_id
        )
        assert env.n_states == 55
    finally:
        kb.close()
    again = run(
        "learn",
        "two-rooms",
        "--runs",
        "1",
        "--episodes",
        "5",
        "--out",
        str(tmp_path / "p"),
        "--kb",
        str(kb_dir),
        "--json",
    )
    assert json.loads(again.output)["kb"]["task"] == ids["task"]  # same task record reused


def test_learn_does_not_record_the_same_request_twice(tmp_path):
    kb_dir = tmp_path / "kb"
    args = ["learn", "two-rooms", "--runs", "2", "--episodes", "10", "--seed", "3",
            "--kb", str(kb_dir), "--json"]
    first = json.loads(run(*args, "--out", str(tmp_path / "a")).output)["kb"]
    second = json.loads(run(*args, "--out", str(tmp_path / "b")).output)["kb"]
    assert second.pop("already_stored") is True and "already_stored" not in first
    assert second == first
    other = json.loads(run(*args[:-1], "--seed", "4", "--json", "--out", str(tmp_path / "c"))
                       .output)["kb"]
    assert other["run"] != first["run"]  # another seed is another run
    text = run(*args[:-1], "--out", str(tmp_path / "d")).output
    assert f"already stored in {kb_dir}: {first['run']}" in text
    from adpart.store import KnowledgeBase

    kb = KnowledgeBase.open(str(kb_dir))
    try:
        assert len(kb.records("run")) == 2
    finally:
        kb.close()


def test_learn_no_store_leaves_the_knowledge_base_alone(tmp_path):
    kb_dir = tmp_path / "kb"
    result = run(
        "learn",
        "two-rooms",
        "--runs",
        "1",
        "--episodes",
        "5",
        "--out",
        str(tmp_path / "o"),
        "--kb",
        str(kb_dir),
        "--no-store",
        "--json",
    )
    assert result.exit_code == 0
    assert "kb" not in json.loads(result.output)
    assert not kb_dir.exists()

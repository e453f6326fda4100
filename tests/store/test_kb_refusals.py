"""Impossible numbers and broken knowledge bases are refused before any work, in one line.

Each case is a row of docs/reliability.md's bad-input table: the message names the problem and
the option or field to fix, the exit status is 2, and nothing is created or stored first.
"""

from __future__ import annotations

import os
import textwrap

import numpy as np
import pytest
from click.testing import CliRunner
from sqlalchemy import create_engine, text

from adpart.cli import cli
from adpart.cli.kb import kb as kb_group
from adpart.store import KnowledgeBase, StoreError
from adpart.workflows.sweep import MAX_SEEDS, SweepConfigError, parse_config

HUGE = str(10**23)


def _cli(*args: str):
    return CliRunner().invoke(cli, list(args))


def _one_line(result, code: int = 2) -> str:
    assert result.exit_code == code, result.output
    assert "Traceback" not in result.output
    assert len(result.output.strip().splitlines()) == 1, result.output
    return result.output


# ------------------------------------------------------------------ counts at parse
@pytest.mark.parametrize(("option", "bound"), [
    ("--episodes", "must be <= 10000000"), ("--max-steps", "must be <= 1000000000"),
    ("--eval-every", "must be <= 10000000"), ("--runs", "must be <= 100000"),
    ("--seed", "must be <= 9223372036854775807"),
])
def test_learn_refuses_impossible_counts_before_making_the_kb(tmp_path, option, bound):
    value = HUGE if option != "--seed" else "18446744073709551617"
    out = _one_line(_cli("learn", "two-rooms", "--kb", str(tmp_path / "kb"), "--out",
                         str(tmp_path / "out"), option, value, "-q"))
    assert option in out and bound in out
    assert not (tmp_path / "kb").exists() and not (tmp_path / "out").exists()


@pytest.mark.parametrize(("config", "message"), [
    ({"seeds": 10**9}, rf"`seeds` as a count must be in \[1, {MAX_SEEDS}\], got 1000000000"),
    ({"seeds": [0], "runs": 10**12}, r"`runs` must be an integer in \[1, 100000\]"),
    ({"seeds": [0], "episodes": 10**23}, r"`episodes` must be an integer in \[1, 10000000\]"),
    ({"seeds": [2**64]}, r"`seeds\[0\]` must be an integer in \[0, 9223372036854775807\]"),
    ({"seeds": list(range(MAX_SEEDS + 1))}, rf"lists {MAX_SEEDS + 1} seeds; at most"),
])
def test_sweep_config_bounds_every_count_at_parse(config, message):
    with pytest.raises(SweepConfigError, match=message):
        parse_config({"environments": ["two-rooms"], **config})


def test_a_sweep_of_a_billion_seeds_is_refused_at_once(tmp_path):
    path = tmp_path / "huge.toml"
    path.write_text('seeds = 1000000000\nenvironments = ["two-rooms"]\n')
    out = _one_line(_cli("sweep", str(path), "--dry-run", "--kb", str(tmp_path / "kb")))
    assert "`seeds` as a count must be in [1, 100000]" in out
    assert not (tmp_path / "kb").exists()


# ------------------------------------------------------------------ the trust model of names
def test_a_config_file_imports_only_the_modules_it_lists(tmp_path):
    with pytest.raises(SweepConfigError, match=r"imports the Python module 'this'.*"
                                               r'allow_imports = \["this"\]'):
        parse_config({"seeds": 1, "environments": ["gym:this:X-v0"]})
    path = tmp_path / "sweep.toml"
    path.write_text('seeds = 1\nenvironments = ["gym:this:X-v0"]\n')
    out = _one_line(_cli("sweep", str(path), "--dry-run", "--kb", str(tmp_path / "kb")))
    assert "allow_imports" in out and "Zen of Python" not in out  # `this` was not imported
    config = parse_config({"seeds": 1, "environments": ["gym:this:X-v0"],
                           "allow_imports": ["this"]})
    assert config.environments[0].name == "gym:this:X-v0"
    with pytest.raises(SweepConfigError, match="`allow_imports` must be a list"):
        parse_config({"seeds": 1, "environments": ["two-rooms"], "allow_imports": "this"})


# ------------------------------------------------------------------ locations and schemas
def test_a_malformed_kb_url_is_one_line(tmp_path):
    out = _one_line(CliRunner().invoke(kb_group, ["info", "--kb", "a+b://[::1"]))
    assert "is not a database URL or a directory" in out and "--kb" in out


def _sql(where, *statements: str) -> None:
    engine = create_engine(where.db_url)
    with engine.begin() as conn:
        for statement in statements:
            conn.execute(text(statement))
    engine.dispose()


def test_a_dropped_row_hash_column_is_refused_at_open(where):
    where.open().close()
    _sql(where, "ALTER TABLE policies DROP COLUMN row_sha")
    with pytest.raises(StoreError, match=r"table policies has no column row_sha.*restore"):
        where.open()
    out = _one_line(CliRunner().invoke(kb_group, ["info", *where.cli]))
    assert "has no column row_sha" in out


def test_a_second_schema_row_is_refused(where):
    where.open().close()
    _sql(where, "INSERT INTO adpart_schema (id, version, written_by) VALUES (2, 1, 'x')")
    with pytest.raises(StoreError, match="2 adpart schema rows where there is exactly one"):
        where.open()
    _one_line(CliRunner().invoke(kb_group, ["ls", *where.cli]))


def test_upgrade_of_a_tampered_version_is_a_clean_message(where):
    where.open().close()
    _sql(where, "UPDATE adpart_schema SET version = 1")  # the tables are the current ones
    out = _one_line(CliRunner().invoke(kb_group, ["upgrade", *where.cli]))
    assert "do not match the schema version it records" in out and "[SQL:" not in out
    with pytest.raises(StoreError, match="run `adpart kb upgrade`"):
        where.open()  # left unchanged


# ------------------------------------------------------------------ the API's puts
@pytest.mark.parametrize(("call", "message"), [
    (lambda kb, env: kb.put_task(env, "t", spec={}, gamma=float("nan")),
     r"put_task: gamma = nan must be a finite number in \[0, 1\]"),
    (lambda kb, env: kb.put_task(env, "t", spec={}, gamma=-5),
     r"put_task: gamma = -5 must be a finite number in \[0, 1\]"),
    (lambda kb, env: kb.put_task(env, "\x00" * 1_000_000, spec={}, gamma=0.9),
     "put_task: name has 1000000 characters; at most 255"),
    (lambda kb, env: kb.put_task(env, "a\x00b", spec={}, gamma=0.9),
     "put_task: name contains a NUL character"),
    (lambda kb, env: kb.put_environment("e2", model_hash="f" * 64, n_states=-5, n_actions=2),
     r"put_environment: n_states = -5 is outside \[1, "),
    (lambda kb, env: kb.put_environment("e2", model_hash="f" * 64, n_states=3, n_actions=0),
     r"put_environment: n_actions = 0 is outside \[1, "),
    (lambda kb, env: kb.put_run(1, "q", seed=2**64, curve={"x": np.arange(3)}),
     r"put_run: seed = 18446744073709551616 is outside"),
    (lambda kb, env: kb.put_option(env, "o", initiation=np.ones(4, bool),
                                   policy=np.zeros(4, int), termination=np.ones(4),
                                   gamma=float("inf")),
     r"put_option: gamma = inf must be a finite number"),
])
def test_puts_refuse_impossible_values_naming_the_field(kb, call, message):
    env = kb.put_environment("e", model_hash="a" * 64, n_states=4, n_actions=2)
    kb.put_task(env, "t0", spec={}, gamma=0.9)
    before = (kb.counts(), sorted(os.listdir(kb.artifacts.base)))
    with pytest.raises(StoreError, match=message):
        call(kb, env)
    assert (kb.counts(), sorted(os.listdir(kb.artifacts.base))) == before  # nothing written


# ------------------------------------------------------------------ --out and symlinks
def test_export_does_not_write_through_a_symlink(tmp_path, kb, where):
    env = kb.put_environment("e", model_hash="a" * 64, n_states=4, n_actions=2)
    task = kb.put_task(env, "t", spec={}, gamma=0.9)
    policy = kb.put_policy(task, "q", q=np.zeros((4, 2)))
    canary = tmp_path / "canary.csv"
    canary.write_text("keep me\n")
    link = tmp_path / "q.csv"
    link.symlink_to(canary)
    out = _one_line(CliRunner().invoke(kb_group, ["export", f"policy:{policy.id}", "--field",
                                                  "q", "--out", str(link), *where.cli]))
    assert "is a symbolic link" in out
    assert canary.read_text() == "keep me\n"


def test_the_kb_docstring_names_only_methods_that_exist():
    doc = textwrap.dedent(KnowledgeBase.__doc__ or "")
    for name in ("get_ref",):
        assert name not in doc
    for name in ("get", "artifact", "records", "find_environment", "load", "check", "gc"):
        assert f"``{name}" in doc and hasattr(KnowledgeBase, name)


def test_learn_of_an_unknown_gym_module_names_it(tmp_path):
    out = _cli("learn", "gym:no_such_module_here:X-v0", "--kb", str(tmp_path / "kb"), "-q")
    assert out.exit_code == 2 and "cannot import module 'no_such_module_here'" in out.output


@pytest.mark.parametrize(("field", "value"), [("epsilon", float("nan")), ("epsilon", -1.0),
                                               ("delta", 1.5), ("delta", float("nan"))])
def test_put_partition_refuses_a_threshold_out_of_range_naming_it(tmp_path, field, value):
    with KnowledgeBase.open(tmp_path / "kb") as kb:
        env = kb.put_environment("e", model_hash="a" * 64, n_states=2, n_actions=2)
        given = {"epsilon": 0.0, "delta": 0.0, field: value}
        with pytest.raises(StoreError, match=f"put_partition: {field}"):
            kb.put_partition(env, "per-option", [0, 1], **given)
        assert kb.counts().get("partition", 0) == 0
        kb.put_partition(env, "per-option", [0, 1], epsilon=float("inf"), delta=1.0)  # the ends

"""Bad input is refused before anything is computed or stored, naming the option to fix.

Each case here is a row of docs/reliability.md's bad-input table.
"""

from __future__ import annotations

import os
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from adpart.cli import cli
from adpart.cli.kb import kb as kb_group
from adpart.errors import UnknownNameError
from adpart.store import KnowledgeBase, StoreError
from adpart.workflows.sweep import SweepConfigError, parse_config, plan_cells

PIPELINE = ["pipeline", "three-floor", "--tasks", "reach-goal,reach-top-west", "--runs", "1",
            "--episodes", "5", "--first-episodes", "5", "-q"]


def _cli(*args: str):
    return CliRunner().invoke(cli, list(args))


@pytest.mark.parametrize(("args", "message"), [
    (["--delta", "-0.1"], "--delta = -0.1 is outside [0, 1]"),
    (["--delta", "nan"], "--delta = nan must be a finite number (nan and inf are refused)"),
    (["--reward-epsilon", "inf"], "--reward-epsilon = inf must be a finite number"),
    (["--hier-opt", "bogus=1"], "--hier-opt: learner 'hierarchical' has no parameter --bogus"),
    (["--hier-opt", "threshold-scale=nan"],
     "--hier-opt: learner 'hierarchical': --threshold-scale must be a finite number"),
    (["--hier-opt", "partition-epsilon=nan"],
     "--hier-opt: learner 'hierarchical': --partition-epsilon must be a finite number"),
    (["--hier-opt", "delta=nan"], "--hier-opt: learner 'hierarchical': --delta must be a finite"),
    (["--flat-opt", "epsilon=-1"],
     "--flat-opt: learner 'q-learning': --epsilon '-1': schedule scale = -1.0 must be >= 0"),
    (["--detector-opt", "p=nan"], "--detector-opt: subgoal-detector"),
])
def test_pipeline_refuses_bad_values_before_storing_anything(tmp_path, args, message):
    kb_dir = tmp_path / "kb"
    result = _cli(*PIPELINE, "--kb", str(kb_dir), "--out", str(tmp_path / "out"), *args)
    assert result.exit_code == 2, result.output
    assert message in result.output
    assert "Traceback" not in result.output
    assert not kb_dir.exists()  # nothing opened, nothing stored


def test_transfer_refuses_a_bad_hier_opt_before_opening_the_kb(tmp_path):
    result = _cli("transfer", "three-floor", "--task", "reach-top-west", "--partition",
                  "partition:1", "--hier-opt", "threshold-scale=nan", "--kb", str(tmp_path / "kb"))
    assert result.exit_code == 2, result.output
    assert "--hier-opt: learner 'hierarchical': --threshold-scale must be a finite" in result.output
    assert not (tmp_path / "kb").exists()


@pytest.mark.parametrize(("args", "message"), [
    (["--epsilon", "-1"], "learner 'q-learning': --epsilon '-1': schedule scale = -1.0 must be"),
    (["--alpha", "nan"], "learner 'q-learning': --alpha 'nan': cannot read a schedule"),
    (["--q-init", "nan"], "learner 'q-learning': --q-init must be a finite number; got 'nan'"),
])
def test_learn_names_the_option(tmp_path, args, message):
    result = _cli("learn", "two-rooms", "--runs", "1", "--episodes", "5", "--kb",
                  str(tmp_path / "kb"), "--out", str(tmp_path / "out"), *args)
    assert result.exit_code == 2, result.output
    assert message in result.output
    assert not (tmp_path / "kb").exists() and not (tmp_path / "out").exists()


@pytest.mark.parametrize("value", ["nan", "inf", "-1"])
def test_partition_delta_must_be_finite(tmp_path, value):
    result = _cli("partition", "two-rooms", "--options", "primitive", "--delta", value,
                  "--kb", str(tmp_path / "kb"))
    assert result.exit_code == 2
    assert f"--delta = {value} " in result.output
    assert len(result.output.strip().splitlines()) == 1
    assert not (tmp_path / "kb").exists()


def test_sweep_config_with_nan_fails_the_config_check():
    config = parse_config({"seeds": [0], "environments": ["two-rooms"], "runs": 1,
                           "episodes": 5, "params": {"alpha": ["nan"]}})
    with pytest.raises(SweepConfigError, match=r"`params.alpha`: .*--alpha 'nan'"):
        plan_cells(config)


def test_gc_ages_must_be_finite(tmp_path):
    for option in ("--grace", "--tmp-age"):
        result = CliRunner().invoke(kb_group, ["gc", option, "nan", "--kb", str(tmp_path)])
        assert result.exit_code == 2
        assert f"{option} = nan must be a finite number" in result.output


# ---------------------------------------------------------------------- reading commands
def test_reading_commands_never_create_a_knowledge_base(tmp_path):
    new = tmp_path / "no-kb-here"
    out = tmp_path / "out.csv"
    reads = (["info"], ["ls"], ["ls", "run", "--json"], ["check"], ["show", "run:1"],
             ["export", "run:1", "--out", str(out)])
    for args in reads:
        result = CliRunner().invoke(kb_group, [*args, "--kb", str(new)])
        assert result.exit_code == 2, result.output
        assert "there is no knowledge base directory" in result.output
        assert "never create" in result.output and "adpart learn ENV --kb" in result.output
        assert "Traceback" not in result.output
    assert not new.exists() and not out.exists()
    new.mkdir()
    for args in reads:
        result = CliRunner().invoke(kb_group, [*args, "--kb", str(new)])
        assert result.exit_code == 2 and "holds no knowledge base" in result.output
        assert "adpart learn ENV --kb" in result.output
    for args in reads:  # a sqlite URL whose file is missing
        result = CliRunner().invoke(kb_group, [*args, "--kb", f"sqlite:///{new}/kb.sqlite"])
        assert result.exit_code == 2 and "no knowledge base database" in result.output
    assert list(new.iterdir()) == [] and not out.exists()


def test_a_read_only_knowledge_base_can_be_inspected(tmp_path, monkeypatch):
    with KnowledgeBase.open(tmp_path / "kb") as kb:
        env = kb.put_environment("e", model_hash="a" * 64, n_states=2, n_actions=2)
        task = kb.put_task(env, "t", spec={}, gamma=0.9)
        run = kb.put_run(task, "q", curve={"gap": np.ones(3)})
    def files() -> list[str]:  # SQLite's own -wal/-shm reader files aside
        return sorted(p.name for p in (tmp_path / "kb").rglob("*")
                      if not p.name.endswith(("-wal", "-shm")))

    before = files()
    real_access = os.access
    monkeypatch.setattr(os, "access", lambda p, mode, **kw: (
        False if mode & os.W_OK else real_access(p, mode, **kw)))
    opts = ["--kb", str(tmp_path / "kb")]
    for args in (["info"], ["ls"], ["show", f"run:{run.id}"], ["check"],
                 ["export", f"run:{run.id}", "--out", str(tmp_path / "curve.csv")]):
        result = CliRunner().invoke(kb_group, [*args, *opts])
        assert result.exit_code == 0, (args, result.output)
    assert (tmp_path / "curve.csv").exists()
    assert files() == before
    with (KnowledgeBase.open(tmp_path / "kb", read_only=True) as kb,
          pytest.raises(StoreError, match="opened read-only")):
        kb.put_run(task, "q")


# ---------------------------------------------------------------------- re-creating records
def test_a_damaged_run_can_be_re_created(tmp_path):
    kb_dir, out = str(tmp_path / "kb"), str(tmp_path / "out")
    learn = ["learn", "two-rooms", "--runs", "1", "--episodes", "5", "--eval-every", "5", "-q",
             "--kb", kb_dir, "--out", out]
    assert _cli(*learn).exit_code == 0
    with KnowledgeBase.open(kb_dir) as kb:
        run = kb.records("run")[0]
        path = Path(kb.artifacts.base) / kb.artifacts.uri_for(run.curve)
    path.write_bytes(b"garbage")
    result = _cli(*learn)
    assert result.exit_code == 2, result.output
    assert f"run:{run.id} is already stored but damaged" in result.output
    assert "--force" in result.output and f"adpart kb rm run:{run.id}" in result.output
    result = _cli(*learn, "--force")
    assert result.exit_code == 0, result.output
    assert "stored in" in result.output and "already" not in result.output
    # or: remove the damaged record (with its policies) and run again
    result = CliRunner().invoke(kb_group, ["rm", f"run:{run.id}", "--kb", kb_dir])
    assert "would remove" in result.output and "policy:" in result.output
    result = CliRunner().invoke(kb_group, ["rm", f"run:{run.id}", "--yes", "--kb", kb_dir])
    assert result.exit_code == 0, result.output
    with KnowledgeBase.open(kb_dir) as kb:
        assert [r.id for r in kb.records("run")] != [] and run.id not in {
            r.id for r in kb.records("run")}
        kb.gc(delete=True, grace_s=0)
        assert kb.check().ok and kb.check().orphan_records == []


def test_rm_refuses_a_record_others_refer_to(populated, where):
    _, rec = populated
    result = CliRunner().invoke(kb_group, ["rm", f"task:{rec['task'].id}", "--yes", *where.cli])
    assert result.exit_code == 2
    assert "still referred to by other records" in result.output


# ---------------------------------------------------------------------- gym:module:Id
def test_gym_module_prefix_imports_the_module(tmp_path, monkeypatch):
    from adpart.envs.gym_adapter import make_env

    (tmp_path / "adpart_test_gym_mod.py").write_text(textwrap.dedent("""
        import gymnasium
        gymnasium.register(id="AdpartTestLake-v0",
                           entry_point="gymnasium.envs.toy_text:FrozenLakeEnv")
    """))
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "adpart_test_gym_mod", raising=False)
    env = make_env("adpart_test_gym_mod:AdpartTestLake-v0")
    assert env.observation_space.n == 16
    env.close()
    with pytest.raises(UnknownNameError, match="cannot import module 'no_such_module_x'"):
        make_env("no_such_module_x:Foo-v0")

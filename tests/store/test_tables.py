"""The knowledge base as tables (records_table, curves_table, partition_table), on every backend."""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa
import pytest
from click.testing import CliRunner

from adpart.cli.kb import kb as kb_group
from adpart.store import StoreError, open_kb
from adpart.store.tables import BASE_COLUMNS, json_rows, strict_json


def _ls_json(where, *args):
    result = CliRunner().invoke(kb_group, ["ls", *args, "--json", *where.cli])
    assert result.exit_code == 0, result.output
    return json.loads(result.output)


def test_records_table_has_one_row_per_record(populated):
    kb, rec = populated
    table = kb.records_table()
    assert table.column_names[: len(BASE_COLUMNS)] == list(BASE_COLUMNS)
    assert table.schema.field("created").type == pa.timestamp("us", tz="UTC")
    refs = table.column("ref").to_pylist()
    assert refs == ["environment:1", "task:1", rec["policy"].ref, rec["subgoal-set"].ref,
                    rec["option"].ref, rec["p1"].ref, rec["partition"].ref, rec["run"].ref]
    row = {r["ref"]: r for r in table.to_pylist()}
    run = row[rec["run"].ref]
    assert (run["kind"], run["env"], run["task"], run["learner"]) == ("run", "five", "goal-4",
                                                                      "smdp-q")
    assert run["metrics.final_gap"] == 0.25 and run["size"] == kb.artifact(rec["run"].curve).bytes
    policy = row[rec["policy"].ref]
    assert policy["params.alpha"] == 0.1 and policy["task_id"] == rec["task"].id
    assert row[rec["option"].ref]["env"] == "five" and row[rec["option"].ref]["task"] is None
    assert "per-option blocks=3" in row[rec["p1"].ref]["summary"]
    assert run["summary"] == f"smdp-q partition=partition:{rec['partition'].id}"


def test_records_table_filters(populated):
    kb, rec = populated
    assert kb.records_table("partition").column("ref").to_pylist() == [rec["p1"].ref,
                                                                       rec["partition"].ref]
    # a task's records: its own row, its policy, the partition made for it and its run
    assert kb.records_table(task="goal-4").column("ref").to_pylist() == [
        "task:1", rec["policy"].ref, rec["partition"].ref, rec["run"].ref]
    assert kb.records_table("run", env="five").num_rows == 1
    assert kb.records_table("run", env=rec["environment"].id).num_rows == 1
    assert kb.records_table("run", env="environment:1").num_rows == 1
    assert kb.records_table("policy", where={"alpha": 0.1}).num_rows == 1
    assert kb.records_table("policy", where={"alpha": "0.1"}).num_rows == 1  # as from a CLI
    assert kb.records_table("policy", where={"alpha": 0.2}).num_rows == 0
    assert kb.records_table(limit=3).num_rows == 3
    assert kb.records_table("artifact").num_rows == kb.counts()["artifact"]
    with pytest.raises(StoreError, match=r"no environment 'nope'.*it has five"):
        kb.records_table(env="nope")
    with pytest.raises(StoreError, match=r"no task 'nope'.*goal-4"):
        kb.records_table(task="nope")
    with pytest.raises(StoreError, match=r"no listed record has a parameter 'alpah'.*alpha"):
        kb.records_table("policy", where={"alpah": 1})
    with pytest.raises(StoreError, match="unknown record kind 'runz'"):
        kb.records_table("runz")
    with pytest.raises(StoreError, match="limit must be a positive"):
        kb.records_table(limit=0)


def test_curves_and_partition_tables(populated):
    kb, rec = populated
    curves = kb.curves_table(rec["run"].ref)
    assert curves.column_names == ["run_id", "episode", "gap"]
    assert curves.column("run_id").to_pylist() == [rec["run"].id] * 4
    assert curves.column("gap").to_pylist() == [3.0, 1.0, 0.5, 0.25]
    assert kb.curves_table(kb.records_table("run")).equals(curves)
    assert kb.curves_table().equals(curves)
    assert kb.curves_table([rec["run"]]).equals(curves)
    part = kb.partition_table(rec["partition"].ref)
    assert part.column_names == ["state", "block"]
    assert part.column("block").to_pylist() == kb.load(rec["partition"], "labels").tolist()
    assert kb.partition_table(rec["p1"]).column("block").to_pylist() == [0, 0, 1, 1, 2]
    with pytest.raises(StoreError, match="not a partition"):
        kb.partition_table("run:1")
    with pytest.raises(StoreError, match="either runs or the env"):
        kb.curves_table(rec["run"], env="five")


def test_tables_convert_to_pandas_and_polars(populated):
    kb, rec = populated
    pd = pytest.importorskip("pandas")
    frame = kb.records_table("run").to_pandas()
    assert isinstance(frame, pd.DataFrame) and frame["ref"].tolist() == [rec["run"].ref]
    assert kb.curves_table(rec["run"]).to_pandas()["gap"].iloc[-1] == 0.25
    pl = pytest.importorskip("polars")
    assert pl.from_arrow(kb.partition_table(rec["p1"])).height == 5


def test_ls_json_is_the_records_table(where, populated):
    kb, _ = populated
    assert _ls_json(where) == json_rows(kb.records_table())
    assert _ls_json(where, "run", "--env", "five") == json_rows(kb.records_table("run", env="five"))
    assert _ls_json(where, "--kind", "policy", "--where", "alpha=0.1", "--limit", "1") == \
        json_rows(kb.records_table("policy", where={"alpha": 0.1}, limit=1))
    assert _ls_json(where, "--task", "goal-4") == json_rows(kb.records_table(task="goal-4"))


def test_open_kb_read_only_creates_nothing(tmp_path):
    missing = tmp_path / "none"
    with pytest.raises(StoreError, match=r"never create.*adpart learn"):
        open_kb(missing, read_only=True)
    with pytest.raises(StoreError, match="never create"):
        open_kb(f"sqlite:///{tmp_path}/kb.sqlite", read_only=True)
    assert not missing.exists() and list(tmp_path.iterdir()) == []


def test_strict_json_has_no_nan_or_infinity():
    text = strict_json({"a": float("inf"), "b": [float("nan"), 1.5], "c": np.float64("-inf")})
    assert json.loads(text) == {"a": None, "b": [None, 1.5], "c": None}
    assert "Infinity" not in text and "NaN" not in text


@pytest.mark.parametrize(("args", "message"), [
    (["--where", "alpha"], "--where 'alpha' is not KEY=VALUE"),
    (["--where", "alpah=1"], "no listed record has a parameter 'alpah'"),
    (["--limit", "0"], "--limit"),
    (["--kind", "runz"], "unknown record kind 'runz'"),
    (["run", "--kind", "policy"], "disagree"),
    (["--env", "nope"], "no environment 'nope'"),
    (["--task", "nope"], "no task 'nope'"),
    (["artifact", "--env", "five"], "artifacts belong to no environment"),
])
def test_ls_bad_input_names_the_option(where, populated, args, message):
    result = CliRunner().invoke(kb_group, ["ls", *args, *where.cli])
    assert result.exit_code == 2, result.output
    assert message in result.output and "Traceback" not in result.output


def test_ls_and_show_text(where, populated):
    _, rec = populated
    lines = CliRunner().invoke(kb_group, ["ls", "--kind", "partition", *where.cli]).output
    rows = lines.splitlines()
    assert [r.split()[0] for r in rows] == ["ID", rec["p1"].ref, rec["partition"].ref]
    assert rows[1].index("per-option") == rows[0].index("SUMMARY")  # aligned columns
    none = CliRunner().invoke(kb_group, ["ls", "run", "--where", "alpha=9", *where.cli])
    assert none.exit_code == 2 or none.output.strip() == "no records match"
    shown = CliRunner().invoke(kb_group, ["show", rec["partition"].ref, *where.cli]).output
    lines = shown.splitlines()
    assert lines[0] == rec["partition"].ref
    assert lines[1].startswith("  environment:") and lines[1].endswith(" five (environment:1)")
    assert "artifacts:" in lines and "provenance:" in lines
    assert any(ln.startswith("  labels:") and "<i8 5 " in ln for ln in lines)
    assert any(ln.startswith("  parent_ids:") and "[" in ln for ln in lines)

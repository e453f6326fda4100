"""Whole records, checks that see everything, and schema creation under concurrent opens."""

from __future__ import annotations

import hashlib
import json
import math
import sqlite3
import subprocess
import sys
import textwrap
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from sqlalchemy import create_engine, select, text, update

from adpart.cli.kb import kb as kb_group
from adpart.store import SCHEMA_VERSION, StoreError
from adpart.store.models import HASHED_TABLES, partition_parents
from adpart.workflows import record_learning, run_learning
from adpart.workflows.learning import LearnRequest

KILLED_RECORD = """
    import os, signal, sys
    from adpart.store import KnowledgeBase
    from adpart.workflows import record_learning, run_learning
    from adpart.workflows.learning import LearnRequest
    kb = KnowledgeBase.open(sys.argv[1], artifacts=sys.argv[2] or None)
    outcome = run_learning(LearnRequest(env="two-rooms", runs=2, episodes=5, eval_every=5))
    def killed(*args, **kwargs):  # the policies are written; die before the run is
        os.kill(os.getpid(), signal.SIGKILL)
    KnowledgeBase.put_run = killed
    record_learning(kb, outcome)
"""


def test_a_failure_between_policies_and_run_leaves_no_dangling_record(kb, monkeypatch):
    outcome = run_learning(LearnRequest(env="two-rooms", runs=2, episodes=5, eval_every=5))

    def fail(*args, **kwargs):
        raise StoreError("simulated failure after the policies were written")

    monkeypatch.setattr(kb, "put_run", fail)
    with pytest.raises(StoreError, match="simulated"):
        record_learning(kb, outcome)
    assert kb.counts()["policy"] == 0 and kb.counts()["run"] == 0
    assert kb.check().orphan_records == []
    monkeypatch.undo()
    ids = record_learning(kb, outcome)
    assert len(ids["policies"]) == 2 and kb.check().ok


@pytest.mark.slow
def test_a_kill_between_policies_and_run_leaves_no_dangling_record(where):
    where.open().close()
    proc = subprocess.run([sys.executable, "-c", textwrap.dedent(KILLED_RECORD), where.location,
                           where.artifacts], capture_output=True, text=True, timeout=300,
                          check=False)
    assert proc.returncode == -9, proc.stderr
    with where.open() as kb:
        assert kb.counts()["policy"] == 0 and kb.counts()["run"] == 0
        report = kb.check()
        assert report.ok, report.problems
        assert report.orphan_records == []


def test_orphan_policies_are_named_by_check_and_removed_by_gc(where, kb):
    env = kb.put_environment("e", model_hash="a" * 64, n_states=2, n_actions=2)
    task = kb.put_task(env, "t", spec={}, gamma=0.9)
    lone = kb.put_policy(task, "q-learning", q=np.ones((2, 2)))  # as a killed old write left it
    kept = kb.put_policy(task, "q-learning", q=np.zeros((2, 2)))
    kb.put_run(task, "q-learning", parameters={"policies": [kept.id]})
    assert kb.check().orphan_records == [f"policy:{lone.id}"]
    result = CliRunner().invoke(kb_group, ["check", *where.cli])
    assert result.exit_code == 0, result.output
    assert f"orphan record policy:{lone.id}" in result.output
    dry = CliRunner().invoke(kb_group, ["gc", "--yes", *where.cli])
    assert "pass --orphans" in dry.output and kb.counts()["policy"] == 2
    result = CliRunner().invoke(kb_group, ["gc", "--yes", "--orphans", *where.cli])
    assert result.exit_code == 0, result.output
    assert [p.id for p in kb.records("policy")] == [kept.id]
    assert kb.check().ok and kb.check().orphan_records == []


def test_transaction_stores_all_or_nothing(kb):
    env = kb.put_environment("e", model_hash="b" * 64, n_states=2, n_actions=2)
    task = kb.put_task(env, "t", spec={}, gamma=0.9)
    with pytest.raises(StoreError), kb.transaction():
        kb.put_policy(task, "q", q=np.ones((2, 2)))
        kb.put_run(999, "q")  # no such task: the whole group goes
    assert kb.counts()["policy"] == 0
    with kb.transaction():
        policy = kb.put_policy(task, "q", q=np.ones((2, 2)))
        kb.put_run(task, "q", parameters={"policies": [policy.id]})
    assert kb.counts()["policy"] == 1 and kb.counts()["run"] == 1


# ---------------------------------------------------------------------- check sees everything
def _sqlite_file(where) -> Path:
    return Path(where.location) / "kb.sqlite"


def test_check_names_the_record_whose_metadata_row_changed(where, populated):
    kb, rec = populated
    run = rec["run"]
    # change a stored value behind adpart's back, as a flipped bit would
    with kb.engine.begin() as conn:
        conn.execute(text("UPDATE runs SET metrics = :m WHERE id = :i"),
                     {"m": '{"final_gap": 0.35}', "i": run.id})
    report = kb.check()
    assert not report.ok
    assert [p for p in report.problems if f"run:{run.id} is damaged" in p], report.problems
    result = CliRunner().invoke(kb_group, ["check", *where.cli])
    assert result.exit_code == 1 and f"run:{run.id}" in result.output


def test_check_names_a_flipped_bit_in_the_database_file(where, tmp_path):
    if where.backend != "sqlite":
        pytest.skip("the flipped bit is in the SQLite file")
    with where.open() as kb:
        env = kb.put_environment("e", model_hash="c" * 64, n_states=2, n_actions=2)
        task = kb.put_task(env, "t", spec={}, gamma=0.9)
        run = kb.put_run(task, "q", metrics={"final_value_gap": {"mean": 0.248, "max": 0.3}})
    path = _sqlite_file(where)
    with sqlite3.connect(path) as conn:
        conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    data = bytearray(path.read_bytes())
    at = data.find(b"0.248")
    assert at >= 0 and data.count(b"0.248") == 1
    data[at + 2] ^= 0x01  # 0.248 -> 0.348: one bit ("2" is 0x32, "3" is 0x33)
    path.write_bytes(bytes(data))
    with where.open() as kb:
        with pytest.raises(StoreError, match=rf"run:{run.id} is damaged.*row hash mismatch"):
            kb.get("run", run.id)  # reads verify the row hash too: 0.348 is never returned
        report = kb.check()
    assert any(f"run:{run.id} is damaged" in p for p in report.problems), report.problems


@pytest.mark.parametrize("table", ["policies", "runs"])
def test_check_runs_the_engines_integrity_check(where, populated, table):
    if where.backend != "sqlite":
        pytest.skip("zeroes a page of the SQLite file")
    kb, _ = populated
    kb.close()
    path = _sqlite_file(where)
    with sqlite3.connect(path) as conn:
        conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        page_size = conn.execute("PRAGMA page_size").fetchone()[0]
        root = conn.execute("SELECT rootpage FROM sqlite_master WHERE name = ?",
                            (table,)).fetchone()[0]
    data = bytearray(path.read_bytes())
    data[(root - 1) * page_size:root * page_size] = bytes(page_size)
    path.write_bytes(bytes(data))
    result = CliRunner().invoke(kb_group, ["check", *where.cli])
    assert result.exit_code == 1, result.output
    assert "integrity check" in result.output or f"table {table} cannot be read" in result.output


#: What each schema added, newest first: undone to make an older knowledge base again (4
#: changed only the row hashes' encoding: the rows are stamped as schema 3 did, below).
ADDED = {5: [], 4: [], 3: ["ALTER TABLE runs DROP COLUMN experience_sha"],
         2: [f"ALTER TABLE {table} DROP COLUMN row_sha" for table in (
             "artifacts", "environments", "tasks", "policies", "subgoal_sets", "subgoals",
             "options", "partition_options", "partitions", "runs")]}


def _stamp_as_schema_3(conn) -> None:
    """Every row's hash as schema 3 wrote it: the canonical JSON object of each value wrapped
    as ``{"float": repr}``, ``{"datetime": UTC ISO}`` (written out here, not taken from
    adpart)."""
    parents: dict[int, list[int]] = {}
    for child, parent in conn.execute(select(partition_parents.c.child_id,
                                             partition_parents.c.parent_id)):
        parents.setdefault(child, []).append(parent)

    def plain(value):
        if isinstance(value, bool | int | str) or value is None:
            return value
        if isinstance(value, float):
            return {"float": repr(value) if math.isfinite(value) else str(value)}
        if isinstance(value, datetime):
            utc = value.replace(tzinfo=timezone.utc) if value.tzinfo is None else value
            return {"datetime": utc.astimezone(timezone.utc).isoformat()}
        if isinstance(value, dict):
            return {str(k): plain(v) for k, v in value.items()}
        return [plain(v) for v in value]

    for table in HASHED_TABLES:
        names = [c.name for c in table.columns if c.name != "row_sha"]
        for row in conn.execute(select(table)).mappings().all():
            payload = {"table": table.name, "columns": {n: plain(row[n]) for n in names}}
            if table.name == "partitions":
                payload["parents"] = sorted(parents.get(row["id"], []))
            digest = hashlib.sha256(json.dumps(payload, sort_keys=True,
                                               separators=(",", ":")).encode()).hexdigest()
            key = [table.c[c.name] == row[c.name] for c in table.primary_key.columns]
            conn.execute(update(table).where(*key).values(row_sha=digest))


def _stamp_as_schema_4(conn) -> None:
    """Every row's hash as schema 4 wrote it: compact sorted-key JSON of ``[table, [column
    names]]`` followed by that of the list of the row's values, times as whole microseconds
    since the epoch (UTC), a partition's sorted parent ids appended (written out here, not
    taken from adpart)."""
    parents: dict[int, list[int]] = {}
    for child, parent in conn.execute(select(partition_parents.c.child_id,
                                             partition_parents.c.parent_id)):
        parents.setdefault(child, []).append(parent)
    epoch = datetime(1970, 1, 1, tzinfo=timezone.utc)

    def plain(value):
        if isinstance(value, datetime):
            utc = value.replace(tzinfo=timezone.utc) if value.tzinfo is None else value
            return (utc - epoch) // timedelta(microseconds=1)
        return value

    def encode(value) -> bytes:
        return json.dumps(value, sort_keys=True, separators=(",", ":")).encode()

    for table in HASHED_TABLES:
        names = [c.name for c in table.columns if c.name != "row_sha"]
        for row in conn.execute(select(table)).mappings().all():
            values = [plain(row[n]) for n in names]
            if table.name == "partitions":
                values.append(sorted(parents.get(row["id"], [])))
            digest = hashlib.sha256(encode([table.name, names]) + encode(values)).hexdigest()
            key = [table.c[c.name] == row[c.name] for c in table.primary_key.columns]
            conn.execute(update(table).where(*key).values(row_sha=digest))


def _upgraded_from(where, kb, version: int, damage: str | None = None) -> str:
    """Make ``kb`` a schema-``version`` knowledge base again (``damage``: an SQL statement
    run on it then), see it refused, upgrade it; return what ``kb upgrade`` printed."""
    kb.close()
    engine = create_engine(where.db_url)
    with engine.begin() as conn:
        for newer in range(SCHEMA_VERSION, version, -1):
            for statement in ADDED[newer]:
                conn.execute(text(statement))
        if version == 3:
            _stamp_as_schema_3(conn)
        if version == 4:
            _stamp_as_schema_4(conn)
        conn.execute(text(f"UPDATE adpart_schema SET version = {version}"))
        if damage is not None:
            conn.execute(text(damage))
    engine.dispose()
    with pytest.raises(StoreError, match="run `adpart kb upgrade`"):
        where.open()
    result = CliRunner().invoke(kb_group, ["upgrade", *where.cli])
    assert result.exit_code == 0, result.output
    assert f"{version} -> {SCHEMA_VERSION}" in result.output
    return result.output


def test_an_old_schema_is_upgraded_with_row_hashes(where, populated):
    kb, rec = populated
    _upgraded_from(where, kb, 1)
    with where.open() as kb:
        report = kb.check()
        assert report.ok, report.problems
        assert report.rows_checked >= 10
        assert kb.get("run", rec["run"].id) == rec["run"]


def test_a_schema_2_knowledge_base_is_upgraded_with_run_experience(where, populated):
    kb, rec = populated
    _upgraded_from(where, kb, 2)
    with where.open() as kb:
        report = kb.check()
        assert report.ok, report.problems  # the runs' row hashes cover the new column
        run = kb.get("run", rec["run"].id)
        assert run.experience is None and run == rec["run"]
        table = {"state": [0, 0], "action": [1, 1], "next_state": [2, 3], "count": [5, 1]}
        task = kb.get("task", run.task_id)
        again = kb.put_run(task, "q-learning", experience=table)
        assert kb.load(again, "experience").column("count").to_pylist() == [5, 1]
        assert kb.check().ok

@pytest.mark.parametrize("version", [3, 4])
def test_a_schema_3_or_4_knowledge_base_is_upgraded_to_the_new_row_hashes(where, populated,
                                                                          version):
    kb, rec = populated
    _upgraded_from(where, kb, version)
    with where.open() as kb:
        report = kb.check()
        assert report.ok, report.problems
        assert report.rows_checked >= 10
        for name, record in rec.items():
            kind = "partition" if name == "p1" else name
            assert kb.get(kind, record.id) == record


@pytest.mark.parametrize("version", [3, 4])
def test_a_row_damaged_before_the_upgrade_stays_damaged_after_it(where, populated, version):
    kb, rec = populated
    run = rec["run"]
    # a value changed under the old schema: its old hash no longer holds; the upgrade must not
    # stamp the changed row valid
    output = _upgraded_from(where, kb, version, damage="UPDATE runs SET seed = 7 WHERE id = "
                                                       f"{run.id}")
    assert f"run:{run.id}" in output and "stay named as damaged" in output
    with where.open() as kb:
        with pytest.raises(StoreError, match=rf"run:{run.id} is damaged.*row hash mismatch"):
            kb.get("run", run.id)
        report = kb.check()
        assert [p for p in report.problems if f"run:{run.id} is damaged" in p], report.problems
        assert kb.get("policy", rec["policy"].id) == rec["policy"]  # the rest was re-stamped


# ---------------------------------------------------------------------- concurrent first opens
OPENER = """
    import sys
    from adpart.store import KnowledgeBase
    KnowledgeBase.open(sys.argv[1], artifacts=sys.argv[2] or None).close()
    print("ok")
"""


def _first_opens(where) -> None:
    procs = [subprocess.Popen([sys.executable, "-c", textwrap.dedent(OPENER), where.location,
                               where.artifacts], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True) for _ in range(4)]
    outs = [p.communicate(timeout=300) for p in procs]
    failed = [err.strip().splitlines()[-1] for p, (_, err) in zip(procs, outs, strict=True)
              if p.returncode != 0]
    assert failed == []
    with where.open() as kb:
        assert kb.schema_version == SCHEMA_VERSION and kb.check().ok


@pytest.mark.processes
def test_concurrent_first_opens_create_the_schema_once(where):
    if where.backend == "sqlite":
        pytest.skip("SQLite creates the schema inside BEGIN IMMEDIATE; the slow test covers it")
    _first_opens(where)


@pytest.mark.slow
def test_concurrent_first_opens_create_the_schema_once_on_any_backend(where):
    _first_opens(where)


# ---------------------------------------------------------------------- the row hash's encoding
def test_the_row_encoding_is_compact_sorted_json_and_one_instant_one_hash():
    from zoneinfo import ZoneInfo

    from adpart.store import integrity
    from adpart.store.models import SqlRun

    values = [1, "é\x00\"", None, True, 1.5, float("nan"), float("-inf"), -0.0, 1e300,
              {"b": [1.0, 2], "a": {"z": None, "y": "x"}}, [3, [4]]]
    assert integrity._encode(values) == json.dumps(values, sort_keys=True,
                                                   separators=(",", ":"))
    table = SqlRun.__table__
    naive = datetime(2026, 12, 6, 21, 30, 0, 123456)  # SQLite gives UTC times without a zone
    row = {c: None for c in integrity.hashed_columns(table)}
    row.update(id=3, task_id=1, learner="q", metrics={"gap": 0.25}, parameters={},
               created_at=naive, schema_version=4)
    digest = integrity.row_digest_v4(table, row)
    for same in (naive.replace(tzinfo=timezone.utc),  # PostgreSQL, any session time zone
                 naive.replace(tzinfo=timezone.utc).astimezone(ZoneInfo("America/Lima"))):
        assert integrity.row_digest_v4(table, {**row, "created_at": same}) == digest
    for column, other in (("created_at", naive.replace(microsecond=123457)), ("id", 4),
                          ("metrics", {"gap": 0.35}), ("learner", "Q"), ("seed", 0),
                          ("schema_version", 4.0), ("parameters", {"a": True})):
        assert integrity.row_digest_v4(table, {**row, column: other}) != digest, column


def test_the_row_text_depends_on_the_stored_values_alone(where):
    """Schema 5 hashes the text the database renders of a row: the same under any session
    time zone and float-output setting (PostgreSQL), and a double one ulp away is named as
    damaged (SQLite's ``json_array`` alone prints 15 digits: ``quote()`` keeps all 17)."""
    from adpart.store.integrity import row_text, text_digest
    from adpart.store.models import SqlTask

    with where.open() as kb:
        env = kb.put_environment("five", model_hash="e" * 64, n_states=5, n_actions=2)
        task = kb.put_task(env, "goal-4", spec={"goal": [4]}, gamma=0.1)
    table = SqlTask.__table__
    sessions: list[list[str]] = [[]]
    if where.backend == "postgresql":
        sessions += [["SET TIME ZONE 'America/Lima'", "SET extra_float_digits = 0"],
                     ["SET TIME ZONE 'Asia/Kathmandu'", "SET extra_float_digits = 3"]]
    engine = create_engine(where.db_url)
    texts = set()
    for statements in sessions:
        with engine.connect() as conn:
            for statement in statements:
                conn.execute(text(statement))
            (rendered, stored), = conn.execute(
                select(row_text(table), table.c.row_sha).where(table.c.id == task.id)).all()
        assert text_digest(table, rendered) == stored, statements
        texts.add(rendered)
    assert len(texts) == 1
    with engine.begin() as conn:  # the last bit of gamma flipped
        conn.execute(update(table).where(table.c.id == task.id)
                     .values(gamma=math.nextafter(0.1, 1.0)))
    engine.dispose()
    with where.open() as kb, pytest.raises(StoreError, match=rf"task:{task.id} is damaged"):
        kb.get("task", task.id)

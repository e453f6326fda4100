"""Damaged metadata is named on read, never returned and never a traceback.

Readers (``kb ls``, ``kb show``, ``kb export``, the API) verify each row's hash and survive a row
the driver cannot even decode: the API raises :class:`StoreError` naming the record, the table
and the column; ``kb ls`` lists the rest and names what it left out (exit 1); ``kb check`` names
it and goes on; ``kb gc`` skips what it cannot decide and finishes its round.
"""

from __future__ import annotations

import json
import random
import sqlite3
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from sqlalchemy import create_engine, text

from adpart.cli.kb import kb as kb_group
from adpart.store import KnowledgeBase, StoreError


def _kb(*args: str):
    return CliRunner().invoke(kb_group, list(args))


def _fill(kb: KnowledgeBase, n: int = 3) -> dict[str, list]:
    env = kb.put_environment("five", model_hash="e" * 64, n_states=5, n_actions=2)
    task = kb.put_task(env, "goal", spec={"goal": [4]}, gamma=0.9)
    policies, runs = [], []
    for i in range(n):
        policy = kb.put_policy(task, "q", q=np.full((5, 2), float(i)), seed=i)
        runs.append(kb.put_run(task, "q", seed=i, curve={"episode": np.arange(3) + i},
                               metrics={"final_gap": 0.1 * i},
                               parameters={"policies": [policy.id]}))
        policies.append(policy)
    return {"policies": policies, "runs": runs}


def _sql(where, statement: str, **params) -> None:
    engine = create_engine(where.db_url)
    with engine.begin() as conn:
        conn.execute(text(statement), params)
    engine.dispose()


def _sqlite_only(where) -> None:
    if where.backend != "sqlite":
        pytest.skip("PostgreSQL's json and timestamptz columns cannot hold such a value")


DAMAGE = {
    "parameters": ("UPDATE runs SET parameters = '{not json' WHERE id = :id",
                   r"runs\.parameters cannot be read \(JSONDecodeError"),
    "created_at": ("UPDATE runs SET created_at = 'yesterday' WHERE id = :id",
                   r"runs\.created_at cannot be read \(ValueError"),
}


@pytest.mark.parametrize("column", list(DAMAGE))
def test_an_undecodable_run_is_named_by_every_reader_and_the_rest_survive(where, column):
    _sqlite_only(where)
    with where.open() as kb:
        rec = _fill(kb)
    bad, good = rec["runs"][1], rec["runs"][0]
    statement, named = DAMAGE[column]
    _sql(where, statement, id=bad.id)
    with where.open() as kb:
        for read in (lambda: kb.get("run", bad.id), lambda: kb.records("run"),
                     lambda: kb.records_table("run"), lambda: kb.runs_for(bad.task_id)):
            with pytest.raises(StoreError, match=rf"run:{bad.id} is damaged: {named}"):
                read()
        assert kb.get("run", good.id) == good
        damaged: list[str] = []
        table = kb.records_table("run", damaged=damaged)
        assert table.column("id").to_pylist() == [r.id for r in rec["runs"] if r != bad]
        assert len(damaged) == 1 and f"run:{bad.id} is damaged" in damaged[0]

    result = _kb("ls", *where.cli)
    assert result.exit_code == 1, result.output
    assert f"run:{good.id} " in result.output and "Traceback" not in result.output
    assert f"DAMAGED (left out): run:{bad.id} is damaged: runs.{column}" in result.output
    result = _kb("show", f"run:{bad.id}", *where.cli)
    assert result.exit_code == 2 and len(result.output.strip().splitlines()) == 1
    assert f"runs.{column} cannot be read" in result.output
    assert _kb("show", f"run:{good.id}", *where.cli).exit_code == 0
    result = _kb("check", *where.cli)
    assert result.exit_code == 1 and "Traceback" not in result.output
    assert f"DAMAGED: run:{bad.id} is damaged: runs.{column}" in result.output

    result = _kb("gc", "--yes", "--orphans", *where.cli)
    assert "Traceback" not in result.output
    assert result.exit_code == 1 and "skipped: no artifact row dropped: run:" in result.output
    if column == "parameters":  # which policies run:2 lists is unknown: no orphan is removed
        assert "skipped: orphan records not looked for" in result.output
    with where.open() as kb:
        assert kb.counts()["policy"] == 3

    result = _kb("rm", f"run:{bad.id}", "--yes", *where.cli)  # the fix the messages name
    assert result.exit_code == 0, result.output
    result = _kb("check", *where.cli)
    orphan = rec["policies"][1]
    assert result.exit_code == 0 and f"orphan record policy:{orphan.id}" in result.output


def test_a_changed_row_is_refused_on_read_on_every_backend(where):
    with where.open() as kb:
        rec = _fill(kb)
    bad = rec["runs"][2]
    _sql(where, "UPDATE runs SET metrics = :m WHERE id = :id", m=json.dumps({"final_gap": 9}),
         id=bad.id)
    with where.open() as kb:
        with pytest.raises(StoreError, match=rf"run:{bad.id} is damaged: its metadata row "
                                             r"\(table runs\) changed.*row hash mismatch"):
            kb.get("run", bad.id)
        with pytest.raises(StoreError, match="row hash mismatch"):
            kb.records("run")
    result = _kb("ls", "run", "--json", *where.cli)
    assert result.exit_code == 1
    listed = json.loads(result.stdout)
    assert [r["id"] for r in listed] == [r.id for r in rec["runs"][:2]]
    assert all(r["metrics.final_gap"] != 9 for r in listed)


def test_a_pointer_moved_to_another_policys_table_is_refused_by_load_and_export(where, tmp_path):
    with where.open() as kb:
        rec = _fill(kb)
    victim, other = rec["policies"][:2]
    _sql(where, "UPDATE policies SET q_sha = :q WHERE id = :id", q=other.q, id=victim.id)
    with where.open() as kb:
        with pytest.raises(StoreError, match=rf"policy:{victim.id} is damaged.*row hash"):
            kb.load(kb.get("policy", victim.id), "q")
        # a record read before the damage still holds its own pointer and its own values
        np.testing.assert_array_equal(kb.load(victim, "q"), np.zeros((5, 2)))
    out = tmp_path / "q.csv"
    result = _kb("export", f"policy:{victim.id}", "--field", "q", "--out", str(out), *where.cli)
    assert result.exit_code == 2 and f"policy:{victim.id} is damaged" in result.output
    assert not out.exists()


def test_a_changed_artifact_row_is_refused_naming_the_record(where):
    with where.open() as kb:
        rec = _fill(kb)
    policy = rec["policies"][0]
    _sql(where, "UPDATE artifacts SET bytes = bytes + 1 WHERE sha256 = :s", s=policy.q)
    with where.open() as kb:
        with pytest.raises(StoreError, match=rf"policy:{policy.id} \(q\): artifact:{policy.q[:16]}"
                                             r" is damaged"):
            kb.load(policy, "q")
        damaged: list[str] = []
        kb.records_table("policy", damaged=damaged)  # the size column reads artifact rows
        assert any(policy.q[:16] in d for d in damaged)
        problems = kb.check().problems
    assert any(f"referenced by policy:{policy.id} (q)" in p for p in problems), problems


def _filled_file(where, n: int) -> Path:
    """A SQLite knowledge base of ``n`` records, its write-ahead log folded in: the one file."""
    _sqlite_only(where)
    with where.open() as kb:
        _fill(kb, n=n)
    db = Path(where.location) / "kb.sqlite"
    with sqlite3.connect(db) as conn:
        conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    return db


def test_random_bit_flips_in_the_database_never_change_what_is_read(where, tmp_path):
    """Every flip either leaves what a reader returns unchanged or is refused (exit 1 or 2)."""
    db = _filled_file(where, 6)
    clean = db.read_bytes()
    refs = [f"run:{i}" for i in range(1, 7)] + [f"policy:{i}" for i in range(1, 7)]
    commands = [["ls", "--json"], *(["show", r, "--json"] for r in refs)]
    expected = [_kb(*c, *where.cli).stdout for c in commands]
    rng = random.Random(39)
    used = [i for i in range(100, len(clean)) if clean[i]]  # past the header, not free space
    changed = refused = 0
    for _ in range(30):
        data = bytearray(clean)
        at = rng.choice(used)
        data[at] ^= 1 << rng.randrange(8)
        db.write_bytes(bytes(data))
        for command, before in zip(commands, expected, strict=True):
            result = _kb(*command, *where.cli)
            assert "Traceback" not in result.output
            assert result.exception is None or isinstance(result.exception, SystemExit), (
                command, result.exception)
            if result.exit_code == 0:
                changed += result.stdout != before
            else:
                refused += 1
                if command[0] == "ls" and result.exit_code == 1:  # the rest, unchanged
                    kept = {r["ref"]: r for r in json.loads(result.stdout)}
                    for row in json.loads(before):  # a damaged artifact row: size unknown
                        if row["ref"] in kept and kept[row["ref"]]["size"] is None:
                            row["size"] = None
                        assert row["ref"] not in kept or row == kept[row["ref"]]
    db.write_bytes(clean)
    assert changed == 0 and refused > 0


@pytest.mark.parametrize("cut", [1000, 8192, 40000])
def test_a_truncated_database_file_is_named_not_a_traceback(where, cut):
    db = _filled_file(where, 40)
    data = db.read_bytes()
    db.write_bytes(data[: max(len(data) - cut, 4096)])
    for command in (["check"], ["ls"], ["show", "run:1"], ["gc"], ["info"]):
        result = _kb(*command, *where.cli)
        assert "Traceback" not in result.output, (command, result.output)
        assert result.exception is None or isinstance(result.exception, SystemExit), (
            command, repr(result.exception))
    assert _kb("check", *where.cli).exit_code in (0, 1, 2)

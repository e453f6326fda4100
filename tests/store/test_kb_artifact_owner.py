"""An artifact root belongs to one knowledge base: a second one given the same root is refused.

Two knowledge bases sharing a root used to delete each other's artifacts in ``kb gc`` (each
sees the other's files as unreferenced). A root now records its owner's identity when it is first
used (``adpart-owner.json``); every open checks it, before anything is created.
"""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from sqlalchemy import create_engine, inspect

from adpart.cli.kb import kb as kb_group
from adpart.store import KnowledgeBase, StoreError
from adpart.store.artifacts import OWNER_FILE
from tests.store.conftest import PG_URL, drop_pg_schema, pg_scratch_schema


def _kb(*args: str):
    return CliRunner().invoke(kb_group, list(args))


def _write(kb: KnowledgeBase, n: int = 5) -> list:
    env = kb.put_environment("e", model_hash="a" * 64, n_states=4, n_actions=2)
    task = kb.put_task(env, "t", spec={}, gamma=0.9)
    return [kb.put_policy(task, "q", q=np.full((4, 2), float(i))) for i in range(n)]


@pytest.fixture
def second(where, tmp_path):
    """Another knowledge-base database on the same backend as ``where`` (its URL)."""
    if where.backend == "sqlite":
        yield f"sqlite:///{tmp_path / 'second.sqlite'}"
        return
    schema, url = pg_scratch_schema(PG_URL)
    yield url
    drop_pg_schema(PG_URL, schema)


def _tables(url: str) -> list[str]:
    engine = create_engine(url)
    try:
        return inspect(engine).get_table_names()
    finally:
        engine.dispose()


def test_a_second_knowledge_base_is_refused_a_root_another_owns(where, second, tmp_path):
    root = Path(where.artifacts) if where.artifacts else Path(where.location) / "artifacts"
    with where.open() as kb:
        policies = _write(kb)
        owner = json.loads((root / OWNER_FILE).read_text())
        assert owner["kb_id"] == kb.kb_id
    with pytest.raises(StoreError, match=r"belongs to another knowledge base.*--kb-artifacts / "
                                         r"ADPART_KB_ARTIFACTS"):
        KnowledgeBase.open(second, artifacts=str(root))
    assert _tables(second) == []  # refused before its schema was made
    result = _kb("gc", "--yes", "--kb", second, "--kb-artifacts", str(root))
    assert result.exit_code == 2 and len(result.output.strip().splitlines()) == 1
    assert "belongs to another knowledge base" in result.output and "Traceback" not in result.output
    # the owner's artifacts are all there; its own gc keeps them and the owner file
    with where.open() as kb:
        report = kb.gc(delete=True, grace_s=0, temporary_age_s=0)
        assert report.artifacts == [] and report.files == [] and report.strays == []
        for i, policy in enumerate(policies):
            np.testing.assert_array_equal(kb.load(policy, "q"), np.full((4, 2), float(i)))
        assert kb.check().ok and not kb.check().stray_files
    assert (root / OWNER_FILE).is_file()


def test_a_read_only_open_is_refused_another_owners_root(where, second):
    root = Path(where.artifacts) if where.artifacts else Path(where.location) / "artifacts"
    with where.open():
        pass
    other = Path(str(root) + "-other")
    with KnowledgeBase.open(second, artifacts=str(other)) as kb:
        _write(kb, 1)
    result = _kb("ls", "--kb", second, "--kb-artifacts", str(root))
    assert result.exit_code == 2 and "belongs to another knowledge base" in result.output


def test_a_directory_ignores_the_artifacts_variable(tmp_path, monkeypatch):
    elsewhere = tmp_path / "shared-artifacts"
    monkeypatch.setenv("ADPART_KB_ARTIFACTS", str(elsewhere))
    with KnowledgeBase.open(tmp_path / "kb") as kb:
        policy = _write(kb, 1)[0]
        assert kb.artifact_uri == str(tmp_path / "kb" / "artifacts")
    assert not elsewhere.exists()
    monkeypatch.delenv("ADPART_KB_ARTIFACTS")
    with KnowledgeBase.open(tmp_path / "kb") as kb:  # reads the same without the variable
        np.testing.assert_array_equal(kb.load(policy, "q"), np.zeros((4, 2)))
        assert kb.check().ok


def test_a_directory_refuses_an_explicit_artifact_root_elsewhere(tmp_path):
    result = _kb("gc", "--kb", str(tmp_path / "kb"), "--kb-artifacts", str(tmp_path / "art"))
    assert result.exit_code == 2 and len(result.output.strip().splitlines()) == 1
    assert "--kb-artifacts" in result.output and "is for a database URL" in result.output
    assert not (tmp_path / "kb").exists() and not (tmp_path / "art").exists()
    with KnowledgeBase.open(tmp_path / "kb2", artifacts=str(tmp_path / "kb2" / "artifacts")):
        pass  # naming its own artifacts/ is fine


def test_a_root_without_an_owner_is_claimed_by_the_first_writable_open(tmp_path):
    url, root = f"sqlite:///{tmp_path / 'a.sqlite'}", tmp_path / "art"
    with KnowledgeBase.open(url, artifacts=str(root)) as kb:
        policy = _write(kb, 1)[0]
        kb_id = kb.kb_id
    (root / OWNER_FILE).unlink()  # a root made before roots had owners
    with KnowledgeBase.open(url, artifacts=str(root), read_only=True) as kb:
        kb.load(policy, "q")  # a reader claims nothing
    assert not (root / OWNER_FILE).exists()
    with KnowledgeBase.open(url, artifacts=str(root)):
        pass
    assert json.loads((root / OWNER_FILE).read_text())["kb_id"] == kb_id
    with pytest.raises(StoreError, match="belongs to another knowledge base"):
        KnowledgeBase.open(f"sqlite:///{tmp_path / 'b.sqlite'}", artifacts=str(root))


def test_a_knowledge_base_without_an_identity_gets_one_at_its_first_writable_open(tmp_path):
    url, root = f"sqlite:///{tmp_path / 'a.sqlite'}", tmp_path / "art"
    with KnowledgeBase.open(url, artifacts=str(root)) as kb:
        _write(kb, 1)
    with sqlite3.connect(tmp_path / "a.sqlite") as conn:  # as written before identities
        conn.execute("DROP TABLE adpart_identity")
    (root / OWNER_FILE).unlink()
    with KnowledgeBase.open(url, artifacts=str(root), read_only=True) as kb:
        assert kb.kb_id is None and kb.check().ok
    with KnowledgeBase.open(url, artifacts=str(root)) as kb:
        assert kb.kb_id is not None
        assert json.loads((root / OWNER_FILE).read_text())["kb_id"] == kb.kb_id


def test_a_closed_postgresql_port_creates_no_artifact_directory(tmp_path):
    art = tmp_path / "art"
    url = "postgresql+psycopg://postgres@127.0.0.1:1/test?connect_timeout=2"
    result = _kb("gc", "--kb", url, "--kb-artifacts", str(art))
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert len(result.output.strip().splitlines()) == 1
    assert not art.exists()

"""The ``adpart kb`` group through CliRunner on a real SQLite knowledge base."""

from __future__ import annotations

import json

import numpy as np
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner

from adpart.cli.kb import kb as kb_group


@pytest.fixture
def sqlite_kb(populated):
    kb, rec = populated
    if not kb.db_url.startswith("sqlite"):
        pytest.skip("CLI tests address the KB by directory")
    return kb.label, kb, rec


def _run(*args):
    result = CliRunner().invoke(kb_group, list(args))
    return result


def test_info(sqlite_kb):
    where, kb, _ = sqlite_kb
    result = _run("info", "--kb", where, "--json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    assert data["schema_version"] == 1
    assert data["counts"]["partition"] == 2 and data["artifact_bytes"] == kb.artifact_bytes() > 0
    assert "schema version: 1" in _run("info", "--kb", where).output


def test_ls_and_show(sqlite_kb):
    where, _, rec = sqlite_kb
    result = _run("ls", "partitions", "--env", "five", "--json", "--kb", where)
    assert result.exit_code == 0, result.output
    assert [r["ref"] for r in json.loads(result.output)] == [rec["p1"].ref, rec["partition"].ref]
    assert _run("ls", "--kb", where).output.count("\n") == 8
    result = _run("show", rec["policy"].ref, "--json", "--kb", where)
    data = json.loads(result.output)
    assert data["provenance"]["parameters"] == {"alpha": 0.1} and data["q"] == rec["policy"].q
    result = _run("show", f"artifact:{rec['policy'].q[:8]}", "--json", "--kb", where)
    assert json.loads(result.output)["referenced_by"] == [f"policy:{rec['policy'].id} (q)"]
    result = _run("show", "policy:999", "--kb", where)
    assert result.exit_code == 2 and "kb ls policy" in result.output


@pytest.mark.parametrize("suffix", [".parquet", ".csv", ".json"])
def test_export(sqlite_kb, tmp_path, suffix):
    where, _, rec = sqlite_kb
    out = tmp_path / f"q{suffix}"
    result = _run("export", rec["policy"].ref, "--field", "q", "--out", str(out), "--kb", where)
    assert result.exit_code == 0, result.output
    q = np.arange(10.0).reshape(5, 2)
    if suffix == ".parquet":
        assert pq.read_table(out).column("c1").to_pylist() == q[:, 1].tolist()
    elif suffix == ".csv":
        assert out.read_text().splitlines()[1] == "0,1"
    else:
        assert json.loads(out.read_text())["values"] == q.tolist()
    result = _run("export", rec["run"].ref, "--out", str(tmp_path / "c.csv"), "--kb", where)
    assert result.exit_code == 0, result.output
    assert (tmp_path / "c.csv").read_text().splitlines()[0] == '"episode","gap"'
    result = _run("export", rec["policy"].ref, "--out", str(tmp_path / "x.csv"), "--kb", where)
    assert result.exit_code == 2 and "--field" in result.output


def test_check_and_gc(sqlite_kb):
    where, kb, _ = sqlite_kb
    assert _run("check", "--kb", where).exit_code == 0
    before = kb.counts()["artifact"]
    orphan = kb.put_array(np.arange(7), kind="scratch")
    result = _run("gc", "--kb", where)
    assert result.exit_code == 0 and orphan.sha256[:16] in result.output
    assert "would delete 1 item" in result.output
    assert kb.counts()["artifact"] == before + 1
    result = _run("gc", "--yes", "--kb", where)
    assert "deleted 1 item" in result.output
    assert kb.counts()["artifact"] == before
    assert _run("check", "--kb", where).exit_code == 0
    assert "already current" in _run("upgrade", "--kb", where).output

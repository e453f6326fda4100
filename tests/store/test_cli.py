"""The ``adpart kb`` group through CliRunner on SQLite (a directory) and PostgreSQL (a URL)."""

from __future__ import annotations

import json

import numpy as np
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner

from adpart.cli.kb import kb as kb_group
from adpart.store import SCHEMA_VERSION


@pytest.fixture
def cli_kb(where, populated):
    """The ``--kb`` options of the populated knowledge base, the KB and its records."""
    kb, rec = populated
    return where.cli, kb, rec


def _run(*args):
    result = CliRunner().invoke(kb_group, list(args))
    return result


def test_info(cli_kb):
    opts, kb, _ = cli_kb
    result = _run("info", *opts, "--json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    assert data["schema_version"] == SCHEMA_VERSION
    assert data["counts"]["partition"] == 2 and data["artifact_bytes"] == kb.artifact_bytes() > 0
    text = _run("info", *opts).output
    assert f"schema version: {SCHEMA_VERSION}" in text
    assert "policies:" in text and "partitions:" in text and "policys" not in text


def test_ls_and_show(cli_kb):
    opts, _, rec = cli_kb
    result = _run("ls", "partitions", "--env", "five", "--json", *opts)
    assert result.exit_code == 0, result.output
    assert [r["ref"] for r in json.loads(result.output)] == [rec["p1"].ref, rec["partition"].ref]
    lines = _run("ls", *opts).output.splitlines()
    assert lines[0].split() == ["ID", "KIND", "ENV", "TASK", "SUMMARY", "CREATED", "SIZE"]
    assert len(lines) == 1 + 8  # a header, then one line per record (artifacts not listed)
    result = _run("show", rec["policy"].ref, "--json", *opts)
    data = json.loads(result.output)
    assert data["provenance"]["parameters"] == {"alpha": 0.1} and data["q"] == rec["policy"].q
    result = _run("show", f"artifact:{rec['policy'].q[:8]}", "--json", *opts)
    assert json.loads(result.output)["referenced_by"] == [f"policy:{rec['policy'].id} (q)"]
    result = _run("show", "policy:999", *opts)
    assert result.exit_code == 2 and "kb ls policy" in result.output


@pytest.mark.parametrize("suffix", [".parquet", ".csv", ".json"])
def test_export(cli_kb, tmp_path, suffix):
    opts, _, rec = cli_kb
    out = tmp_path / f"q{suffix}"
    result = _run("export", rec["policy"].ref, "--field", "q", "--out", str(out), *opts)
    assert result.exit_code == 0, result.output
    q = np.arange(10.0).reshape(5, 2)
    if suffix == ".parquet":
        table = pq.read_table(out)
        assert table.column("state").to_pylist() == list(range(5))  # rows indexed by state
        assert table.column("c1").to_pylist() == q[:, 1].tolist()
    elif suffix == ".csv":
        assert out.read_text().splitlines()[1] == "0,0,1"  # state, c0, c1
    else:
        assert json.loads(out.read_text())["values"] == q.tolist()
    result = _run("export", rec["run"].ref, "--out", str(tmp_path / "c.csv"), *opts)
    assert result.exit_code == 0, result.output
    assert (tmp_path / "c.csv").read_text().splitlines()[0] == '"episode","gap"'
    result = _run("export", rec["policy"].ref, "--out", str(tmp_path / "x.csv"), *opts)
    assert result.exit_code == 2 and "--field" in result.output


def test_check_and_gc(cli_kb):
    opts, kb, _ = cli_kb
    assert _run("check", *opts).exit_code == 0
    before = kb.counts()["artifact"]
    orphan = kb.put_array(np.arange(7), kind="scratch")
    result = _run("gc", *opts)
    assert result.exit_code == 0 and orphan.sha256[:16] in result.output
    assert "would delete 1 item" in result.output
    assert kb.counts()["artifact"] == before + 1
    result = _run("gc", "--yes", *opts)
    assert "deleted 1 item" in result.output
    assert kb.counts()["artifact"] == before
    assert _run("check", *opts).exit_code == 0
    assert "already current" in _run("upgrade", *opts).output

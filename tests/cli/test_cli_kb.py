"""The documented ways of reading the knowledge base as data (docs/knowledge-base.md, "The
knowledge base as data"): the command-line example, run as written, and the duckdb example on
the SQLite file and a Parquet artifact, checked against the Python table API."""

from __future__ import annotations

import importlib.metadata
import json
import re
import shlex
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from adpart.cli import cli
from adpart.store import open_kb
from adpart.store.tables import json_rows

DOC = Path(__file__).resolve().parents[2] / "docs" / "knowledge-base.md"


def _block(marker: str) -> str:
    """The fenced code block that follows ``<!-- marker -->`` in the knowledge-base page."""
    found = re.search(rf"<!-- {marker} -->\s*```[a-z]*\n(.*?)```", DOC.read_text(), re.DOTALL)
    assert found, f"docs/knowledge-base.md lost its <!-- {marker} --> block"
    return found.group(1)


def _commands() -> list[list[str]]:
    lines = [ln for ln in _block("kb-cli-example").splitlines() if ln.strip()]
    assert all(ln.startswith("adpart ") for ln in lines)
    return [shlex.split(ln)[1:] for ln in lines]


@pytest.fixture(scope="module")
def example(tmp_path_factory):
    """The documented command-line example, run in a fresh folder: (folder, outputs)."""
    folder = tmp_path_factory.mktemp("kb-example")
    outputs = []
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(folder)
        mp.setenv("ADPART_HOME", str(folder / "adpart-home"))  # as the autouse fixture does
        mp.delenv("ADPART_KB", raising=False)
        for args in _commands():
            result = CliRunner().invoke(cli, args)
            assert result.exit_code == 0, (args, result.output)
            outputs.append((args, result.output))
    return folder, outputs


def test_the_documented_cli_example_prints_what_the_page_shows(example):
    folder, outputs = example
    printed = {" ".join(args[:2]) + (" --json" if "--json" in args else ""): out
               for args, out in outputs}
    # kb ls run: a header and one aligned line per run, the step size in the summary
    lines, shared = printed["kb ls"].splitlines()[:-1], printed["kb ls"].splitlines()[-1]
    assert shared.startswith("every run above also has: runs=2 episodes=20 seed=0")
    assert lines[0].split() == ["ID", "KIND", "ENV", "TASK", "SUMMARY", "CREATED", "SIZE"]
    assert [ln.split()[:4] for ln in lines[1:]] == [
        ["run:1", "run", "two-rooms", "reach-goal"], ["run:2", "run", "two-rooms", "reach-goal"]]
    assert "alpha=0.5" in lines[1] and "alpha=1" in lines[2]
    starts = {ln.index(word) for ln in lines for word in ln.split()[:1]}
    assert starts == {0}
    assert len({ln.index("two-rooms") for ln in lines[1:]} | {lines[0].index("ENV")}) == 1
    # kb ls --kind run --where alpha=0.5 --json: strict JSON, one object, the records_table row
    text = printed["kb ls --json"]
    assert "NaN" not in text and "Infinity" not in text
    rows = json.loads(text)
    assert [r["ref"] for r in rows] == ["run:1"] and rows[0]["params.alpha"] == "0.5"
    assert rows[0]["params.episodes"] == 20 and rows[0]["metrics.runs"] == 2
    with open_kb(folder / "kb", read_only=True) as kb:
        assert rows == json_rows(kb.records_table("run", where={"alpha": 0.5}))
    # kb show run:2: the record, then its sections, nested parameters indented
    shown = printed["kb show"].splitlines()
    assert shown[0] == "run:2"
    assert shown[1].split() == ["environment:", "two-rooms", "(environment:1)"]
    for section in ("metrics:", "artifacts:", "provenance:", "parameters:"):
        assert section in shown
    assert "  request:" in shown and "    params:" in shown
    assert any(re.fullmatch(r"      alpha: +1(\.0)?", ln) for ln in shown)


def _duckdb_with_sqlite():
    duckdb = pytest.importorskip("duckdb")
    try:
        ext = next(f for f in importlib.metadata.files("duckdb-ext-sqlite") or []
                   if f.name.endswith(".duckdb_extension")).locate()
    except (importlib.metadata.PackageNotFoundError, StopIteration):
        pytest.skip("duckdb's SQLite extension is not installed (pip install duckdb-ext-sqlite)")
    con = duckdb.connect()
    con.execute(f"SET extension_directory = '{ext.parents[2]}'")
    con.execute("SET autoinstall_known_extensions = false")
    con.execute("LOAD sqlite")
    return con


def test_the_documented_duckdb_example_reads_what_the_api_returns(example, monkeypatch):
    folder, _ = example
    pytest.importorskip("pandas")
    con = _duckdb_with_sqlite()
    monkeypatch.chdir(folder)
    scope = {"con": con}
    exec(_block("kb-duckdb-example"), scope)  # noqa: S102  (the page's own example, as written)
    runs, curve = scope["runs"], scope["curve"]
    with open_kb("kb", read_only=True) as kb:
        table = kb.records_table("run").to_pandas()
        assert runs["run_id"].tolist() == table["id"].tolist() == [1, 2]
        assert runs["env"].tolist() == table["env"].tolist()
        assert runs["task"].tolist() == table["task"].tolist()
        assert [float(a) for a in runs["alpha"]] == [0.5, 1.0]
        np.testing.assert_array_equal(runs["final_gap"].to_numpy(),
                                      table["metrics.final_value_gap.mean"].to_numpy())
        api = (kb.curves_table("run:1").to_pandas()[["run", "episode", "value_gap"]]
               .sort_values(["run", "episode"]).reset_index(drop=True))
        assert len(curve) == 2 * 20
        np.testing.assert_array_equal(curve["run"].to_numpy(), api["run"].to_numpy())
        np.testing.assert_array_equal(curve["episode"].to_numpy(), api["episode"].to_numpy())
        np.testing.assert_array_equal(curve["value_gap"].to_numpy(), api["value_gap"].to_numpy())
        # an array artifact: one `values` column, row number = state
        policy = kb.get("policy", 1)
        uri = con.execute("SELECT a.uri FROM kb.policies p JOIN kb.artifacts a "
                          "ON a.sha256 = p.pi_sha WHERE p.id = 1").fetchone()[0]
        pi = con.sql(f"SELECT values FROM read_parquet('kb/artifacts/{uri}')").fetchnumpy()
        np.testing.assert_array_equal(pi["values"], kb.load(policy, "pi"))


def _refuse(name):
    raise ValueError(f"non-strict JSON constant {name}")


def test_kb_json_outputs_are_strict(example, tmp_path):
    """A learned curve has NaN gaps on the episodes it did not evaluate: every JSON the kb
    commands write must still parse with a strict parser (null, never NaN or Infinity)."""
    folder, _ = example
    opts = ["--kb", str(folder / "kb")]
    out = tmp_path / "curve.json"
    result = CliRunner().invoke(cli, ["kb", "export", "run:1", "--out", str(out), *opts])
    assert result.exit_code == 0, result.output
    curve = json.loads(out.read_text(), parse_constant=_refuse)
    assert None in curve["value_gap"] and len(curve["value_gap"]) == 2 * 20
    q = tmp_path / "q.json"
    result = CliRunner().invoke(cli, ["kb", "export", "policy:1", "--field", "q", "--out", str(q),
                                      *opts])
    assert result.exit_code == 0, result.output
    json.loads(q.read_text(), parse_constant=_refuse)
    for args in (["info"], ["ls"], ["show", "run:1"], ["show", "policy:1"], ["check"]):
        result = CliRunner().invoke(cli, ["kb", *args, "--json", *opts])
        assert result.exit_code == 0, (args, result.output)
        json.loads(result.output, parse_constant=_refuse)


def test_reading_the_default_location_creates_nothing(tmp_path, monkeypatch):
    home = tmp_path / "home"
    monkeypatch.setenv("ADPART_HOME", str(home))
    for args in (["info"], ["ls", "run"], ["show", "run:1"], ["check"]):
        result = CliRunner().invoke(cli, ["kb", *args])
        assert result.exit_code == 2, result.output
        assert "never create" in result.output and "--kb" in result.output
        assert "Traceback" not in result.output
    assert not home.exists()

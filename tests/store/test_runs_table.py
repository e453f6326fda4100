"""Runs as a table: each learning run's time to the success bound, stored with its record by
the pipeline's own definition, read back by ``runs_table`` and ``adpart kb runs``, and the
paged ``kb ls`` (docs/knowledge-base.md, "Runs as a table")."""

from __future__ import annotations

import json
import re
import shlex
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from adpart.cli import cli
from adpart.cli.kb import LS_PAGE
from adpart.cli.kb import kb as kb_group
from adpart.learning.comparison import SUCCESS_FRACTION, task_row
from adpart.learning.curves import LearningCurve
from adpart.store import StoreError, open_kb
from adpart.store.tables import RUN_COLUMNS, json_rows
from adpart.workflows import record_learning, run_learning
from adpart.workflows.learning import LearnRequest, load_curve

DOC = Path(__file__).resolve().parents[2] / "docs" / "knowledge-base.md"


def _to_bound_by_hand(curve: LearningCurve, v_star: float) -> list[tuple[int, int, bool]]:
    """Per run, (episodes, steps, censored) to the bound, written out from the definition: the
    first evaluated episode from which every later evaluated gap is within 5 % of |V*|, the
    steps of the episodes up to it; never within it: the last evaluation, censored."""
    bound = 0.05 * abs(v_star)
    evaluated = [int(e) for e in curve.evaluated_episodes()]
    gaps, steps = curve.matrix("value_gap"), curve.matrix("steps")
    out = []
    for k in range(curve.n_runs):
        found = None
        for e in evaluated:
            if all(gaps[k, later - 1] <= bound for later in evaluated if later >= e):
                found = e
                break
        at = found if found is not None else evaluated[-1]
        out.append((at, int(sum(steps[k, :at])), found is None))
    return out


@pytest.fixture
def learned(kb):
    """Two run records on two-rooms (q-learning at two step sizes) and one on its moved goal."""
    ids = [record_learning(kb, run_learning(LearnRequest(
        env="two-rooms", runs=4, episodes=episodes, eval_every=10, params={"alpha": alpha})))[
        "run"] for alpha, episodes in ((1.0, 300), (0.5, 40))]
    ids.append(record_learning(kb, run_learning(LearnRequest(
        env="two-rooms", task="goal:x=2,y=2", runs=2, episodes=10, eval_every=5)))["run"])
    return kb, [int(i.split(":")[1]) for i in ids]


def test_each_run_stores_its_time_to_the_bound_by_the_pipelines_definition(learned):
    kb, (first, *_) = learned
    run = kb.get("run", first)
    curve = load_curve(kb, run)  # as the pipeline reads a stored run back
    v_star = run.metrics["v_star_start"]
    stored = run.metrics["per_run"]
    assert stored["fraction"] == SUCCESS_FRACTION
    assert stored["bound"] == pytest.approx(0.05 * abs(v_star))
    by_hand = _to_bound_by_hand(curve, v_star)
    assert list(zip(stored["episodes_to_bound"], stored["steps_to_bound"], stored["censored"],
                    strict=True)) == by_hand
    assert stored["final_gap"] == pytest.approx(curve.matrix("value_gap")[:, -1].tolist())
    assert not all(stored["censored"])  # some runs get there: the times are real ones
    # the pipeline's table row of the same curve: the same median and the same censored runs
    row = task_row("reach-goal", "flat", curve, SUCCESS_FRACTION, {})
    times = [np.inf if c else e for e, _, c in by_hand]
    assert row["episodes_to_bound_median"] == np.median(times)
    assert row["censored_runs"] == sum(stored["censored"])
    assert row["bound"] == stored["bound"]


def test_runs_table_has_a_row_per_run_and_filters(learned):
    kb, (first, second, moved) = learned
    table = kb.runs_table()
    assert table.schema.names == list(RUN_COLUMNS)
    rows = table.to_pylist()
    assert [(r["run_id"], r["replicate"]) for r in rows] == (
        [(first, k) for k in range(4)] + [(second, k) for k in range(4)]
        + [(moved, k) for k in range(2)])
    for r in rows:
        stored = kb.get("run", r["run_id"]).metrics["per_run"]
        k = r["replicate"]
        assert (r["episodes_to_bound"], r["steps_to_bound"], r["censored"]) == (
            stored["episodes_to_bound"][k], stored["steps_to_bound"][k], stored["censored"][k])
        assert r["env"] == "two-rooms" and r["learner"] == "q-learning"
    assert {r["task"] for r in rows} == {"reach-goal", "goal:x=2,y=2"}
    assert kb.runs_table(task="reach-goal").num_rows == 8
    assert kb.runs_table(where={"alpha": 0.5}).column("run_id").to_pylist() == [second] * 4
    assert kb.runs_table(learner="known-dynamics").num_rows == 0
    assert kb.runs_table(limit=3).num_rows == 3
    with pytest.raises(StoreError, match="no environment 'nowhere'"):
        kb.runs_table(env="nowhere")
    # the per-run lists stay out of records_table's metrics columns
    assert not [c for c in kb.records_table("run").column_names if "per_run" in c]


def test_a_run_stored_without_the_figures_is_one_row_of_nulls(kb):
    env = kb.put_environment("e", model_hash="a" * 64, n_states=2, n_actions=2)
    task = kb.put_task(env, "t", spec={}, gamma=0.9)
    run = kb.put_run(task, "q-learning", metrics={"episodes": 5})
    rows = kb.runs_table().to_pylist()
    assert len(rows) == 1 and rows[0]["run_id"] == run.id and rows[0]["episodes"] == 5
    assert rows[0]["replicate"] is None and rows[0]["episodes_to_bound"] is None


def test_kb_runs_prints_the_table_and_its_json(where, learned):
    kb, _ = learned
    result = CliRunner().invoke(kb_group, ["runs", "--task", "reach-goal", *where.cli])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert lines[0].split()[:5] == ["RUN", "#", "ENV", "TASK", "LEARNER"]
    assert len(lines) == 1 + 8
    table = kb.runs_table(task="reach-goal").to_pylist()
    for line, row in zip(lines[1:], table, strict=True):
        cells = line.split()
        assert cells[:2] == [row["run"], str(row["replicate"])]
        shown = f">{row['episodes_to_bound']}" if row["censored"] else str(
            row["episodes_to_bound"])
        assert cells[6] == shown
    as_json = CliRunner().invoke(kb_group, ["runs", "--json", *where.cli])
    assert as_json.exit_code == 0, as_json.output
    assert json.loads(as_json.output) == json_rows(kb.runs_table())
    paged = CliRunner().invoke(kb_group, ["runs", "--limit", "3", *where.cli])
    assert paged.output.splitlines()[-1].startswith("... 7 more of 10 runs")
    none = CliRunner().invoke(kb_group, ["runs", "--learner", "maxq-q", *where.cli])
    assert none.exit_code == 0 and none.output.strip() == "no runs match"
    both = CliRunner().invoke(kb_group, ["runs", "--all", "--limit", "2", *where.cli])
    assert both.exit_code == 2 and "--all and --limit" in both.output


def test_kb_ls_pages_by_default_and_its_summary_tells_runs_apart(where, kb):
    env = kb.put_environment("e", model_hash="b" * 64, n_states=2, n_actions=2)
    task = kb.put_task(env, "t", spec={}, gamma=0.9)
    params = {f"a_rather_long_parameter_{i}": 0.25 for i in range(4)}
    for runs in range(1, LS_PAGE + 8):
        kb.put_run(task, "hierarchical", parameters={
            "request": {"runs": runs, "episodes": 300, "seed": 0, "params": params}})
    result = CliRunner().invoke(kb_group, ["ls", "run", *where.cli])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert len(lines) == 1 + LS_PAGE + 2
    assert lines[-1].startswith(f"... 7 more of {LS_PAGE + 7} records")
    # a run's cell keeps what differs between the listed runs; what they share is said once
    cells = [re.search(r"  (hierarchical runs=\d+)  ", ln) for ln in lines[1:-2]]
    assert [m.group(1) for m in cells if m] == [f"hierarchical runs={n}"
                                                 for n in range(1, LS_PAGE + 1)]
    shared = lines[-2].removeprefix("every run above also has: ").split()
    assert shared[:2] == ["episodes=300", "seed=0"]
    assert sorted(shared[2:]) == [f"a_rather_long_parameter_{i}=0.25" for i in range(4)]
    # one run alone: its whole summary, the request's size first (runs=1 and runs=10 differ
    # inside a cut cell)
    one = CliRunner().invoke(kb_group, ["ls", "run", "--limit", "1", *where.cli])
    assert "hierarchical runs=1 episodes=300 seed=0 a_rather" in one.output
    everything = CliRunner().invoke(kb_group, ["ls", "run", "--all", *where.cli])
    assert len(everything.output.splitlines()) == 1 + LS_PAGE + 7 + 1
    as_json = CliRunner().invoke(kb_group, ["ls", "run", "--json", *where.cli])
    assert len(json.loads(as_json.output)) == LS_PAGE + 7  # scripts get every record
    five = CliRunner().invoke(kb_group, ["ls", "--limit", "5", "--learner", "hierarchical",
                                         *where.cli])
    assert len(five.output.splitlines()) == 1 + 5 + 2  # and what the five share


# ---------------------------------------------------------------------- the documented example
def _block(marker: str) -> str:
    found = re.search(rf"<!-- {marker} -->\s*```[a-z]*\n(.*?)```", DOC.read_text(), re.DOTALL)
    assert found, f"docs/knowledge-base.md lost its <!-- {marker} --> block"
    return found.group(1)


def test_the_documented_runs_table_answers_match_the_curves(tmp_path, monkeypatch):
    pytest.importorskip("duckdb")
    pytest.importorskip("pandas")
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("ADPART_KB", raising=False)
    lines = [ln for ln in _block("kb-runs-cli").splitlines() if ln.strip()]
    outputs = []
    for line in lines:
        result = CliRunner().invoke(cli, shlex.split(line)[1:])
        assert result.exit_code == 0, (line, result.output)
        outputs.append(result.output)
    printed = outputs[-1].splitlines()  # kb runs --env three-floor
    assert printed[0].split()[:5] == ["RUN", "#", "ENV", "TASK", "LEARNER"]
    scope: dict = {}
    exec(_block("kb-runs-python"), scope)  # noqa: S102  (the page's own example, as written)
    answer, same = scope["answer"], scope["same"]
    assert list(answer.columns) == ["run", "replicate", "learner", "episodes_to_bound",
                                    "censored"]
    assert answer.reset_index(drop=True).equals(same)  # pandas and duckdb agree
    with open_kb("kb", read_only=True) as kb:
        expected = []
        for run in kb.select_records("run", env="three-floor"):
            curve = LearningCurve.from_arrow(kb.load(run, "curve"))
            expected += [(run.ref, k, run.learner, e, c) for k, (e, _, c) in
                         enumerate(_to_bound_by_hand(curve, run.metrics["v_star_start"]))]
    got = [(r.run, r.replicate, r.learner, r.episodes_to_bound, bool(r.censored))
           for r in same.itertuples()]
    assert got == expected
    assert {learner for _, _, learner, _, _ in got} == {"q-learning", "value-iteration"}
    assert {censored for *_, censored in got} == {True, False}
    assert len(printed) == 1 + len(expected)

"""Resumable sweeps (serial executor, no Ray needed): interrupted sweeps skip stored cells."""

from __future__ import annotations

import functools
from pathlib import Path

import pytest

from adpart.store import KnowledgeBase
from adpart.workflows import record_learning, run_learning
from adpart.workflows.sweep import (
    SweepError,
    cell_key,
    done_cells,
    parse_config,
    plan_cells,
    preview,
    run_cell,
    run_sweep,
)

CONFIG = {"seeds": [0, 1], "environments": ["two-rooms"], "runs": 1, "episodes": 10,
          "eval_every": 5, "params": {"alpha": ["0.1", "0.5"]}}


def _raise_once(flag_dir: str, target: str, job: dict) -> dict:
    """A cell that fails (outside the per-cell guard) the first time ``target`` runs."""
    flag = Path(flag_dir) / "raised"
    if job["key"] == target and not flag.exists():
        flag.write_text("")
        raise RuntimeError("transient failure")
    return run_cell(job)


def _keys(kb) -> list[str]:
    return sorted(r.provenance.parameters["sweep_cell"] for r in kb.records("run"))


def test_sweep_interrupted_by_a_failure_resumes_without_duplicates(tmp_path):
    cells = plan_cells(parse_config(CONFIG))
    worker = functools.partial(_raise_once, str(tmp_path), cells[2].key)
    with KnowledgeBase.open(tmp_path / "kb") as kb:
        with pytest.raises(SweepError, match=r"after storing 2 of 4 cells.*rerun"):
            run_sweep(cells, kb, worker=worker)
        assert _keys(kb) == sorted(c.key for c in cells[:2])
        assert [r.status for r in preview(cells, kb).results] == ["skipped"] * 2 + ["pending"] * 2
        ran = []
        report = run_sweep(cells, kb, worker=worker,
                           progress=lambda done, total, r: ran.append((done, total, r.cell.index)))
        assert ran == [(1, 2, 2), (2, 2, 3)]
        assert [r.status for r in report.results] == ["skipped"] * 2 + ["stored"] * 2
        assert _keys(kb) == sorted(c.key for c in cells)
        assert run_sweep(cells, kb).count("skipped") == 4
        assert _keys(kb) == sorted(c.key for c in cells)


def test_sweep_interrupted_by_the_user_keeps_what_was_stored(tmp_path):
    cells = plan_cells(parse_config(CONFIG))

    def stop_after_three(done: int, total: int, result) -> None:
        if done == 3:
            raise KeyboardInterrupt

    with KnowledgeBase.open(tmp_path / "kb") as kb:
        with pytest.raises(KeyboardInterrupt):
            run_sweep(cells, kb, progress=stop_after_three)
        assert len(done_cells(kb)) == 3
        assert run_sweep(cells, kb).count("stored") == 1
        assert len(kb.records("run")) == 4


def _failing_worker(job: dict) -> dict:
    """A worker in which the alpha=0.25 cell fails (a bad value that got past the config check
    is refused there now, so the failure is made in the worker)."""
    if job["request"]["params"]["alpha"] == "0.25":
        params = {**job["request"]["params"], "alpha": "not-a-schedule"}
        job = {**job, "request": {**job["request"], "params": params}}
    return run_cell(job)


def test_sweep_failed_cells_are_reported_and_retried_next_time(tmp_path):
    config = {**CONFIG, "params": {"alpha": ["0.5", "0.25"]}, "seeds": [0]}
    cells = plan_cells(parse_config(config))
    with KnowledgeBase.open(tmp_path / "kb") as kb:
        report = run_sweep(cells, kb, worker=_failing_worker)
        assert [r.status for r in report.results] == ["stored", "failed"]
        assert "cannot read a schedule" in report.results[1].error
        assert not report.complete
        again = run_sweep(cells, kb, worker=_failing_worker)
        assert [r.status for r in again.results] == ["skipped", "failed"]


def test_sweep_recognises_a_run_stored_by_adpart_learn(tmp_path):
    """The key is recomputed from the stored request, so identical requests count as done."""
    cells = plan_cells(parse_config(CONFIG))
    with KnowledgeBase.open(tmp_path / "kb") as kb:
        record_learning(kb, run_learning(cells[1].request))
        assert done_cells(kb) == {cell_key(cells[1].request): 1}
        report = run_sweep(cells, kb)
        assert [r.status for r in report.results] == ["stored", "skipped", "stored", "stored"]


def test_sweep_streams_chunks_through_the_plain_map_contract(tmp_path):
    """An executor without imap_unordered is fed chunks; results still land on their cells."""
    from adpart.execution import SerialExecutor

    cells = plan_cells(parse_config(CONFIG))
    seen = []
    with KnowledgeBase.open(tmp_path / "kb") as kb:
        report = run_sweep(cells, kb, SerialExecutor(), chunk=3,
                           progress=lambda d, t, r: seen.append(r.cell.index))
        assert seen == [0, 1, 2, 3]
        stored = done_cells(kb)
        for result in report.results:
            run = kb.get("run", stored[result.cell.key])
            assert run.seed == result.cell.request.seed
            assert run.provenance.parameters["alpha"] == result.cell.request.params["alpha"]

"""Sweeps on a local 2-CPU Ray cluster: identical results to the local pool, and worker death.

The oracle for the first test is the local process-pool executor: the knowledge bases written by
the two sweeps must hold bitwise-identical curves and Q tables for every cell.
"""

from __future__ import annotations

import functools
import os
import signal
import threading
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("ray")

from adpart.execution import LocalExecutor
from adpart.execution.ray import RayExecutor
from adpart.store import KnowledgeBase
from adpart.workflows.sweep import done_cells, load_config, plan_cells, run_cell, run_sweep


def _stored(kb: KnowledgeBase) -> dict[str, tuple]:
    """cell key -> (curve table, [Q of every policy]) as stored."""
    out = {}
    for key, run_id in done_cells(kb).items():
        run = kb.get("run", run_id)
        policies = [kb.get("policy", p) for p in run.provenance.parameters["policies"]]
        out[key] = (kb.load(run, "curve"), [kb.load(p, "q") for p in policies])
    return out


def test_ray_sweep_stores_the_same_results_as_the_local_pool(ray_cluster, small_sweep, tmp_path):
    cells = plan_cells(load_config(small_sweep))
    assert len(cells) == 8
    stored = {}
    for name, executor in (("local", LocalExecutor(workers=2)), ("ray", RayExecutor())):
        with KnowledgeBase.open(tmp_path / f"kb-{name}") as kb, executor:
            report = run_sweep(cells, kb, executor)
            assert report.count("stored") == 8
            stored[name] = _stored(kb)
    assert set(stored["local"]) == set(stored["ray"]) == {c.key for c in cells}
    for key, (curve, qs) in stored["local"].items():
        ray_curve, ray_qs = stored["ray"][key]
        assert curve.schema.equals(ray_curve.schema, check_metadata=True)
        for column in curve.column_names:
            np.testing.assert_array_equal(curve[column].to_numpy(), ray_curve[column].to_numpy())
        assert len(qs) == len(ray_qs) == 2
        for q, ray_q in zip(qs, ray_qs, strict=True):
            np.testing.assert_array_equal(q, ray_q)


def _pid_then_sleep(pid_dir: str, job: dict) -> dict:
    """A cell that announces its worker's pid, gives the test time to kill it, then learns."""
    (Path(pid_dir) / f"{os.getpid()}-{job['key'][:12]}").write_text("")
    time.sleep(1.0)
    return run_cell(job)


def test_ray_sweep_survives_a_killed_worker(ray_cluster, small_sweep, tmp_path):
    cells = plan_cells(load_config(small_sweep))
    pid_dir = tmp_path / "pids"
    pid_dir.mkdir()
    killed: list[str] = []
    stop = threading.Event()

    def killer() -> None:
        while not stop.is_set():
            files = sorted(pid_dir.iterdir())
            if files:
                pid, key = files[0].name.split("-")
                os.kill(int(pid), signal.SIGKILL)
                killed.append(key)
                return
            time.sleep(0.01)

    thread = threading.Thread(target=killer, daemon=True)
    thread.start()
    try:
        with KnowledgeBase.open(tmp_path / "kb") as kb, RayExecutor(max_retries=3) as ex:
            report = run_sweep(cells, kb, ex, worker=functools.partial(_pid_then_sleep,
                                                                      str(pid_dir)))
            runs = kb.records("run")
    finally:
        stop.set()
        thread.join()
    assert len(killed) == 1
    # the killed cell ran again in another worker process
    attempts = [f.name for f in pid_dir.iterdir() if f.name.endswith(killed[0])]
    assert len(attempts) == 2 and len({a.split("-")[0] for a in attempts}) == 2
    assert report.complete and report.count("stored") == 8
    keys = [r.provenance.parameters["sweep_cell"] for r in runs]
    assert sorted(keys) == sorted(c.key for c in cells), "every cell stored exactly once"

"""`adpart experiment benchmark --quick`: every cell's branch, ratio and the aggregates."""

from __future__ import annotations

import json

import numpy as np
import pytest
from matplotlib.image import imread

from adpart.experiments.base import ExperimentConfig, run_experiment
from adpart.experiments.benchmark import (
    BENCHMARK_CELLS,
    LOSS_BOUND,
    QUICK_BENCHMARK_CELLS,
    CellResult,
)
from adpart.workflows.resolve import resolve_domain


@pytest.mark.extended
def test_every_cell_runs_and_says_which_branch_it_took(tmp_path):
    out = tmp_path / "out"
    run_experiment("benchmark", ExperimentConfig(out=out, runs=3, seed=0, quick=True))
    summary = json.loads((out / "summary.json").read_text())
    data = summary["data"]
    assert data["failed"] == []
    assert [c["env"] for c in data["cells"]] == [c.env for c in QUICK_BENCHMARK_CELLS]
    for cell in data["cells"]:
        assert cell["branch"] in ("layer", "flat") and cell["reason"]
        ratio = cell["ratio_to_flat"]
        if cell["branch"] == "flat":  # the chain is flat's own runs
            assert ratio["ratio"] == 1.0 and ratio["ci95"] == [1.0, 1.0]
        if ratio.get("ratio") is not None:
            assert cell["loses"] == (ratio["ci95"][0] > LOSS_BOUND)
    md = (out / "summary.md").read_text()
    assert md.count("\n| ") == len(QUICK_BENCHMARK_CELLS) + 1  # header and a row per cell
    if "iqm_chain_over_flat" in data:
        est, lo, hi = data["iqm_chain_over_flat"]
        assert lo <= est <= hi
        p, plo, phi = data["probability_chain_sooner"]
        assert 0 <= plo <= p <= phi <= 1
        image = imread(out / "benchmark-profile.png")
        assert image.shape[0] > 200 and image[..., :3].std() > 0.05  # drawn, not blank
        # the profile is the fraction of pooled runs below each tau: a distribution function
        prof = data["profiles"]
        taus = np.asarray(prof["taus"])
        for key in ("chain", "flat"):
            frac = np.asarray(prof[key]["fraction"])
            assert np.all(np.diff(frac) >= 0) and 0 <= frac[0] and frac[-1] <= 1
            assert np.all(np.asarray(prof[key]["low"]) <= frac + 1e-12)
            assert np.all(frac <= np.asarray(prof[key]["high"]) + 1e-12)
        # recomputed from the cells' runs (JSON writes a censored run's inf as null)
        for key in ("chain", "flat"):
            pooled = np.concatenate([np.array([np.inf if t is None else t
                                               for t in cell[f"{key}_runs"]], dtype=float)
                                     for cell in data["cells"] if cell[f"{key}_runs"]])
            expected = (pooled[:, None] < taus[None, :]).mean(axis=0)
            np.testing.assert_allclose(prof[key]["fraction"], expected)


def test_the_cells_span_toy_text_minigrid_and_the_built_ins_with_a_new_second_task():
    envs = [c.env for c in BENCHMARK_CELLS]
    assert len(BENCHMARK_CELLS) >= 30
    assert sum(e.startswith("gym:") for e in envs) >= 8
    assert sum(e.startswith("minigrid:") for e in envs) >= 10
    assert sum(":" not in e for e in envs) >= 5
    assert len(set(zip(envs, (c.tasks for c in BENCHMARK_CELLS), strict=True))) == len(envs)
    for cell in BENCHMARK_CELLS:
        assert cell.tasks[0] != cell.tasks[1]
    # every built-in cell names tasks its domain has (the others are checked by the full run)
    for cell in BENCHMARK_CELLS:
        if ":" not in cell.env:
            domain = resolve_domain(cell.env)
            for task in cell.tasks:
                assert np.any(domain.task(task).terminal), (cell.env, task)


def test_a_cell_loses_only_on_the_evidence_of_its_ratio():
    def result(ratio):
        return CellResult(QUICK_BENCHMARK_CELLS[0], "layer", "", "20/20", "20/20", ratio,
                          np.ones(2), np.ones(2))

    inf = float("inf")
    assert result({"ratio": 1.3, "ci95": [1.15, 2.0]}).loses
    assert not result({"ratio": 1.3, "ci95": [1.05, 2.0]}).loses
    assert not result({"ratio": None, "ci95": [inf, inf]}).loses  # both never: no verdict
    assert result({"ratio": None, "ci95": [inf, inf], "at_least": 2.0}).loses  # flat did, chain not
    assert not result({"ratio": None, "ci95": [0.0, 0.0], "at_most": 0.5}).loses
    assert not result(None).loses

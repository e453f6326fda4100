"""`adpart experiment comparisons --quick`: one table per cell, every learner with its knowledge."""

from __future__ import annotations

import json

import numpy as np
import pytest

from adpart.experiments.base import ExperimentConfig, run_experiment
from adpart.experiments.comparisons import CELLS, QUICK_CELLS


@pytest.mark.extended
def test_every_cell_has_its_table_with_each_learners_knowledge(tmp_path):
    config = ExperimentConfig(out=tmp_path / "out", runs=3, seed=0, quick=True)
    run_experiment("comparisons", config)
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    cells = summary["data"]["cells"]
    assert [c["env"] for c in cells] == [c.env for c in QUICK_CELLS]
    md = (tmp_path / "out" / "summary.md").read_text()
    for cell in cells:
        assert f"{cell['env']}, {' -> '.join(cell['tasks'])}" in md
        for row in cell["rows"]:
            assert row["knowledge"], row  # every learner says what it knew
        layer = [r for r in cell["rows"] if r["learner"] == "hierarchical"]
        if layer:  # learned on the stored step-4 layer (the learned-model regime's), beside
            # the planner and the model-based learner that knows as much
            assert layer[0]["knowledge"].startswith("dynamics estimated, rewards observed")
            assert any(r["learner"] == "estimated-dynamics" for r in cell["rows"])
            assert layer[0]["partition"] is not None
            assert any(r["learner"] == "planner" for r in cell["rows"])
            km = layer[0]["time_to_bound_km"]
            assert set(km) == {"episodes", "steps"} and len(km["steps"]) == 3
        else:  # or the pipeline says why it learned flat
            assert "fallback" in cell["stages"]
    assert "what each learner knew:" in md and "flat: dynamics none, rewards observed" in md
    assert summary["data"]["settings"]["eval_every"] == 1
    if "iqm_ratio_to_flat" in summary["data"]:
        est, lo, hi = summary["data"]["iqm_ratio_to_flat"]
        assert lo <= est <= hi and np.isfinite(lo)


def test_the_full_cells_are_the_benchmarks():
    envs = [c.env for c in CELLS]
    assert envs[:3] == ["three-floor", "urban", "three-floor-arm"]
    assert sum(e.startswith("gym:") for e in envs) == 2
    assert all(c.tasks[0] != c.tasks[1] for c in CELLS)

"""`adpart experiment methods --quick`: every source x learner per cell, what each knew, and
aggregates recomputed from the stored runs."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from matplotlib.image import imread
from scipy.stats import trim_mean

from adpart.experiments.base import ExperimentConfig, run_experiment
from adpart.experiments.methods import BASELINE, OPTION_LEARNERS, SOURCES


def _runs(values: list) -> np.ndarray:
    return np.array([np.inf if t is None else t for t in values], dtype=float)


@pytest.mark.extended
def test_every_method_runs_in_the_learned_model_regime_and_the_aggregates_recompute(tmp_path):
    out = tmp_path / "out"
    run_experiment("methods", ExperimentConfig(out=out, runs=3, seed=0, quick=True))
    data = json.loads((out / "summary.json").read_text())["data"]
    assert data["failed"] == [] and len(data["cells"]) == 2
    expected = {f"{learner} [{source}]" for source in SOURCES for learner in OPTION_LEARNERS}
    expected |= {"sf-gpi", "estimated-dynamics", BASELINE}
    for cell in data["cells"]:
        assert set(cell["methods"]) == expected  # a source without subgoals: its learners flat
        for method, entry in cell["methods"].items():
            # honest by construction: nothing read the true model of either task
            flat = method == BASELINE or entry["flat_instead"]
            assert entry["knowledge"].startswith(
                "dynamics none" if flat else "dynamics estimated"), (method, entry)
            assert "rewards observed" in entry["knowledge"]
            if entry["flat_instead"]:
                assert entry["episodes"] == cell["methods"][BASELINE]["episodes"]
            # each run's time over the cell's scale: flat's KM median, or its budget
            np.testing.assert_allclose(_runs(entry["runs"]),
                                       _runs(entry["episodes"]) / cell["scale"])
    # the aggregates are over the same cells for every method: those where all have runs
    methods = {m for c in data["cells"] for m in c["methods"]}
    common = [c for c in data["cells"]
              if all(c["methods"].get(m, {}).get("runs") for m in methods)]
    assert common and all(a["cells"] == len(common) for a in data["aggregate"].values())
    # the interquartile mean of each method is rliable's: the 25 % trimmed mean of its pooled
    # runs (each over flat's median on its own cell)
    for method, agg in data["aggregate"].items():
        pooled = np.concatenate([_runs(c["methods"][method]["runs"]) for c in common])
        est, lo, hi = (np.inf if v is None else v for v in agg["iqm"])
        finite = np.isfinite(pooled)
        if finite.all():
            assert est == pytest.approx(trim_mean(pooled, 0.25))
        assert lo <= est <= hi or not np.isfinite(est)
        p, plo, phi = agg["probability_sooner"]
        assert 0 <= plo <= p <= phi <= 1
    image = imread(out / "methods-profile.png")
    assert image.shape[0] > 200 and image[..., :3].std() > 0.05  # drawn, not blank
    taus = np.asarray(data["profiles"]["taus"])
    for method, prof in data["profiles"]["methods"].items():
        pooled = np.concatenate([_runs(c["methods"][method]["runs"]) for c in common])
        np.testing.assert_allclose(prof["fraction"], (pooled[:, None] < taus).mean(axis=0))
    md = (out / "summary.md").read_text()
    assert "| sf-gpi | dynamics estimated, rewards observed |" in md
    rows = re.findall(r"^\| \d+ \| `", md, flags=re.MULTILINE)
    assert len(rows) == len(data["cells"])  # a row per cell in the per-cell table

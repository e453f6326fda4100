"""`adpart experiment methods --quick`: every source x learner per cell in both regimes, what
each knew, and aggregates recomputed from the stored runs."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from matplotlib.image import imread
from scipy.stats import trim_mean

from adpart.experiments.base import ExperimentConfig, run_experiment
from adpart.experiments.methods import (
    BASELINE,
    CELLS_PAGE,
    OPTION_LEARNERS,
    REGIMES_RUN,
    available_sources,
)


def _runs(values: list) -> np.ndarray:
    return np.array([np.inf if t is None else t for t in values], dtype=float)


#: What every method may know in each regime (flat knows nothing in both).
DYNAMICS = {"learned-model": "dynamics estimated", "true-model": "dynamics true-model"}
PLANNER = {"learned-model": "estimated-dynamics", "true-model": "known-dynamics"}


@pytest.mark.extended
def test_every_method_runs_in_each_regime_and_the_aggregates_recompute(tmp_path):
    out = tmp_path / "out"
    run_experiment("methods", ExperimentConfig(out=out, runs=3, seed=0, quick=True))
    data = json.loads((out / "summary.json").read_text())["data"]
    assert list(data["by_regime"]) == list(REGIMES_RUN)
    md = (out / "summary.md").read_text()
    for regime, found in data["by_regime"].items():
        assert found["failed"] == [] and len(found["cells"]) == 2
        sources, _ = available_sources()
        expected = {f"{learner} [{source}]" for source in sources for learner in OPTION_LEARNERS}
        expected |= {"sf-gpi", PLANNER[regime], BASELINE}
        for cell in found["cells"]:
            assert set(cell["methods"]) == expected  # no subgoals: the source's learners flat
            for method, entry in cell["methods"].items():
                # honest by construction: each method knew its regime's dynamics, no more
                flat = method == BASELINE or entry["flat_instead"]
                assert entry["knowledge"].startswith(
                    "dynamics none" if flat else DYNAMICS[regime]), (regime, method, entry)
                if regime == "learned-model":
                    assert "rewards observed" in entry["knowledge"]
                if entry["flat_instead"]:
                    assert entry["episodes"] == cell["methods"][BASELINE]["episodes"]
                # each run's time over the cell's scale: flat's KM median, or its budget
                np.testing.assert_allclose(_runs(entry["runs"]),
                                           _runs(entry["episodes"]) / cell["scale"])
        # the aggregates are over the same cells for every method: those where all have runs
        methods = {m for c in found["cells"] for m in c["methods"]}
        common = [c for c in found["cells"]
                  if all(c["methods"].get(m, {}).get("runs") for m in methods)]
        assert common and all(a["cells"] == len(common) for a in found["aggregate"].values())
        # the interquartile mean of each method is rliable's: the 25 % trimmed mean of its
        # pooled runs (each over the scale of its own cell)
        for method, agg in found["aggregate"].items():
            pooled = np.concatenate([_runs(c["methods"][method]["runs"]) for c in common])
            est, lo, hi = (np.inf if v is None else v for v in agg["iqm"])
            if np.isfinite(pooled).all():
                assert est == pytest.approx(trim_mean(pooled, 0.25))
            assert lo <= est <= hi or not np.isfinite(est)
            p, plo, phi = agg["probability_sooner"]
            assert 0 <= plo <= p <= phi <= 1
        taus = np.asarray(found["profiles"]["taus"])
        for method, prof in found["profiles"]["methods"].items():
            pooled = np.concatenate([_runs(c["methods"][method]["runs"]) for c in common])
            np.testing.assert_allclose(prof["fraction"], (pooled[:, None] < taus).mean(axis=0))
        assert f"**{regime} regime**" in md
    for figure in ("profile", "iqm", "probability"):  # a figure per aggregate and regime
        for suffix in ("", "-true-model"):
            image = imread(out / f"methods-{figure}{suffix}.png")
            assert image.shape[0] > 200 and image[..., :3].std() > 0.05  # drawn, not blank
    # a table per cell and regime, a row per method, each row its stored figures
    page = (out / CELLS_PAGE).read_text()
    for regime, found in data["by_regime"].items():
        for number, cell in enumerate(found["cells"], 1):
            section = page.split(f"### {regime} {number}: ", 1)[1].split("###", 1)[0]
            rows = re.findall(r"^\| (\S[^|]*?) \| ([^|]+) \| (\d+/\d+) \| ([^|]+) \|",
                              section, flags=re.MULTILINE)
            assert [r[0] for r in rows] == list(cell["methods"])
            for method, known, within, median in rows:
                entry = cell["methods"][method]
                assert within == entry["within"]
                assert entry["knowledge"].startswith(known)
                assert median.strip() == ("never" if entry["km_median"] is None
                                          else f"{entry['km_median']:.4g}")
                episodes = _runs(entry["episodes"])
                if np.isfinite(episodes).all():  # no censoring: KM's median is the lower median
                    assert entry["km_median"] == np.quantile(episodes, 0.5,
                                                             method="inverted_cdf")
    assert "| sf-gpi | dynamics estimated, rewards observed |" in md
    assert "| sf-gpi | dynamics true-model, rewards observed |" in md
    rows = re.findall(r"^\| \d+ \| `", md, flags=re.MULTILINE)
    assert len(rows) == 2 * len(REGIMES_RUN)  # a row per cell in each regime's table

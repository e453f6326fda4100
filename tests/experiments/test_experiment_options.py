"""`options-three-floor` (quick): option sets, exact optimum, curves, comparisons, files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from adpart.experiments.base import ExperimentConfig, run_experiment
from adpart.experiments.options_three_floor import FLAT, options_three_floor  # noqa: F401


@pytest.mark.slow
def test_quick_options_three_floor(tmp_path):
    config = ExperimentConfig(out=tmp_path, runs=2, seed=0, quick=True)
    report, files = run_experiment("options-three-floor", config)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["name"] == "options-three-floor" and set(files) == {"json", "markdown"}
    data = report.data
    n_disc = len(data["subgoals"]["discovered"])
    assert 0 < n_disc < data["subgoals"]["hand_designed"] == 65
    assert data["options"] == {
        "discovered + primitives": n_disc, "hand-designed + primitives": 65,
        "discovered + goal option": n_disc + 1, "hand-designed + goal option": 66}
    # every option set can express the optimal policy of the new task
    for v in data["v_options_start"].values():
        assert abs(v - data["v_star_start"]) < 1e-6
    assert abs(data["threshold"] - 0.1 * (data["v_star_start"] + 100.0)) < 1e-9
    learners = set(data["episodes_to_threshold"])
    assert FLAT in learners and len(learners) == 5
    for runs in data["episodes_to_threshold"].values():
        assert len(runs) == 2 and all(10 <= e <= 61 for e in runs)
    # the goal-option SMDPs get below the threshold within 60 episodes
    assert data["censored"]["SMDP Q, discovered + goal option"] == 0
    assert data["censored"]["SMDP Q, hand-designed + goal option"] == 0
    assert len(data["comparisons"]) == 6
    curves = json.loads((tmp_path / "curves.json").read_text())
    assert curves["episodes"] == [10, 20, 30, 40, 50, 60]
    assert set(curves["mean_value_gap"]) == learners
    assert np.all(np.array(curves["mean_value_gap"][FLAT]) >= -1e-9)
    for fig in report.figures:
        assert (tmp_path / fig.split("/")[-1]).stat().st_size > 1000
    assert "about 300 SMDP, 500 flat" in (tmp_path / "summary.md").read_text()

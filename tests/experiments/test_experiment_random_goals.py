"""`adpart experiment random-goals --quick`: one layer for every goal, ratios per goal, pooled."""

from __future__ import annotations

import json

import numpy as np

from adpart.experiments.base import ExperimentConfig, run_experiment
from adpart.experiments.random_goals import SETTINGS, goal_cells


def test_goals_are_distinct_cells_other_than_the_first_goal():
    goals = goal_cells("three-floor", "reach-goal", 20, seed=0)
    assert len(set(goals)) == 20 and "goal:x=37,y=30,floor=2" not in goals
    assert goals == goal_cells("three-floor", "reach-goal", 20, seed=0)  # from the seed alone
    assert goals != goal_cells("three-floor", "reach-goal", 20, seed=1)


def test_every_goal_is_learned_on_the_one_reward_free_layer(tmp_path):
    config = ExperimentConfig(out=tmp_path / "out", runs=3, seed=0, quick=True)
    run_experiment("random-goals", config)
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    data = summary["data"]
    quick = SETTINGS["quick"]
    assert data["settings"]["regime"] == "learned-model"
    assert len(data["per_goal"]) == quick["goals"]
    pipe = json.loads((tmp_path / "out" / "pipeline" / "summary.json").read_text())
    layers = {s["result"] for s in pipe["stages"] if s["stage"] == "partition"}
    assert len(layers) == 1  # phases 1-2 read no goal: one layer serves them all
    learners = {r["learner"] for r in pipe["tasks"]}
    assert {"hierarchical", "flat", "estimated-dynamics"} <= learners
    for est, lo, hi in data["iqm"].values():  # JSON writes an infinite IQM (never) as null
        est, lo, hi = (np.inf if v is None else v for v in (est, lo, hi))
        assert lo <= est <= hi
    md = (tmp_path / "out" / "summary.md").read_text()
    assert "per goal" in md and "interquartile mean" in md

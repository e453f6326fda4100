"""`subgoals-two-rooms` and `subgoals-sampling` (quick): key numbers, figures, summaries."""

from __future__ import annotations

import json

import numpy as np
import pytest

from adpart.envs.registry import get_domain
from adpart.experiments.base import ExperimentConfig, run_experiment
from adpart.experiments.subgoals import jaccard  # registers both experiments


def _files_exist(out, report):
    assert (out / "summary.json").is_file() and (out / "summary.md").is_file()
    for fig in report.figures:
        path = out / fig.split("/")[-1]
        assert path.suffix == ".png" and path.stat().st_size > 1000
    return json.loads((out / "summary.json").read_text())


def test_jaccard_oracle():
    a, b = np.array([1, 2, 3]), np.array([2, 3, 4, 5])
    assert jaccard(a, b) == pytest.approx(2 / 5)
    assert jaccard(np.array([], dtype=np.int64), np.array([], dtype=np.int64)) == 1.0
    assert jaccard(a, np.array([], dtype=np.int64)) == 0.0


def test_quick_two_rooms_finds_only_the_doorway(tmp_path):
    config = ExperimentConfig(out=tmp_path, runs=3, seed=0, quick=True)
    report, files = run_experiment("subgoals-two-rooms", config)
    summary = _files_exist(tmp_path, report)
    assert summary["name"] == "subgoals-two-rooms" and set(files) == {"json", "markdown"}
    door = int(np.flatnonzero(get_domain("two-rooms").dynamics().features["door"])[0])
    runs = report.data["runs_30_trajectories"]
    assert len(runs) == 3
    for row in runs:
        assert row["subgoals"] == [door] and row["doorway_only"]
        assert row["door_ratio"] >= row["mu"] > row["max_other_ratio"]
        assert row["ratio_sd"] > 0
    assert report.data["summary"]["30"]["doorway_only"] == 3
    assert max(report.data["final_value_gap"]) < 0.01
    assert "mu 1.8" in report.findings[0] and "only subgoal in 3/3" in report.findings[1]


def test_quick_sampling_curve_times_and_agreement(tmp_path):
    config = ExperimentConfig(out=tmp_path, runs=2, seed=0, quick=True)
    report, _ = run_experiment("subgoals-sampling", config)
    _files_exist(tmp_path, report)
    assert len(report.figures) == 2
    curve = report.data["curve"]
    samples = np.array(curve["samples"])
    assert samples[0] == 30 + 20 and samples[-1] == 200 and np.all(np.diff(samples) <= 20)
    assert len(curve["n_subgoals_mean"]) == samples.size == len(curve["jaccard_mean"])
    assert all(0.0 <= j <= 1.0 for j in curve["jaccard_mean"])
    for row in report.data["runs"]:
        ex, mc = row["exhaustive"], row["monte_carlo"]
        assert ex["subgoals"] and ex["mu"] > ex["ratio_mean"]
        assert mc["stop_reason"] in ("passes", "bernstein", "stable") and mc["samples"] >= 30
        assert ex["time_s"] > 0 and mc["time_s"] > 0
        common = len(set(ex["subgoals"]) & set(mc["subgoals"]))
        assert mc["common"] == common
        union = len(set(ex["subgoals"]) | set(mc["subgoals"]))
        assert mc["jaccard"] == pytest.approx(common / union if union else 1.0)
        assert row["monte_carlo_full"]["samples"] == 200
    assert "5,176" in report.findings[2] and "5177" in report.findings[2]

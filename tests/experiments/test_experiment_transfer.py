"""`three-floor`, `three-floor-arm`, `urban` (quick): pipeline, alternatives, report, bounds."""

from __future__ import annotations

import json

import numpy as np
import pytest

from adpart.experiments.base import ExperimentConfig, run_experiment
from adpart.experiments.transfer import (  # three_floor registers the three
    certainty_equivalence_gaps,
    grounded_policy_gaps,
    three_floor,  # noqa: F401
)
from adpart.learning.hierarchical import decision_layer
from adpart.mdp.generate import random_grid_mdp
from adpart.options import subgoal_option
from tests.learning.hierarchical_run import hierarchical_run
from tests.learning.test_hierarchical import DELTA, SETTINGS, goal_grid

LEARNERS = {"flat Q", "partition, no refinement", "partition, refinement",
            "partition, reward variation"}


def _run(name, tmp_path, kb=None):
    config = ExperimentConfig(out=tmp_path / "out", runs=2, seed=0, quick=True, kb=kb)
    report, files = run_experiment(name, config)
    return report, files


def _check_common(report, files, tmp_path, n_states):
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["name"] == report.name and set(files) == {"json", "markdown"}
    for fig in report.figures:
        assert (tmp_path / "out" / fig.split("/")[-1]).stat().st_size > 1000
    rows = {r["learner"]: r for r in report.data["rows"]}
    assert LEARNERS <= set(rows)
    assert report.data["theorem_4_5_bound"] > 0
    for row in rows.values():
        assert row["runs"] == 2
        # an exact gap lies between 0 (optimal) and the gap of never arriving (-1 a step,
        # gamma = 0.99: V_never = -100), so a sign or scale slip in the scoring fails here
        never = row["v_star_start"] + 1 / (1 - 0.99)
        assert -1e-9 <= row["final_gap_mean"] <= row["final_gap_max"] <= never + 1e-6
    stages = {s["stage"] for s in report.data["pipeline"]["stages"]}
    assert {"learn-flat", "discover", "options", "partition", "learn-hierarchical"} <= stages
    blocks = report.data["blocks"]
    # no refinement keeps its decision layer; refinement only ever adds blocks
    nr = blocks["no refinement"]
    assert nr["final_min"] == nr["final_max"] == nr["initial"] < n_states
    assert blocks["refinement"]["final_min"] >= blocks["refinement"]["initial"]
    assert report.data["refinements_per_run"] and all(
        n >= 0 for n in report.data["refinements_per_run"])
    assert report.seed_reports and any("Ours" in f for f in report.findings)
    assert (tmp_path / "out" / "summary.md").read_text().count("- ") >= 5
    return rows


@pytest.mark.slow
def test_three_floor_quick(tmp_path):
    report, files = _run("three-floor", tmp_path)
    rows = _check_common(report, files, tmp_path, 2900)
    assert {"SMDP Q (discovered + primitives)", "hand-designed, refinement",
            "hand-designed, reward variation"} <= set(rows)
    # the new goal is not a subgoal: without refinement no run ever reaches it
    nr = rows["partition, no refinement"]
    assert nr["runs_within_bound"] == 0
    assert nr["final_gap_mean"] == pytest.approx(nr["v_star_start"] + 1 / (1 - 0.99), abs=1e-6)
    # reward variation makes the goal a subgoal: every run within the bound
    rv = rows["partition, reward variation"]
    assert rv["runs_within_bound"] == 2 and rv["final_gap_max"] <= rv["bound"]
    assert report.data["hand_designed"]["blocks"] > 1
    assert "about 63" in (tmp_path / "out" / "summary.md").read_text()
    labels = [(c["a"], c["b"]) for c in report.data["comparisons"]]
    assert all("steps" in c and "p_sooner" in c for c in report.data["comparisons"])
    assert ("partition, refinement", "partition, reward variation") in labels


def test_planning_on_counts_is_exact_on_a_deterministic_task_and_improves_with_tries():
    exact = random_grid_mdp(36, slip=0.0, terminal_fraction=0.1, seed=1)
    for gaps in certainty_equivalence_gaps(exact, (1, 3), draws=2, seed=0).values():
        np.testing.assert_allclose(gaps, 0.0, atol=1e-9)
    slippery = random_grid_mdp(36, slip=0.6, terminal_fraction=0.1, seed=1)
    gaps = certainty_equivalence_gaps(slippery, (1, 20_000), draws=5, seed=0)
    assert (gaps[1] >= -1e-9).all() and gaps[1].max() > 1e-3  # one try misleads somewhere
    np.testing.assert_allclose(gaps[20_000], 0.0, atol=1e-9)  # enough tries find the optimum


def test_the_grounded_policy_of_a_learner_that_tried_every_pair_is_optimal():
    """R-max with one try a pair explores the deterministic goal grid whole in 200 episodes."""
    mdp = goal_grid()
    side = int(np.sqrt(mdp.n_states))
    opts = [subgoal_option(mdp, c, initiation="reachable")
            for c in (0, side - 1, side * (side - 1), side * side - 1)]
    part, _, _ = decision_layer(mdp, opts, delta=DELTA, epsilon=0.0)
    kw = dict(SETTINGS, runs=2, episodes=200, explore="r-max")
    np.testing.assert_allclose(
        grounded_policy_gaps(hierarchical_run(mdp, opts, part, **kw), mdp), 0.0, atol=1e-9)
    assert grounded_policy_gaps(
        hierarchical_run(mdp, opts, part, threshold=np.inf, **kw), mdp) is None


@pytest.mark.slow
def test_three_floor_arm_quick_and_resume(tmp_path):
    kb = str(tmp_path / "kb")
    report, files = _run("three-floor-arm", tmp_path, kb=kb)
    _check_common(report, files, tmp_path, 3600)
    assert report.data["settings"]["detector"] == "count-mc"
    # the directed-exploration pair: the unrefined layer cannot reach deliver's goal whatever
    # its values (its exact best block policy never arrives); no layer beats V*
    directed = report.data["directed_exploration"]
    rows = {r["learner"]: r for r in report.data["rows"]}
    off, on = directed["partition, no refinement, R-max"], directed["partition, refinement, R-max"]
    never = rows["flat Q"]["v_star_start"] + 1 / (1 - 0.99)
    assert off["refinements"] == [0, 0]
    np.testing.assert_allclose(off["layer_optimum_gap"], never, atol=1e-6)
    assert all(-1e-9 <= g <= never + 1e-6 for g in on["layer_optimum_gap"])
    assert {"partition, no refinement, R-max", "partition, refinement, R-max"} <= set(rows)
    # planning on 30 tries of every pair beats planning on 3; the learner's own samples too
    limit = report.data["sample_limit"]
    assert limit["samples_per_pair"] == [3, 30]
    few, more = (np.array(g) for g in limit["gaps"])
    assert np.median(more) < np.median(few) <= never + 1e-6 and (more >= -1e-9).all()
    assert all(-1e-9 <= g <= never + 1e-6 for g in limit["learner_samples_gap"])
    # a rerun on the same knowledge base recomputes none of the pipeline's stages
    again, _ = _run("three-floor-arm", tmp_path, kb=kb)
    assert all(s["reused"] for s in again.data["pipeline"]["stages"])
    assert again.data["rows"] == report.data["rows"]


@pytest.mark.slow
def test_three_floor_arm_planned_quick(tmp_path):
    """The planned learners run on the stored layer; without refinement the layer keeps its
    blocks and can never deliver; every gap lies between 0 and that of never delivering."""
    report, files = _run("three-floor-arm-planned", tmp_path, kb=str(tmp_path / "kb"))
    assert set(files) == {"json", "markdown"}
    rows = {r["learner"]: r for r in report.data["rows"]}
    assert set(rows) == {"flat Q", "partition, no refinement, planned",
                         "partition, refinement, planned"}
    never = rows["flat Q"]["v_star_start"] + 1 / (1 - 0.99)
    for row in rows.values():
        assert row["runs"] == 2 and -1e-9 <= row["final_gap_mean"] <= never + 1e-6
    off = report.data["layers"]["partition, no refinement, planned"]
    assert off["refinements"] == [0, 0] and off["blocks_after"] == [off["blocks_before"]] * 2
    np.testing.assert_allclose(off["layer_optimum_gap"], never, atol=1e-6)
    assert off["learner_samples_gap"] is None
    on = report.data["layers"]["partition, refinement, planned"]
    assert all(-1e-9 <= g <= never + 1e-6 for g in on["layer_optimum_gap"])
    assert report.data["settings"]["known_after"] == 2
    assert report.data["settings"]["split_offered"] is True
    for fig in report.figures:
        assert (tmp_path / "out" / fig.split("/")[-1]).stat().st_size > 1000


@pytest.mark.slow
def test_urban_quick(tmp_path):
    """Slow (about 90 s): 1,200 flat episodes of the first task on 20,004 states, then phases
    1-3 split the states into thousands of blocks (docs/hierarchical-learning.md)."""
    report, files = _run("urban", tmp_path)
    rows = _check_common(report, files, tmp_path, 20004)
    assert np.isfinite(rows["partition, refinement"]["v_star_start"])
    assert report.data["settings"]["new_task"] == "navigate-pickup"
    assert (rows["partition, reward variation"]["final_gap_max"]
            < rows["partition, no refinement"]["final_gap_mean"])

"""`task-sequence` (quick): five urban tasks, a built layer per later task, task five compared."""

from __future__ import annotations

import json
from itertools import pairwise

import numpy as np
import pytest

from adpart.experiments.base import ExperimentConfig, run_experiment
from adpart.experiments.task_sequence import TASKS, task_sequence  # noqa: F401 (registers)
from adpart.store import KnowledgeBase


@pytest.mark.slow
def test_quick_run_builds_a_layer_per_task_and_compares_task_five(tmp_path):
    kb_dir = tmp_path / "kb"
    config = ExperimentConfig(out=tmp_path / "out", runs=2, seed=0, quick=True, kb=str(kb_dir))
    report, files = run_experiment("task-sequence", config)
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["name"] == "task-sequence" and set(files) == {"json", "markdown"}
    layers = report.data["layers"]
    assert [layer["task"] for layer in layers] == list(TASKS[1:])
    stages = report.data["pipeline"]["stages"]
    built = [s for s in stages if s["stage"] == "hierarchy"]
    # layer k is built from the k tasks before it (the first task, then each later one)
    assert [len(s["detail"]["tasks"]) for s in built] == [1, 2, 3, 4]
    for layer in layers:
        trace = layer["trace"]
        assert all(b <= a for a, b in pairwise(trace))
    rows = report.data["pipeline"]["tasks"]
    # each later task: the layer, flat, the learner that knows the true dynamics (the sequence
    # runs in the true-model regime) and the planner's V* row
    assert {(r["task"], r["learner"]) for r in rows} == {(TASKS[0], "flat")} | {
        (t, learner) for t in TASKS[1:]
        for learner in ("hierarchical", "flat", "known-dynamics", "planner")}
    five = report.data["task_five"]
    kb = KnowledgeBase.open(str(kb_dir))
    try:
        for name in ("expected-learning-time", "all-subgoals"):
            rec = kb.get("partition", int(five[name]["partition"].split(":")[1]))
            assert rec.kind == "hierarchy"
            assert np.unique(kb.load(rec, "labels")).size == five[name]["initial_blocks"]
        subgoal_layer = kb.get("partition", int(five["all-subgoals"]["partition"].split(":")[1]))
        assert subgoal_layer.option_ids  # every subgoal option offered somewhere
    finally:
        kb.close()
    for name, finals in five["final_blocks"].items():
        initial = five["expected-learning-time" if name.startswith("expected") else
                       "all-subgoals"]["initial_blocks"]
        assert len(finals) == 2 and min(finals) >= initial  # refinement only adds blocks
    text = (tmp_path / "out" / "summary.md").read_text()
    assert "72" in text and "43" in text
    assert len(report.figures) == 7
    for fig in report.figures:
        assert (tmp_path / "out" / fig.split("/")[-1]).stat().st_size > 1000


def test_the_layer_sizes_figure_draws_each_tasks_built_and_offered_blocks():
    """Read back Fig. 5.19's bars: one pair per task, heights the given block counts."""
    from adpart.experiments.task_sequence import layer_sizes_figure

    fig = layer_sizes_figure(list(TASKS[1:]), [48, 57, 86, 47], [63, 84, 98, 58])
    ax = fig.axes[0]
    heights = {gid: [p.get_height() for p in ax.patches if p.get_gid() == gid]
               for gid in ("built", "offered")}
    assert heights == {"built": [48, 57, 86, 47], "offered": [63, 84, 98, 58]}
    assert [t.get_text() for t in ax.get_xticklabels()] == list(TASKS[1:])

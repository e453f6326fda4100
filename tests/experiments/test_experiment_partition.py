"""`partition-three-floor` (quick): partitions stored and checked, curves compared, report."""

from __future__ import annotations

import json

import numpy as np
import pytest

from adpart.experiments.base import ExperimentConfig, run_experiment
from adpart.experiments.partition_three_floor import partition_three_floor  # noqa: F401 (registers)
from adpart.store import KnowledgeBase


@pytest.mark.slow
def test_quick_run_partitions_learns_and_reports(tmp_path):
    kb_dir = tmp_path / "kb"
    config = ExperimentConfig(out=tmp_path / "out", runs=2, seed=0, quick=True, kb=str(kb_dir))
    report, files = run_experiment("partition-three-floor", config)
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["name"] == "partition-three-floor"
    parts = report.data["partitions"]
    for name in ("hand-designed", "discovered"):
        p = parts[name]
        assert p["states"] == 2900 and p["check"]["ok"]
        assert 1 < p["phase2"]["blocks"] <= p["phase3"]["blocks"] < 2900
        assert p["value_gap"]["inside_interval"] == 1.0
    assert parts["discovered"]["phase1"]["computed"] == len(parts["discovered"]["phase1"][
        "partitions"])
    learning = report.data["learning"]
    assert set(learning["episodes_to_threshold"]) == {
        "flat Q-learning", "SMDP Q (options)", "partition space"}
    assert len(report.data["comparisons"]) == 3
    for fig in report.figures:
        assert (tmp_path / "out" / fig.split("/")[-1]).stat().st_size > 1000
    assert "about 63" in (tmp_path / "out" / "summary.md").read_text()
    kb = KnowledgeBase.open(str(kb_dir))
    try:
        kinds = {p.kind for p in kb.records("partition")}
        final = kb.get("partition", int(parts["hand-designed"]["final"]["id"].split(":")[1]))
        labels = kb.load(final, "labels")
    finally:
        kb.close()
    assert kinds == {"per-option", "intersected", "reward-refined"}
    assert np.unique(labels).size == parts["hand-designed"]["final"]["blocks"]
    assert set(files) == {"json", "markdown"}

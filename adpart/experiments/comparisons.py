"""The default chain against what knows the same, on the benchmark's cells: one table per cell.

``adpart experiment comparisons`` runs ``adpart pipeline`` with its defaults (the seed's chain:
subgoals of the first task, options to them, the stored multi-phase layer, inconsistency
refinement) on each cell of :data:`CELLS` - a first task and a different second task - and writes
one comparison table per cell: every learner with what it knew (the knowledge record of each
run), the runs within the bound, the Kaplan-Meier median time to it in episodes and primitive
steps with 95 % CIs, the log-rank test of layer against flat, and the planner that knows what the
layer learner knows. Across cells it aggregates the layer's time over flat's the way rliable
does (the interquartile mean of per-run ratios to flat's median, with a stratified bootstrap CI).
The tables in docs/pipeline.md are this experiment's ``summary.md``; ``--quick`` runs a small
version (a few runs, two small cells) that the test suite checks.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from adpart.experiments.base import ExperimentConfig, ExperimentReport, experiment

__all__ = ["CELLS", "QUICK_CELLS", "Cell", "layer_ratios"]


@dataclass(frozen=True)
class Cell:
    """An environment and its task sequence (the first learned flat, the second transferred)."""

    env: str
    tasks: tuple[str, str]
    note: str = ""
    options: dict[str, Any] = field(default_factory=dict)


#: The benchmark's cells (issue texts: three-floor, urban, three-floor-arm and two Gymnasium
#: environments whose second task differs from the first).
CELLS = (
    Cell("three-floor", ("reach-goal", "reach-top-west"),
         "500 episodes, as make demo: in 300 fewer than half of flat's runs reach the bound",
         {"episodes": 500}),
    Cell("urban", ("navigate", "pickup-dropoff"),
         "scored every 10 episodes: an exact evaluation of 20 policies over 20,004 states each "
         "episode would take longer than the learning", {"eval_every": 10}),
    Cell("three-floor-arm", ("navigate", "deliver")),
    Cell("gym:FrozenLake-v1[map_name=8x8,is_slippery=false]", ("reward", "goal:row=0,col=7"),
         "the second task moves the goal to the top-right corner"),
    Cell("gym:CliffWalking-v1", ("reward", "goal:row=0,col=11"),
         "the second task moves the goal above the cliff's end"),
)
#: The quick version's cells: small, fast, and still a different second task each.
QUICK_CELLS = (
    Cell("two-rooms", ("reach-goal", "goal:x=9,y=5")),
    Cell("three-rooms-line", ("reach-east", "reach-middle")),
)


def _cell_table(pipe: Any) -> list[str]:
    from adpart.workflows.pipeline_table import comparison_lines

    return comparison_lines(pipe.rows)


#: Taylor & Stone's measures shown per learner beside the table (TransferMetrics attributes).
MEASURES = (("jumpstart", "jumpstart gap"), ("auc_episodes", "gap area (episodes)"),
            ("auc_steps", "gap area (steps)"), ("asymptotic_gap", "asymptotic gap"))


def _measures(pipe: Any, task: str, seed: int) -> tuple[list[str], dict[str, Any]]:
    """Per learner of ``task``: the run means of :data:`MEASURES` with 95 % bootstrap CIs."""
    from adpart.experiments.stats import bootstrap_ci
    from adpart.learning.comparison import interval_text, success_bound
    from adpart.learning.transfer_metrics import metrics_from_curve

    curves = pipe.curves.get(task, {})
    flat = curves.get("flat (no transfer)") or next(iter(curves.values()), None)  # or fallback
    if flat is None:
        return [], {}
    bound = success_bound(flat, pipe.config.gap_fraction)
    width = max(map(len, curves), default=5)
    lines = [f"{'curve':<{width}} " + " ".join(f"{title:>26}" for _, title in MEASURES)]
    data: dict[str, Any] = {}
    for label, curve in curves.items():
        m = metrics_from_curve(curve, bound)
        cis = {name: bootstrap_ci(getattr(m, name), statistic="mean", seed=seed)
               for name, _ in MEASURES}
        data[label] = {name: list(ci) for name, ci in cis.items()}
        cells = " ".join(f"{interval_text(e, lo, hi):>26}" for e, lo, hi in cis.values())
        lines.append(f"{label:<{width}} {cells}")
    return lines, data


def layer_ratios(pipe: Any, task: str, baseline: str = "flat",
                 unit: str = "episodes") -> np.ndarray | None:
    """Per layer run on ``task``, its time to the bound (``unit``: episodes or steps) over the
    Kaplan-Meier median of the curve whose label starts with ``baseline`` (censored runs: inf);
    None when a curve is missing or the baseline's median lies beyond its budget."""
    from adpart.learning.comparison import success_bound
    from adpart.learning.transfer_metrics import km_median, metrics_from_curve

    curves = pipe.curves.get(task, {})
    layer = next((c for label, c in curves.items() if label.startswith("hierarchical")), None)
    base_curve = next((c for label, c in curves.items() if label.startswith(baseline)), None)
    flat = curves.get("flat (no transfer)")
    if layer is None or base_curve is None or flat is None:
        return None
    bound = success_bound(flat, pipe.config.gap_fraction)
    a, b = metrics_from_curve(layer, bound), metrics_from_curve(base_curve, bound)
    base = km_median(*b.event_times(unit)).estimate
    if not np.isfinite(base) or base <= 0:  # beyond its budget: no ratio to aggregate
        return None
    times, censored = a.event_times(unit)
    return np.where(censored, np.inf, times) / base


@experiment(
    "comparisons",
    "The default chain against flat Q-learning and the planner that knows as much, per cell",
    "section 5.1's comparisons, under every learner's declared knowledge",
)
def comparisons(config: ExperimentConfig) -> ExperimentReport:
    """Run the pipeline's defaults on every cell and tabulate the comparison (module docstring)."""
    from adpart.learning.transfer_metrics import iqm
    from adpart.workflows.pipeline import PipelineConfig, run_pipeline
    from adpart.workflows.working_kb import working_kb

    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    cells = QUICK_CELLS if config.quick else CELLS
    # every episode is scored, so that no figure is set by the first evaluation point
    sizes = ({"runs": min(config.runs, 3), "episodes": 60, "first_episodes": 150}
             if config.quick else {"runs": config.runs})
    report = ExperimentReport("comparisons", "the default chain against what knows the same")
    report.seed_reports = [
        ("5.1: on each domain the layer learned from the first task's subgoals learns the "
         "second task faster than flat Q-learning (three-floor: about 30 against 500 "
         "iterations)."),
    ]
    tables: dict[str, list[str]] = {}
    ratios: list[np.ndarray] = []
    cell_data = []
    with working_kb(config.kb, "comparisons") as kb:
        for cell in cells:
            config.progress(f"{cell.env}: {' -> '.join(cell.tasks)}")
            pcfg = PipelineConfig(env=cell.env, tasks=cell.tasks, seed=config.seed,
                                  **{"eval_every": 1, **sizes, **cell.options})
            pipe = run_pipeline(kb, pcfg, out=out / _folder(cell.env),
                                progress=config.progress)
            measures, measured = _measures(pipe, cell.tasks[1], config.seed)
            title = (f"{cell.tasks[1]}, run means with 95 % bootstrap CIs (Taylor & Stone "
                     "2009; gaps scored as in docs/transfer-metrics.md):")
            tables[cell.env] = [*_cell_table(pipe), "", title, *measures]
            r = layer_ratios(pipe, cell.tasks[1])
            if r is not None:
                ratios.append(r)
            cell_data.append({"env": cell.env, "tasks": list(cell.tasks), "note": cell.note,
                              "rows": pipe.rows, "measures": measured,
                              "stages": [s.stage for s in pipe.stages],
                              "rehearsal": next((s.detail for s in pipe.stages
                                                 if s.stage == "rehearse"), None),
                              "figures": [str(Path(f).relative_to(out)) for f in pipe.figures]})
    report.data["cells"] = cell_data
    from adpart.workflows.regime import LEARNED_EXPLORATION
    from adpart.workflows.rehearsal import REHEARSAL_GOALS, REHEARSAL_RUNS

    report.data["settings"] = {"seed": config.seed, "eval_every": 1, **sizes,
                               "defaults": "adpart pipeline's", "regime": "learned-model",
                               "explore": LEARNED_EXPLORATION,
                               "rehearsal": {"goals": REHEARSAL_GOALS,
                                             "runs_per_goal": REHEARSAL_RUNS}}
    for cell, data in zip(cells, cell_data, strict=True):
        lines = tables[cell.env]
        report.findings.append(
            f"{cell.env}, {' -> '.join(cell.tasks)}{f' ({cell.note})' if cell.note else ''}:"
            "\n\n```\n" + "\n".join(lines) + "\n```")
        if data["rehearsal"] is not None:
            report.findings.append(f"{cell.env}: {data['rehearsal']['reason']}")
        if "fallback" in data["stages"]:
            report.findings.append(f"{cell.env}: the pipeline fell back to flat learning for "
                                   f"{cell.tasks[1]}: {_fallback_reason(data)}")
    if ratios:
        agg = iqm(ratios, seed=config.seed)
        report.data["iqm_ratio_to_flat"] = list(agg)
        report.findings.append(
            f"over the {len(ratios)} cells learned on a layer with flat's median within its "
            f"budget: interquartile mean of each layer "
            f"run's episodes to the bound over flat's Kaplan-Meier median = {agg.estimate:.3g} "
            f"(95 % stratified bootstrap CI {agg.low:.3g}-{agg.high:.3g}; a censored run counts "
            "as never).")
    else:
        report.findings.append("no cell was learned on a layer: every later task fell back to "
                               "flat learning")
    return report


def _folder(env: str) -> str:
    from adpart.workflows.reports import folder_name

    return folder_name(env)


def _fallback_reason(data: dict[str, Any]) -> str:
    rows = [r for r in data["rows"] if r["learner"] == "flat-fallback"]
    return rows[0].get("fallback", "") if rows else ""

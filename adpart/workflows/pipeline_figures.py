"""The pipeline's figures: a value-gap plot per task, the subgoals and every layer on the map.

:func:`write_figures` is called by :func:`adpart.workflows.pipeline.run_pipeline` at its end.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from adpart.learning.curves import plot_curves
from adpart.workflows.refs import parse_ref
from adpart.workflows.reports import folder_name

if TYPE_CHECKING:
    from adpart.workflows.pipeline import PipelineConfig, PipelineReport
    from adpart.workflows.store import KnowledgeStore


def _maps(kb: KnowledgeStore, report: PipelineReport, config: PipelineConfig, out: Path) -> None:
    """The subgoals found and every decision layer used, drawn on the map (Figs. 4.2, 4.5)."""
    from adpart.errors import ModelError
    from adpart.workflows.resolve import resolve_domain

    domain = resolve_domain(config.env)
    own = [r["task"] for r in report.rows
           if r["learner"] == "hierarchical" and r.get("partition") is None]
    try:
        for stage in report.stages:
            if stage.stage == "discover" and stage.detail.get("subgoals"):
                mask = np.zeros(domain.n_states, dtype=bool)
                mask[stage.detail["subgoals"]] = True
                path = out / f"subgoals_{folder_name(stage.task or config.env)}.png"
                domain.render(str(path), marked=mask, task=stage.task, mark_label="subgoals",
                              title=(f"{config.env}: {int(mask.sum())} subgoals in the policy "
                                     f"of {stage.task} ({config.detector})"))
            elif stage.stage in ("partition", "hierarchy") and stage.task not in own:
                record = kb.get("partition", parse_ref(stage.result, "partition"))
                labels = kb.load(record, "labels")
                path = out / f"layer_{folder_name(stage.task or config.env)}.png"
                domain.render(str(path), labels=labels, task=stage.task, title=(
                    f"{config.env}/{stage.task}: decision layer {record.ref}, "
                    f"{record.n_blocks} blocks before refinement"))
            else:
                continue
            report.figures.append(str(path))
        for task in own:  # the layers the reward-variation modes built themselves
            report.figures.append(str(_draw_own_layer(kb, report, config, domain, task, out)))
    except ModelError:
        return  # a domain without a map (x, y features): nothing to draw


def _draw_own_layer(kb: KnowledgeStore, report: PipelineReport, config: PipelineConfig, domain: Any,
                    task: str, out: Path) -> Path:
    """The layer a reward-variation mode learns on: the multi-phase partition over the
    discovered options plus the options to ``task``'s reward states (the learner's own call)."""
    from adpart.learning.decision_layer import decision_layer, reward_options
    from adpart.workflows.options import load_options

    stage = next((s for s in report.stages if s.stage == "options"), None)
    records = [] if stage is None else [kb.get("option", parse_ref(r, "option"))
                                        for r in stage.result.split(",")]
    options = load_options(kb, records)[0] if records else []
    mdp = domain.mdp(task)
    extra = reward_options(mdp)
    layer, _, _ = decision_layer(mdp, options + extra, delta=config.partition.delta,
                                 epsilon=config.partition.reward_epsilon)
    path = out / f"layer_{folder_name(task)}.png"
    domain.render(str(path), labels=layer.labels, task=task, title=(
        f"{config.env}/{task}: decision layer of {len(options)} subgoal and {len(extra)} "
        f"reward-state options, {layer.n_blocks} blocks before refinement"))
    return path


def write_figures(kb: KnowledgeStore, report: PipelineReport, config: PipelineConfig,
                  out: Path | None) -> None:
    """One value-gap figure per task (every learner, the success bound) and the maps, in ``out``."""
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        for task, curves in report.curves.items():
            path = out / f"{folder_name(task)}.png"
            rows = [r for r in report.rows if r["task"] == task and np.isfinite(r["bound"])]
            plot_curves(
                curves,
                path,
                metric="value_gap",
                title=(f"{config.env}/{task}: value gap of the greedy policy\n"
                       f"{config.runs} runs per learner, {config.regime} regime"),
                bound=rows[0]["bound"] if rows else None,
                bound_label=f"success bound ({config.gap_fraction:.0%} of |V*|)",
            )
            report.figures.append(str(path))
        _maps(kb, report, config, out)

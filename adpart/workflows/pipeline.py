"""The transfer pipeline of the dissertation (Fig. 4.1, sections 4.1-4.3) as one procedure.

1. learn the first task flat (Q-learning);
2. discover subgoals in its best learned policy (a detector plugin);
3. learn options to the subgoals and their exact multi-time models;
4. partition the state space over the options - phases 1-2 before the next task's reward is
   used, phase 3 once it is;
5. learn every later task on that decision layer with the hierarchical learner (refinement
   where flat and abstract values disagree), and flat without transfer for comparison.

Every step first looks in the knowledge base for a result of exactly the same request and reuses
it, so a pipeline run again - or resumed after being killed - recomputes nothing it already has.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from adpart.errors import TaskError
from adpart.experiments.stats import episodes_to_threshold
from adpart.learning.curves import LearningCurve, plot_curves
from adpart.workflows.discovery import discover_subgoals
from adpart.workflows.learning import (
    LearnRequest,
    find_learning,
    load_curve,
    record_learning,
    run_learning,
)
from adpart.workflows.options import options_for_subgoals
from adpart.workflows.partitioning import partition_environment
from adpart.workflows.refs import parse_ref


@dataclass(frozen=True)
class PipelineConfig:
    """Settings of one pipeline run.

    Attributes:
        env: environment name.
        tasks: the task sequence; the first is learned flat, the others on the decision layer.
        detector, detector_params: the subgoal detector plugin and its parameters.
        initiation: initiation sets of the subgoal options (``basin`` or ``reachable``).
        delta, epsilon: the partition's delta (eq. 4.6) and reward epsilon (eq. 4.7).
        runs, episodes, first_episodes: runs per learner, episodes per later task, episodes of
            the first (flat) task.
        seed, eval_every: root seed; exact scoring every this many episodes.
        flat_params, hierarchical_params: learner parameters (as on the command line).
        baseline: also learn each later task flat (no transfer) for the comparison.
        gap_fraction: a run has "learned" a task once its greedy policy's value gap stays below
            this fraction of ``|V*|`` at the start distribution (reported as episodes-to-bound).
    """

    env: str
    tasks: tuple[str, ...]
    detector: str = "count-exhaustive"
    detector_params: dict[str, Any] = field(default_factory=dict)
    initiation: str = "basin"
    delta: float = 0.3
    epsilon: float = 10.0
    runs: int = 10
    episodes: int = 300
    first_episodes: int = 500
    seed: int = 0
    eval_every: int = 10
    flat_params: dict[str, Any] = field(default_factory=dict)
    hierarchical_params: dict[str, Any] = field(default_factory=dict)
    baseline: bool = True
    gap_fraction: float = 0.05

    def __post_init__(self) -> None:
        if len(self.tasks) < 2:
            raise TaskError(
                "a pipeline needs at least two tasks: the first is learned flat, later ones "
                "transfer (e.g. --tasks reach-goal,reach-top-west)"
            )


@dataclass
class Stage:
    """One step of the pipeline: what it produced, and whether it came from the KB."""

    stage: str
    task: str | None
    result: str
    reused: bool
    seconds: float
    detail: dict[str, Any] = field(default_factory=dict)


@dataclass
class PipelineReport:
    config: PipelineConfig
    stages: list[Stage] = field(default_factory=list)
    rows: list[dict[str, Any]] = field(default_factory=list)
    curves: dict[str, dict[str, LearningCurve]] = field(default_factory=dict)
    figures: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        return {
            "config": asdict(self.config),
            "stages": [asdict(s) for s in self.stages],
            "tasks": self.rows,
            "figures": self.figures,
        }


def _learn(kb: Any, request: LearnRequest, report: PipelineReport, stage: str) -> tuple[dict, Any]:
    start = time.perf_counter()
    ids = find_learning(kb, request)
    reused = ids is not None
    if ids is None:
        ids = record_learning(kb, run_learning(request, kb=kb))
    run = kb.get("run", parse_ref(ids["run"], "run"))
    curve = load_curve(kb, run)
    report.stages.append(
        Stage(stage, request.task, ids["run"], reused, time.perf_counter() - start)
    )
    return ids, curve


def task_row(
    task: str, label: str, curve: LearningCurve, fraction: float, extra: dict[str, Any]
) -> dict[str, Any]:
    v_star = float(curve.metadata.get("v_star_start", np.nan))
    bound = max(1e-9, fraction * abs(v_star)) if np.isfinite(v_star) else np.inf
    to_bound = episodes_to_threshold(curve.matrix("value_gap"), curve.evaluated_episodes(), bound)
    final = curve.matrix("value_gap")[:, -1]
    return {
        "task": task,
        "learner": label,
        "runs": curve.n_runs,
        "v_star_start": v_star,
        "bound": bound,
        "final_gap_mean": float(np.mean(final)),
        "final_gap_max": float(np.max(final)),
        "runs_within_bound": int(np.sum(final <= bound)),
        "episodes_to_bound_median": float(np.median(to_bound)),
        "steps_total_mean": float(curve.matrix("steps").sum(axis=1).mean()),
        "decisions_total_mean": float(curve.matrix("decisions").sum(axis=1).mean()),
        **extra,
    }


def run_pipeline(
    kb: Any,
    config: PipelineConfig,
    *,
    out: Path | None = None,
    progress: Callable[[str], object] | None = None,
) -> PipelineReport:
    """Run (or resume) the pipeline for ``config``; figures go to ``out`` when given."""
    say = progress or (lambda message: None)
    report = PipelineReport(config)
    first, *later = config.tasks
    flat = dict(config.flat_params)

    say(f"learning {first} flat ({config.runs} runs x {config.first_episodes} episodes)")
    first_req = LearnRequest(
        env=config.env,
        task=first,
        learner="q-learning",
        params=flat,
        runs=config.runs,
        episodes=config.first_episodes,
        seed=config.seed,
        eval_every=config.eval_every,
    )
    first_ids, first_curve = _learn(kb, first_req, report, "learn-flat")
    report.curves[first] = {"flat": first_curve}
    report.rows.append(task_row(first, "flat", first_curve, config.gap_fraction, {}))

    best = int(np.argmin(first_curve.matrix("value_gap")[:, -1]))
    policy = kb.get("policy", parse_ref(first_ids["policies"][best], "policy"))
    say(f"discovering subgoals in {policy.ref} with {config.detector}")
    found = discover_subgoals(
        kb, policy, detector=config.detector, params=config.detector_params, seed=config.seed
    )
    report.stages.append(
        Stage(
            "discover",
            first,
            found.record.ref,
            found.reused,
            found.seconds,
            {"subgoals": found.result.subgoals.tolist(), "threshold": found.result.threshold},
        )
    )
    if found.result.subgoals.size == 0:
        raise TaskError(
            f"{config.detector} found no subgoals in {policy.ref}; try another detector or "
            "learn the first task longer"
        )

    say(f"learning options to {found.result.subgoals.size} subgoals")
    start = time.perf_counter()
    stored = options_for_subgoals(kb, found.record, initiation=config.initiation)
    report.stages.append(
        Stage(
            "options",
            None,
            ",".join(r.ref for r in stored.records),
            stored.reused,
            time.perf_counter() - start,
        )
    )

    for task in later:
        say(f"partitioning for {task} (delta {config.delta}, epsilon {config.epsilon})")
        part = partition_environment(
            kb, config.env, found.record.ref, delta=config.delta, epsilon=config.epsilon, task=task
        )
        summary = part.summary()
        report.stages.append(
            Stage(
                "partition",
                task,
                part.final_record.ref,
                all(p.reused for p in part.phase1)
                and part.phase2.reused
                and (part.phase3 is None or part.phase3.reused),
                sum(part.seconds.values()),
                {
                    "phase1_blocks": [p.blocks for p in part.phase1],
                    "phase2_blocks": part.phase2.blocks,
                    "final_blocks": part.final.n_blocks,
                    "check": summary["check"],
                    "value_gap": summary["value_gap"],
                },
            )
        )
        say(f"learning {task} on {part.final.n_blocks} blocks (hierarchical)")
        hier_req = LearnRequest(
            env=config.env,
            task=task,
            learner="hierarchical",
            params=dict(config.hierarchical_params),
            runs=config.runs,
            episodes=config.episodes,
            seed=config.seed,
            eval_every=config.eval_every,
            partition=part.final_record.ref,
        )
        _, hier_curve = _learn(kb, hier_req, report, "learn-hierarchical")
        report.curves[task] = {f"partition ({part.final.n_blocks} blocks)": hier_curve}
        report.rows.append(
            task_row(
                task,
                "hierarchical",
                hier_curve,
                config.gap_fraction,
                {"initial_blocks": part.final.n_blocks, "partition": part.final_record.ref},
            )
        )
        if config.baseline:
            say(f"learning {task} flat for comparison")
            base_req = LearnRequest(
                env=config.env,
                task=task,
                learner="q-learning",
                params=flat,
                runs=config.runs,
                episodes=config.episodes,
                seed=config.seed,
                eval_every=config.eval_every,
            )
            _, base_curve = _learn(kb, base_req, report, "learn-flat")
            report.curves[task]["flat (no transfer)"] = base_curve
            report.rows.append(task_row(task, "flat", base_curve, config.gap_fraction, {}))

    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        for task, curves in report.curves.items():
            path = out / f"{task}.png"
            plot_curves(
                curves,
                path,
                metric="value_gap",
                title=f"{config.env}/{task}: value gap of the greedy policy",
            )
            report.figures.append(str(path))
    return report

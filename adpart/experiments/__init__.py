"""The seed's experiments as runnable, plotted, stored procedures (``adpart experiment NAME``)."""

from __future__ import annotations

import importlib

from adpart.experiments.base import (
    EXPERIMENTS,
    Experiment,
    ExperimentConfig,
    ExperimentReport,
    experiment,
    get_experiment,
    run_experiment,
)

#: Modules that define experiments (imported on first lookup).
EXPERIMENT_MODULES: tuple[str, ...] = (
    "adpart.experiments.subgoals",
    "adpart.experiments.options_three_floor",
    "adpart.experiments.partition_three_floor",
    "adpart.experiments.task_sequence",
    "adpart.experiments.transfer",
    "adpart.experiments.arm_planned",
    "adpart.experiments.maxq",
    "adpart.experiments.maxq_parr",
    "adpart.experiments.comparisons",
    "adpart.experiments.random_goals",
    "adpart.experiments.benchmark",
    "adpart.experiments.methods",
)


def load_all() -> None:
    for module in EXPERIMENT_MODULES:
        importlib.import_module(module)


__all__ = [
    "EXPERIMENTS",
    "Experiment",
    "ExperimentConfig",
    "ExperimentReport",
    "experiment",
    "get_experiment",
    "load_all",
    "run_experiment",
]

"""The experiment framework: a registry of named procedures and the report each one writes.

An experiment reproduces one of the dissertation's figures end to end. It receives an
:class:`ExperimentConfig` (output folder, runs, seed, a ``quick`` flag for a small version that the
default test suite runs) and returns an :class:`ExperimentReport`, which is written as
``summary.json`` (every number), ``summary.md`` (the seed's figure next to ours, in words) and the
PNG figures the experiment drew.
"""

from __future__ import annotations

import difflib
import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from adpart.errors import UnknownNameError
from adpart.workflows.reports import strict_json


@dataclass(frozen=True)
class ExperimentConfig:
    """Settings shared by every experiment.

    Attributes:
        out: folder for figures and summaries (created).
        runs: independent runs per learner (the seed averages 50; issue texts ask >= 20).
        seed: root seed; everything random derives from it.
        quick: a small, fast version (fewer runs and episodes) for tests and smoke runs.
        kb: knowledge-base location, or None for no recording.
        progress: called with one-line status messages.
    """

    out: Path
    runs: int = 20
    seed: int = 0
    quick: bool = False
    kb: str | None = None
    progress: Callable[[str], None] = field(default=lambda message: None)


@dataclass
class ExperimentReport:
    """What an experiment found: numbers, figures, and the comparison with the seed."""

    name: str
    title: str
    data: dict[str, Any] = field(default_factory=dict)
    figures: list[str] = field(default_factory=list)
    findings: list[str] = field(default_factory=list)
    seed_reports: list[str] = field(default_factory=list)
    seconds: float = 0.0
    #: the shared settings it ran with (runs, seed, quick), so `adpart report` can rerun it
    settings: dict[str, Any] = field(default_factory=dict)

    def write(self, out: Path) -> dict[str, str]:
        out.mkdir(parents=True, exist_ok=True)
        summary = {
            "name": self.name,
            "title": self.title,
            "seconds": round(self.seconds, 3),
            "settings": self.settings,
            "figures": self.figures,
            "seed_reports": self.seed_reports,
            "findings": self.findings,
            "data": self.data,
        }
        (out / "summary.json").write_text(strict_json(summary))
        lines = [
            f"# {self.title}",
            "",
            f"`adpart experiment {self.name}` ({self.seconds:.1f} s)",
            "",
        ]
        record = self.data.get("settings")
        if isinstance(record, dict) and record:  # the result's settings record, in one place
            lines += ["## Settings", ""]
            lines += [f"- `{key}`: `{json.dumps(value)}`" for key, value in record.items()] + [""]
        lines += ["## What the dissertation reports", ""]
        lines += [f"- {line}" for line in self.seed_reports] + [""]
        lines += ["## What we measured", ""]
        lines += [f"- {line}" for line in self.findings] + [""]
        known = knowledge_of(self.data)
        if known:
            note = ("Each run's knowledge record (docs/knowledge.md), its learner's own with "
                    "that of the options and the layer it was given on top (the same record "
                    "with other run ids appears once per cell).")
            lines += ["## What each learner knew", "", note, ""]
            lines += [f"- {learner}: {label}" for learner, label in known] + [""]
        lines += ["## Figures", ""] + [f"![{Path(f).stem}]({Path(f).name})" for f in self.figures]
        (out / "summary.md").write_text("\n".join(lines) + "\n")
        return {"json": str(out / "summary.json"), "markdown": str(out / "summary.md")}


def knowledge_of(data: Any) -> list[tuple[str, str]]:
    """The distinct ``(learner, knowledge label)`` of every row in ``data`` (any depth)."""
    found: dict[tuple[str, str], None] = {}

    def walk(node: Any) -> None:
        if isinstance(node, dict):
            if isinstance(node.get("learner"), str) and isinstance(node.get("knowledge"), str):
                found[(node["learner"], node["knowledge"])] = None
            for value in node.values():
                walk(value)
        elif isinstance(node, (list, tuple)):
            for value in node:
                walk(value)

    walk(data)
    return list(found)


ExperimentFn = Callable[[ExperimentConfig], ExperimentReport]


@dataclass(frozen=True)
class Experiment:
    name: str
    title: str
    figures: str
    run: ExperimentFn


EXPERIMENTS: dict[str, Experiment] = {}


def experiment(name: str, title: str, figures: str) -> Callable[[ExperimentFn], ExperimentFn]:
    """Register ``fn`` as ``adpart experiment NAME`` (``figures`` names the seed's figures)."""

    def decorate(fn: ExperimentFn) -> ExperimentFn:
        EXPERIMENTS[name] = Experiment(name, title, figures, fn)
        return fn

    return decorate


def get_experiment(name: str) -> Experiment:
    from adpart.experiments import load_all

    load_all()
    if name not in EXPERIMENTS:
        hint = difflib.get_close_matches(name, list(EXPERIMENTS), n=1)
        raise UnknownNameError(
            f"no experiment named {name!r}; experiments: {', '.join(sorted(EXPERIMENTS))}"
            + (f". Did you mean {hint[0]!r}?" if hint else "")
        )
    return EXPERIMENTS[name]


def run_experiment(name: str, config: ExperimentConfig) -> tuple[ExperimentReport, dict[str, str]]:
    """Run experiment ``name`` and write its report into ``config.out``."""
    exp = get_experiment(name)
    start = time.perf_counter()
    report = exp.run(config)
    report.seconds = time.perf_counter() - start
    report.settings = {"runs": config.runs, "seed": config.seed, "quick": config.quick}
    return report, report.write(config.out)

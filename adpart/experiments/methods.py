"""The field's option sources and transfer learners side by side, on the benchmark's cells.

``adpart experiment methods`` runs every option source x every transfer learner that uses
options, and the transfer learners that use none, on each cell of
:data:`adpart.experiments.benchmark.BENCHMARK_CELLS` (a first task learned flat, a different
second task), in each knowledge regime (:data:`REGIMES_RUN`):

* **learned-model**: what any method knows of the dynamics is the counts model of the first
  task's runs, and every method observes the second task's rewards;
* **true-model** (the seed's figures): the options, their models and the layer are computed on
  the second task's true model (phase 3 reads its rewards), SF-GPI's successor features on the
  true dynamics, and the planner knows the true dynamics.

The methods:

* **Option sources** (subgoal detectors, :data:`SOURCES`): the seed's count metric, exhaustive
  and Monte Carlo (``count-exhaustive``, ``count-mc``, section 4.1), and with the reward states
  added (``reward-variation``, 4.3.1), betweenness (Şimşek & Barto 2008), eigenoptions' sinks
  (Machado et al. 2017), covering options' ends (Jinnai et al. 2019) and the ``simpleoptions``
  package's diffusion options, each run on the regime's model (docs/subgoals.md); the options
  to their subgoals are solved on it too.
* **Transfer learners over a source's options**: the decision layer with inconsistency
  refinement (``hierarchical``, the seed's chain without the rehearsal's fallback, so that the
  method itself is measured; ``adpart experiment benchmark`` measures the default chain), and
  SMDP Q-learning over the options and the primitive actions (``smdp-q``). A source that finds
  no subgoal on a cell leaves the chain nothing to transfer: both its learners are flat
  Q-learning there (as the pipeline does), and the tables say so.
* **Transfer learners without options**: successor features of the first task's policies with
  GPI (``sf-gpi``, Barreto et al. 2017), and the flat planner that knows what the layer knows
  of the dynamics (``estimated-dynamics`` on the same counts, ``known-dynamics`` on the true
  model).
* **The baseline**: flat Q-learning, which knows nothing (every ratio is to it).

Per cell and method: the ratio of Kaplan-Meier medians of episodes to the bound over flat's in
the same run, with a 95 % bootstrap CI (censored runs stay censored). Per method and regime over
the same cells for all: the interquartile mean of each run's episodes over the cell's scale
(flat's median, or its budget where the median lies beyond it) with a stratified bootstrap CI,
the probability that a run of the method reaches the bound sooner than a flat run of the same
cell, and the run-score performance profile. Figures per regime (the true-model regime's names
end in ``-true-model``): ``methods-profile.png`` (the profiles, a panel per option learner),
``methods-iqm.png`` and ``methods-probability.png`` (each aggregate with its CI); a table per
cell in ``methods-cells.md``. A cell whose pipeline raises is recorded and the rest still run.
Every setting is in the summary's settings record.
"""

from __future__ import annotations

import os
import sys
import tempfile
from contextlib import nullcontext
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from adpart.experiments.base import ExperimentConfig, ExperimentReport, experiment
from adpart.experiments.benchmark import BENCHMARK_CELLS, PROFILE_TAUS, QUICK_BENCHMARK_CELLS
from adpart.experiments.methods_figures import (
    cell_tables,
    draw_intervals,
    draw_profile_panels,
    ratio_text,
)

__all__ = ["BASELINE", "MODEL_BASED", "OPTION_LEARNERS", "REGIMES_RUN", "SOURCES", "method_times"]

#: The option sources: a name -> its subgoal detector plugin and that plugin's parameters, each
#: run on the regime's model. ``reward-variation`` adds the first task's reward states to the count
#: metric's subgoals (section 4.3.1); ``diffusion`` is the ``simpleoptions`` package's diffusion
#: options, keeping the top 4 local maxima of the diffusion score, as betweenness keeps its top 4
#: (it needs the optional package: without it the source is left out and the summary says so).
SOURCES: dict[str, tuple[str, dict[str, Any]]] = {
    "count-exhaustive": ("count-exhaustive", {}),
    "count-mc": ("count-mc", {}),
    "reward-variation": ("reward-variation", {}),
    "betweenness": ("betweenness", {}),
    "eigenoptions": ("eigenoptions", {}),
    "covering": ("covering", {}),
    "diffusion": ("simpleoptions", {"generator": "diffusion", "top": 4}),
}
#: The sources that need an optional package, and the package.
OPTIONAL_SOURCES = {"diffusion": "simpleoptions"}
#: The learners over a source's options (their row names).
OPTION_LEARNERS = ("layer", "smdp-q")
#: The flat planner that knows what the layer learner knows of the dynamics, by regime.
MODEL_BASED = ("estimated-dynamics", "known-dynamics")
#: The baseline every ratio is to.
BASELINE = "flat"
#: The knowledge regimes the methods are run in, and what each gives every method.
REGIMES_RUN = ("learned-model", "true-model")
REGIME_TEXT = {
    "learned-model": "every method's dynamics are the counts of the first task's runs, rewards "
                     "observed",
    "true-model": "the seed's: options, option models and the layer on the new task's true model "
                  "(phase 3 reads its rewards), SF-GPI on the true dynamics, the planner knows "
                  "the true dynamics; flat Q-learning knows nothing in both",
}
#: A run has learned the task once its value gap stays below this fraction of |V*|.
GAP_FRACTION = 0.1


def method_times(curve: Any, flat: Any, fraction: float
                 ) -> tuple[np.ndarray, np.ndarray, float, float, dict[str, Any]]:
    """Per run of ``curve``: its episodes to the bound (inf: censored) and those over the
    cell's scale - flat's Kaplan-Meier median, or flat's budget where that median lies beyond
    it (which overstates every method's ratio on that cell: flat's true median is larger) -;
    the scale; the curve's own KM median (inf: beyond its budget); and the KM-median ratio to
    flat with its CI (:func:`adpart.learning.comparison.time_ratio`)."""
    from adpart.learning.comparison import success_bound, time_ratio
    from adpart.learning.transfer_metrics import km_median, metrics_from_curve

    bound = success_bound(flat, fraction)
    median = km_median(*metrics_from_curve(flat, bound).event_times("episodes")).estimate
    scale = float(median) if np.isfinite(median) and median > 0 else float(flat.n_episodes)
    times, censored = metrics_from_curve(curve, bound).event_times("episodes")
    own = float(km_median(times, censored).estimate)
    episodes = np.where(censored, np.inf, times).astype(np.float64)
    return episodes, episodes / scale, scale, own, time_ratio(curve, flat, fraction, 0)


def _within(curve: Any, flat: Any, fraction: float) -> str:
    from adpart.learning.comparison import success_bound
    from adpart.learning.transfer_metrics import metrics_from_curve

    _, censored = metrics_from_curve(curve, success_bound(flat, fraction)).event_times(
        "episodes")
    return f"{int((~censored).sum())}/{censored.size}"


def _cell_methods(kb: Any, cell: Any, sizes: dict[str, Any], config: ExperimentConfig,
                  out: Path, regime: str, sources: list[str]
                  ) -> tuple[dict[str, Any], dict[str, str], list[str], set[str]]:
    """One cell in one knowledge regime: every method's curve (label -> curve), its knowledge
    label, notes, and the methods that learned flat because their source found no subgoal."""
    from adpart.workflows.experience import estimated_environment
    from adpart.workflows.learning import LearnRequest
    from adpart.workflows.pipeline import (
        PipelineConfig,
        episode_defaults,
        learn_stored,
        learner_defaults,
        run_pipeline,
    )
    from adpart.workflows.reports import folder_name

    curves: dict[str, Any] = {}
    knows: dict[str, str] = {}
    notes: list[str] = []
    flat_instead: set[str] = set()  # a source's learners where it found no subgoal
    first, task = cell.tasks
    base = {"eval_every": 1, **sizes, **cell.options}
    defaults = episode_defaults(cell.env)
    model_env = first_run = None
    for source in sources:
        detector, params = SOURCES[source]
        pcfg = PipelineConfig(env=cell.env, tasks=cell.tasks, seed=config.seed, detector=detector,
                              detector_params=dict(params), fallback=False, regime=regime, **base)
        pipe = run_pipeline(kb, pcfg, out=out / f"{folder_name(cell.env)}-{source}",
                            progress=config.progress)
        rows = {r["learner"]: r for r in pipe.rows if r["task"] == task}
        for label, curve in pipe.curves[task].items():
            if label.startswith("flat (no transfer)"):
                curves[BASELINE], knows[BASELINE] = curve, rows["flat"]["knowledge"]
            elif label.startswith("flat (no subgoals)"):
                curves.setdefault(BASELINE, curve)
                knows.setdefault(BASELINE, rows["flat"]["knowledge"])
                notes.append(f"{source} found no subgoals")
                for learner in OPTION_LEARNERS:  # what the chain does then: it learns flat
                    curves[f"{learner} [{source}]"] = curve
                    knows[f"{learner} [{source}]"] = rows["flat"]["knowledge"]
                    flat_instead.add(f"{learner} [{source}]")
            elif label.startswith("hierarchical"):
                curves[f"layer [{source}]"] = curve
                knows[f"layer [{source}]"] = rows["hierarchical"]["knowledge"]
            elif label.split(" ", 1)[0] in MODEL_BASED:  # the knowledge-matched planner
                based = label.split(" ", 1)[0]
                curves[based], knows[based] = curve, rows[based]["knowledge"]
        estimate = next((s for s in pipe.stages if s.stage == "estimate"), None)
        model_env = estimate.result if estimate is not None else model_env
        first_run = first_run or next(s.result for s in pipe.stages
                                      if s.stage == "learn-flat" and s.task == first)
        options = next((s.result for s in pipe.stages if s.stage == "options"), None)
        if options:
            req = LearnRequest(env=cell.env, task=task, learner="smdp-q",
                               params={**learner_defaults("smdp-q", defaults),
                                       "include-primitives": True},
                               runs=pcfg.runs, episodes=pcfg.episodes, seed=config.seed,
                               eval_every=1, options=options, model=model_env)
            learned, _ = learn_stored(kb, req)
            curves[f"smdp-q [{source}]"], knows[f"smdp-q [{source}]"] = (learned.curve,
                                                                        learned.knowledge)
    # the first task's runs give SF-GPI its base policies; their counts, or the true model in
    # the true-model regime, its dynamics
    sf_params = learner_defaults("sf-gpi", defaults)
    if regime == "true-model":
        sf_params["dynamics"] = "true-model"
    req = LearnRequest(env=cell.env, task=task, learner="sf-gpi", params=sf_params,
                       runs=pcfg.runs, episodes=pcfg.episodes, seed=config.seed, eval_every=1,
                       model=model_env or estimated_environment(kb, cell.env, [first_run]))
    learned, _ = learn_stored(kb, req)
    curves["sf-gpi"], knows["sf-gpi"] = learned.curve, learned.knowledge
    return curves, knows, notes, flat_instead


def available_sources() -> tuple[list[str], list[str]]:
    """The sources that can run here, and a note per source left out (its package missing)."""
    from importlib.util import find_spec

    missing = {source: package for source, package in OPTIONAL_SOURCES.items()
               if find_spec(package) is None}
    return ([s for s in SOURCES if s not in missing],
            [f"{s} left out: the optional package {p!r} is not installed "
             f"(pip install 'adpart[{p}]')" for s, p in missing.items()])


def _row_order(labels: list[str]) -> list[str]:
    order = [f"{learner} [{source}]" for source in SOURCES for learner in OPTION_LEARNERS]
    order += ["sf-gpi", *MODEL_BASED, BASELINE]
    return [m for m in order if m in labels]


def _regime_cells(kb: Any, cells: Any, sizes: dict[str, Any], config: ExperimentConfig,
                  out: Path, regime: str, sources: list[str]
                  ) -> tuple[list[dict[str, Any]], list[dict[str, str]], dict[str, set[str]],
                             dict[str, str]]:
    """Every cell's methods in ``regime``: the per-cell rows, the failed cells, each method's
    knowledge heads and its full record on the first cell it ran on."""
    from adpart.errors import AdpartError

    fraction = GAP_FRACTION
    per_cell: list[dict[str, Any]] = []
    failed: list[dict[str, str]] = []
    regimes: dict[str, set[str]] = {}
    uses: dict[str, str] = {}
    for number, cell in enumerate(cells, 1):
        config.progress(f"{regime}, cell {number}/{len(cells)}: {cell.env}: "
                        f"{' -> '.join(cell.tasks)}")
        try:
            curves, knows, notes, flat_instead = _cell_methods(
                kb, cell, sizes, config, out / regime / f"{number:02d}", regime, sources)
        except AdpartError as err:  # recorded; the other cells still run
            failed.append({"env": cell.env, "tasks": list(cell.tasks),
                           "error": str(err).splitlines()[0]})
            continue
        flat = curves.get(BASELINE)
        if flat is None:
            failed.append({"env": cell.env, "tasks": list(cell.tasks),
                           "error": "no flat baseline"})
            continue
        row: dict[str, Any] = {"env": cell.env, "tasks": list(cell.tasks), "notes": notes,
                               "methods": {}}
        for method in _row_order(list(curves)):
            episodes, times, scale, median, ratio = method_times(curves[method], flat,
                                                                 fraction)
            row["scale"] = scale
            row["flat_median_within_budget"] = scale < flat.n_episodes
            label = knows.get(method, "not declared")
            regimes.setdefault(method, set()).add(label.split(" (", 1)[0])
            uses.setdefault(method, label)
            row["methods"][method] = {
                "within": _within(curves[method], flat, fraction), "ratio_to_flat": ratio,
                "km_median": median,
                "episodes": episodes.tolist(), "runs": times.tolist(),
                "knowledge": knows.get(method), "flat_instead": method in flat_instead}
        per_cell.append(row)
    return per_cell, failed, regimes, uses


def _aggregate(per_cell: list[dict[str, Any]], seed: int) -> dict[str, Any]:
    """The methods seen, the cells every method has runs on (``common``) and the ones left
    out, each method's IQM and probability of beating flat over ``common``, and the
    run-score profiles over the same cells."""
    from adpart.learning.transfer_metrics import (
        iqm,
        performance_profile,
        probability_of_improvement,
    )

    methods_seen = list(dict.fromkeys(
        _row_order([m for row in per_cell for m in row["methods"]])))
    common = [r for r in per_cell
              if all(r["methods"].get(m, {}).get("runs") for m in methods_seen)]
    aggregate: dict[str, Any] = {}
    profiles: dict[str, Any] = {"taus": PROFILE_TAUS.tolist(), "cells": len(common),
                                "methods": {}}
    for method in methods_seen:
        if not common:
            break
        runs = [_times(r, method) for r in common]
        prof = performance_profile([-x for x in runs], -PROFILE_TAUS, seed=seed)
        profiles["methods"][method] = {"fraction": prof.fraction.tolist(),
                                       "low": prof.low.tolist(), "high": prof.high.tolist()}
        if method == BASELINE:
            continue
        agg = iqm(runs, seed=seed)
        sooner = probability_of_improvement(runs, [_times(r, BASELINE) for r in common],
                                            better="lower", seed=seed)
        aggregate[method] = {"cells": len(common), "iqm": list(agg),
                             "probability_sooner": list(sooner)}
    return {"methods": methods_seen, "common": common,
            "left_out": [r for r in per_cell if r not in common], "aggregate": aggregate,
            "profiles": profiles}


@experiment(
    "methods",
    "Option sources x transfer learners, SF-GPI and the knowledge-matched planner against flat",
    "the field's methods on the benchmark cells (no figure of the seed)",
)
def methods(config: ExperimentConfig) -> ExperimentReport:
    """Run every method on every cell in each regime and aggregate (module docstring)."""
    from adpart.execution import LocalExecutor
    from adpart.learning.comparison import interval_text
    from adpart.workflows.working_kb import working_kb

    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    cells = QUICK_BENCHMARK_CELLS[:2] if config.quick else BENCHMARK_CELLS
    sizes = ({"runs": min(config.runs, 3), "episodes": 60, "first_episodes": 150}
             if config.quick else {"runs": config.runs})
    sources, left_out = available_sources()
    report = ExperimentReport("methods", "the field's methods on the benchmark cells")
    report.seed_reports = ["(the dissertation compares its chain with flat Q-learning only)"]
    data: dict[str, Any] = {
        "settings": {"seed": config.seed, "eval_every": 1, **sizes, "regimes": list(REGIMES_RUN),
                     "sources": {s: {"detector": SOURCES[s][0], "params": SOURCES[s][1]}
                                 for s in sources},
                     "option_learners": list(OPTION_LEARNERS),
                     "plain_learners": ["sf-gpi", *MODEL_BASED], "baseline": BASELINE,
                     "gap_fraction": GAP_FRACTION, "layer_fallback": False,
                     "smdp_q": {"include-primitives": True}},
        "by_regime": {}}
    report.findings += left_out
    per_regime: dict[str, list[dict[str, Any]]] = {}
    with (tempfile.TemporaryDirectory(prefix="adpart-methods-") if config.kb is None
          else nullcontext(config.kb)) as where:
        with working_kb(where, "methods"):  # made once, before the workers open it
            pass
        jobs = [RegimeJob(regime, str(where), str(out), tuple(cells), sizes, tuple(sources),
                          config.seed, config.runs, config.quick) for regime in REGIMES_RUN]
        config.progress(f"{len(jobs)} regimes x {len(cells)} cells, a worker process per "
                        "regime (each prints its cells on stderr)")
        with LocalExecutor(workers=min(len(jobs), os.cpu_count() or 1)) as pool:
            results = pool.map(run_regime, jobs)
        for regime, (per_cell, failed, regimes, uses) in zip(REGIMES_RUN, results, strict=True):
            per_regime[regime] = per_cell
            agg = _aggregate(per_cell, config.seed)
            report.findings += _regime_findings(regime, agg, regimes, uses, per_cell, failed,
                                                interval_text)
            data["by_regime"][regime] = {
                "cells": per_cell, "failed": failed, "aggregate": agg["aggregate"],
                "profiles": agg["profiles"], "regimes": {k: sorted(v) for k, v in regimes.items()},
                "knowledge_on_the_first_cell": uses}
            if agg["common"]:
                report.figures += _regime_figures(agg, regime, sources, out)
    (out / CELLS_PAGE).write_text(cell_tables(per_regime, REGIME_TEXT, interval_text))
    report.findings.append(f"a table per cell, a row per method, in each regime: "
                           f"[{CELLS_PAGE}]({CELLS_PAGE})")
    report.data = data
    return report


@dataclass(frozen=True)
class RegimeJob:
    """One regime's cells, as a worker process runs them (:func:`run_regime`)."""

    regime: str
    kb: str
    out: str
    cells: tuple[Any, ...]
    sizes: dict[str, Any]
    sources: tuple[str, ...]
    seed: int
    runs: int
    quick: bool


def run_regime(job: RegimeJob) -> tuple[list[dict[str, Any]], list[dict[str, str]],
                                        dict[str, set[str]], dict[str, str]]:
    """:func:`_regime_cells` of ``job`` on the knowledge base at ``job.kb`` (shared with the
    other regime's worker: the store takes concurrent writers), its progress on stderr."""
    from adpart.workflows.working_kb import working_kb

    config = ExperimentConfig(out=Path(job.out), runs=job.runs, seed=job.seed, quick=job.quick,
                              kb=job.kb, progress=_to_stderr)
    with working_kb(job.kb, "methods") as kb:
        return _regime_cells(kb, job.cells, job.sizes, config, Path(job.out), job.regime,
                             list(job.sources))


def _to_stderr(message: str) -> None:
    print(f"methods: {message}", file=sys.stderr, flush=True)


#: The page of per-cell tables the experiment writes beside its summary.
CELLS_PAGE = "methods-cells.md"


def _regime_findings(regime: str, agg: dict[str, Any], regimes: dict[str, set[str]],
                     uses: dict[str, str], per_cell: list[dict[str, Any]],
                     failed: list[dict[str, str]], interval_text: Any) -> list[str]:
    """The summary's findings of one regime: the aggregates, the cells left out of them, what
    each method knew, the per-cell overview and the failed cells."""
    found = [f"**{regime} regime** ({REGIME_TEXT[regime]}): "
             + _aggregate_table(agg["aggregate"], regimes, interval_text)]
    if agg["left_out"]:
        found.append(
            f"{len(agg['left_out'])} cell(s) left out of the {regime} aggregates and "
            "profiles (a method has no runs there): " + "; ".join(
                f"{r['env']} {r['tasks'][1]} (missing: " + ", ".join(
                    m for m in agg["methods"] if not r["methods"].get(m, {}).get("runs"))
                + ")" for r in agg["left_out"]))
    found.append(
        f"what each method knew in the {regime} regime, in full (its stored knowledge "
        "record on the first cell it ran on):\n\n" + "\n".join(
            f"- **{m}**: {uses[m]}" for m in agg["methods"] if m in uses))
    found.append(f"{regime} regime, " + _overview_table(per_cell, agg["methods"],
                                                           interval_text))
    if failed:
        found.append(f"cells that failed in the {regime} regime: " + "; ".join(
            f"{f['env']} {f['tasks'][1]} ({f['error']})" for f in failed))
    return found


def _regime_figures(agg: dict[str, Any], regime: str, sources: list[str], out: Path
                    ) -> list[str]:
    """The regime's profile panels and a figure per aggregate (IQM, probability sooner)."""
    suffix = "" if regime == REGIMES_RUN[0] else f"-{regime}"
    groups = [*sources, "sf-gpi", *MODEL_BASED, BASELINE]
    cells = len(agg["common"])
    aggregate = agg["aggregate"]
    return [
        draw_profile_panels(PROFILE_TAUS, agg["profiles"]["methods"], OPTION_LEARNERS, groups,
                            f"performance profiles over {cells} cells ({regime} regime)",
                            out / f"methods-profile{suffix}.png"),
        draw_intervals({m: a["iqm"] for m, a in aggregate.items()}, groups,
                       xlabel="IQM of episodes to the bound / flat's median (1: flat)",
                       reference=1.0, log=True,
                       title=f"interquartile mean over {cells} cells, 95 % CI ({regime} regime)",
                       path=out / f"methods-iqm{suffix}.png"),
        draw_intervals({m: a["probability_sooner"] for m, a in aggregate.items()}, groups,
                       xlabel="probability that a run reaches the bound sooner than flat's",
                       reference=0.5, log=False,
                       title=f"probability of improvement over {cells} cells, 95 % CI "
                             f"({regime} regime)",
                       path=out / f"methods-probability{suffix}.png"),
    ]


def _times(row: dict[str, Any], method: str) -> np.ndarray:
    """A cell's per-run times of ``method`` over flat's median (inf: censored)."""
    return np.asarray(row["methods"][method]["runs"], dtype=np.float64)


def _aggregate_table(aggregate: dict[str, Any], regimes: dict[str, set[str]],
                     interval_text: Any) -> str:
    lines = [("| method | what it knew | cells | IQM of episodes / flat's median [95 % CI] | "
              "P(sooner than flat) [95 % CI] |"), "|---|---|---|---|---|"]
    for method, agg in aggregate.items():
        known = "; ".join(sorted(regimes.get(method, ())))
        lines.append(f"| {method} | {known} | {agg['cells']} | "
                     f"{interval_text(*agg['iqm'], inf='never')} | "
                     f"{interval_text(*agg['probability_sooner'])} |")
    return ("per method, over the same cells for all: the interquartile mean of each run's "
            "episodes to the bound over the cell's scale - flat's KM median, or flat's budget "
            "where that median lies beyond it (which overstates every method's ratio there) - "
            "a censored run counting as never, below 1 faster than flat; and the probability "
            "that a run reaches the bound sooner than a flat run of the same cell (ties count "
            "one half):\n\n"
            + "\n".join(lines))


def _overview_table(per_cell: list[dict[str, Any]], methods_seen: list[str],
                    interval_text: Any) -> str:
    """One row per cell, one column per method: its KM-median ratio to flat [95 % CI] (the
    runs within the bound and the medians are in the per-cell tables)."""
    header = "| # | environment | second task | " + " | ".join(methods_seen) + " |"
    lines = [header, "|" + "---|" * (3 + len(methods_seen))]
    for i, row in enumerate(per_cell, 1):
        entries = [row["methods"].get(m) for m in methods_seen]
        cells = " | ".join("-" if e is None else ratio_text(e, interval_text) for e in entries)
        mark = "" if row.get("flat_median_within_budget", True) else " (scale: budget)"
        lines.append(f"| {i} | `{row['env']}` | `{row['tasks'][1]}`{mark} | {cells} |")
    return ("per cell, each method's ratio of KM-median episodes to flat's [95 % CI] (`flat (no "
            "subgoals)`: its source found no subgoal there and the chain learned flat; `(scale: "
            "budget)`: flat's median lies beyond its budget, so the aggregates divide by the "
            "budget there; each cell's own table has the runs within the bound and the "
            f"medians, [{CELLS_PAGE}]({CELLS_PAGE})):\n\n"
            + "\n".join(lines))

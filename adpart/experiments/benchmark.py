"""The default chain against flat Q-learning over every benchmark cell: does it help or step aside?

``adpart experiment benchmark`` runs ``adpart pipeline`` with its defaults (the learned-model
regime: subgoals, options and the layer's phases 1-2 from the first task's experience, the
rehearsal that decides between the layer and flat) on each cell of :data:`BENCHMARK_CELLS`:
Gymnasium's toy text (with slippery variants, a custom map passed as JSON and seeded random maps),
MiniGrid layouts read as exact MDPs, and the built-in domains, each with a second task that
differs from the first (``move-goal:`` keeps the environment's own rewards, terminals and gamma).

Per cell, the *default chain* is what the pipeline learned the second task with - the layer
learner, or flat where it fell back (then the chain is flat's own runs and its ratio 1) - and its
time to the bound is compared with flat Q-learning's in the same run: the ratio of Kaplan-Meier
medians in episodes with a 95 % bootstrap CI (:func:`adpart.learning.comparison.time_ratio`;
censored runs stay censored). A cell *loses* when that CI's lower end is above 1.1. Across cells:
the interquartile mean of each chain run's episodes over flat's median with a stratified
bootstrap CI, the probability that a chain run reaches the bound sooner than a flat run, and the
run-score performance profile (Agarwal et al. 2021; :mod:`adpart.learning.transfer_metrics`),
drawn as ``benchmark-profile.png``. A cell whose pipeline raises is recorded with its message and
the rest still run; ``--quick`` runs three small cells that the test suite checks.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from adpart.experiments.base import ExperimentConfig, ExperimentReport, experiment
from adpart.experiments.comparisons import Cell

__all__ = ["BENCHMARK_CELLS", "LOSS_BOUND", "PROFILE_TAUS", "QUICK_BENCHMARK_CELLS", "CellResult",
           "chain_times", "draw_profiles", "profile_lines"]

#: A cell loses when the lower end of the chain's ratio-to-flat CI lies above this.
LOSS_BOUND = 1.1

_LAKE = "gym:FrozenLake-v1"
_CUSTOM_MAP = '["SFFFFF","FHHFFF","FFFHFF","FHFFFF","FFFFHF","FFFFFG"]'
_MG = "minigrid:MiniGrid-"

#: The benchmark's cells: environment x (first task, a different second task), each with a
#: budget in which flat Q-learning reaches the bound in most runs. Tried and left out because
#: flat reached the bound in no run of 20 within 2,000 episodes (so no ratio to flat exists):
#: Gymnasium's Taxi-v4 and the built-in taxi with a moved goal, four-rooms G1 <-> G2 (greedy
#: policies stay about 5 % of V* away under a constant step size), FrozenLake random_map=10,
#: slippery CliffWalking, and three-floor-arm (its own cell in ``adpart experiment comparisons``).
BENCHMARK_CELLS = (
    # Gymnasium toy text
    Cell(f"{_LAKE}[map_name=4x4,is_slippery=false]", ("reward", "move-goal:row=0,col=3")),
    Cell(f"{_LAKE}[map_name=4x4,is_slippery=false]", ("reward", "move-goal:row=3,col=0")),
    Cell(f"{_LAKE}[map_name=4x4]", ("reward", "move-goal:row=0,col=3"), "slippery"),
    Cell(f"{_LAKE}[map_name=8x8,is_slippery=false]", ("reward", "move-goal:row=0,col=7")),
    Cell(f"{_LAKE}[map_name=8x8,is_slippery=false]", ("reward", "move-goal:row=7,col=0")),
    Cell(f"{_LAKE}[desc={_CUSTOM_MAP},is_slippery=false]", ("reward", "move-goal:row=0,col=5"),
         "a custom map given as JSON"),
    Cell(f"{_LAKE}[random_map=6,map_seed=3,is_slippery=false]",
         ("reward", "move-goal:row=0,col=5"), "a seeded random map"),
    Cell(f"{_LAKE}[random_map=8,map_seed=2,is_slippery=false]",
         ("reward", "move-goal:row=0,col=7"), "a seeded random map",
         {"episodes": 1000, "first_episodes": 1000}),
    Cell("gym:CliffWalking-v1", ("reward", "move-goal:row=0,col=11")),
    Cell("gym:CliffWalking-v1", ("reward", "move-goal:row=0,col=0")),
    # MiniGrid layouts (seed 0), the goal moved to a cell far from the start and the goal
    Cell(f"{_MG}Empty-5x5-v0", ("reward", "move-goal:x=1,y=3")),
    Cell(f"{_MG}Empty-6x6-v0", ("reward", "move-goal:x=1,y=4")),
    Cell(f"{_MG}Empty-8x8-v0", ("reward", "move-goal:x=1,y=6")),
    Cell(f"{_MG}Empty-16x16-v0", ("reward", "move-goal:x=1,y=14"), "",
         {"episodes": 1000, "first_episodes": 1000}),
    Cell(f"{_MG}Empty-Random-6x6-v0", ("reward", "move-goal:x=1,y=3")),
    Cell(f"{_MG}FourRooms-v0", ("reward", "move-goal:x=6,y=1")),
    Cell(f"{_MG}FourRooms-v0[seed=1]", ("reward", "move-goal:x=17,y=17"), "",
         {"episodes": 2000, "first_episodes": 2000}),
    Cell(f"{_MG}DoorKey-5x5-v0", ("reward", "move-goal:x=2,y=1")),
    Cell(f"{_MG}DoorKey-5x5-v0[seed=1]", ("reward", "move-goal:x=3,y=1")),
    Cell(f"{_MG}DoorKey-6x6-v0", ("reward", "move-goal:x=3,y=1")),
    Cell(f"{_MG}LavaGapS7-v0", ("reward", "move-goal:x=1,y=4")),
    Cell(f"{_MG}MultiRoom-N2-S4-v0", ("reward", "move-goal:x=19,y=18")),
    Cell(f"{_MG}SimpleCrossingS9N1-v0", ("reward", "move-goal:x=1,y=7")),
    Cell(f"{_MG}SimpleCrossingS9N2-v0", ("reward", "move-goal:x=1,y=7")),
    Cell(f"{_MG}LavaCrossingS9N1-v0", ("reward", "move-goal:x=1,y=7")),
    Cell(f"{_MG}Unlock-v0", ("reward", "move-goal:x=2,y=1")),
    Cell(f"{_MG}DistShift1-v0", ("reward", "move-goal:x=1,y=5")),
    # the built-in domains
    Cell("two-rooms", ("reach-goal", "goal:x=9,y=5")),
    Cell("two-rooms", ("reach-goal", "move-goal:x=1,y=4")),
    Cell("three-floor", ("reach-goal", "reach-top-west"), "", {"episodes": 500}),
    Cell("three-floor", ("reach-goal", "reach-ground-east"), "", {"episodes": 500}),
    Cell("three-floor", ("reach-goal", "reach-middle-south"), "", {"episodes": 500}),
)

#: The quick version: one toy-text, one MiniGrid and one built-in cell, all small.
QUICK_BENCHMARK_CELLS = (
    Cell(f"{_LAKE}[map_name=4x4,is_slippery=false]", ("reward", "move-goal:row=0,col=3")),
    Cell(f"{_MG}Empty-5x5-v0", ("reward", "move-goal:x=1,y=3")),
    Cell("two-rooms", ("reach-goal", "goal:x=9,y=5")),
)


@dataclass(frozen=True)
class CellResult:
    """One cell's outcome: the chain's branch, its ratio to flat (episodes, KM medians, CI)
    and the per-run times that go into the aggregates."""

    cell: Cell
    branch: str
    reason: str
    chain_within: str
    flat_within: str
    ratio: dict[str, Any] | None
    chain: np.ndarray  # per run, episodes to the bound over flat's KM median (inf: censored)
    flat: np.ndarray

    @property
    def loses(self) -> bool:
        """The chain's ratio CI lies above :data:`LOSS_BOUND`, or flat reached the bound in
        its budget and the chain's median did not (``at_least`` above it); two learners that
        both never reach it do not lose to each other."""
        q = self.ratio
        if not q:
            return False
        if q.get("ratio") is None:
            return bool(q.get("at_least", 0.0) > LOSS_BOUND)
        return bool(q["ci95"][0] > LOSS_BOUND)


def chain_times(pipe: Any, task: str) -> tuple[str, np.ndarray, np.ndarray] | None:
    """The default chain's curve label on ``task`` and, per run of the chain and of flat, the
    episodes to the bound over flat's Kaplan-Meier median (censored: inf); None when flat's
    median lies beyond its budget (no scale to divide by)."""
    from adpart.learning.comparison import success_bound
    from adpart.learning.transfer_metrics import km_median, metrics_from_curve

    curves = pipe.curves.get(task, {})
    flat = curves.get("flat (no transfer)")
    label = next((k for k in curves if k.startswith("hierarchical")), None) or next(
        (k for k in curves if k.startswith("flat (") and k != "flat (no transfer)"), None)
    if flat is None or label is None:
        return None
    bound = success_bound(flat, pipe.config.gap_fraction)
    scaled = []
    for curve in (curves[label], flat):
        times, censored = metrics_from_curve(curve, bound).event_times("episodes")
        scaled.append(np.where(censored, np.inf, times).astype(np.float64))
    median = km_median(*metrics_from_curve(flat, bound).event_times("episodes")).estimate
    if not np.isfinite(median) or median <= 0:
        return None
    return label, scaled[0] / median, scaled[1] / median


def _result(cell: Cell, pipe: Any) -> CellResult:
    task = cell.tasks[1]
    rows = [r for r in pipe.rows if r["task"] == task]
    layer = next((r for r in rows if r["learner"] == "hierarchical"), None)
    fallback = next((r for r in rows if r["learner"] == "flat-fallback"), None)
    flat = next((r for r in rows if r["learner"] == "flat"), None)
    chain = layer or fallback
    if layer is not None:
        branch, reason = "layer", next((s.detail.get("reason", "") for s in pipe.stages
                                        if s.stage == "rehearse" and s.task == task), "")
        ratio = layer.get("ratio_to_flat")
    else:
        branch, reason = "flat", (fallback or {}).get("fallback", "")
        ratio = {"ratio": 1.0, "ci95": [1.0, 1.0], "same_runs": True}
    times = chain_times(pipe, task)
    empty = np.zeros(0)
    return CellResult(
        cell, branch, reason,
        f"{chain['runs_within_bound']}/{chain['runs']}" if chain else "-",
        f"{flat['runs_within_bound']}/{flat['runs']}" if flat else "-",
        ratio, times[1] if times else empty, times[2] if times else empty)


def _ratio_text(result: CellResult) -> str:
    from adpart.learning.comparison import interval_text

    q = result.ratio
    if q is None:
        return "-"
    if q.get("same_runs"):
        return "1 (learned flat)"
    if q.get("ratio") is None:
        if "at_most" in q:
            return f"<= {q['at_most']:.3g} (flat's median beyond budget)"
        if "at_least" in q:
            return f">= {q['at_least']:.3g} (chain's median beyond budget)"
        return "never / never"
    return interval_text(q["ratio"], *q["ci95"], inf="never")


def _table(results: list[CellResult], failed: list[tuple[Cell, str]]) -> list[str]:
    header = (f"| # | environment | second task | chain | chain within | flat within | "
              f"chain / flat, KM episodes [95 % CI] | loses (CI > {LOSS_BOUND}) |")
    lines = [header, "|---|---|---|---|---|---|---|---|"]
    for i, r in enumerate(results, 1):
        lines.append(f"| {i} | `{r.cell.env}` | `{r.cell.tasks[1]}` | {r.branch} | "
                     f"{r.chain_within} | {r.flat_within} | {_ratio_text(r)} | "
                     f"{'**yes**' if r.loses else 'no'} |")
    for cell, message in failed:
        lines.append(f"| - | `{cell.env}` | `{cell.tasks[1]}` | **failed** | - | - | "
                     f"{message} | - |")
    return lines


#: The profile's thresholds: a run's episodes to the bound over flat's median.
PROFILE_TAUS = np.geomspace(0.05, 20.0, 60)


def _profiles(results: list[CellResult], seed: int) -> dict[str, Any] | None:
    """The run-score performance profiles of the chain and of flat over the cells with a
    ratio: per tau, the fraction of all runs whose episodes to the bound are below tau times
    flat's median, with pointwise 95 % stratified-bootstrap bands."""
    from adpart.learning.transfer_metrics import performance_profile

    cells = [r for r in results if r.chain.size and r.flat.size]
    if not cells:
        return None
    out: dict[str, Any] = {"taus": PROFILE_TAUS.tolist(), "cells": len(cells)}
    for name, pick in (("chain", lambda r: r.chain), ("flat", lambda r: r.flat)):
        # lower is better: the fraction of runs with time < tau is the profile of -time at -tau
        prof = performance_profile([-pick(r) for r in cells], -PROFILE_TAUS, seed=seed)
        out[name] = {"fraction": prof.fraction.tolist(), "low": prof.low.tolist(),
                     "high": prof.high.tolist()}
    return out


def profile_lines(ax: Any, taus: np.ndarray, curves: dict[str, dict[str, Any]], *,
                  bands: bool = True, groups: list[str] | None = None) -> None:
    """Run-score performance profiles on ``ax``'s log-tau axis: per name, its ``fraction`` of
    runs within tau (and its ``low``-``high`` band when ``bands``); a dotted line at tau = 1.

    One colour per group - the option source of ``"learner [source]"``, or the plain method's
    name - in the order of ``groups`` (so that panels of one figure agree), else of ``curves``;
    SMDP Q dashed, flat dotted."""
    import matplotlib as mpl

    order = list(groups or [])
    order += [g for g in dict.fromkeys(colour_group(name) for name in curves) if g not in order]
    palette = mpl.colormaps["tab10"].colors
    for name, prof in curves.items():
        style = "--" if name.startswith("smdp-q") else (":" if name == "flat" else "-")
        colour = palette[order.index(colour_group(name)) % len(palette)]
        ax.plot(taus, prof["fraction"], style, color=colour, label=name)
        if bands:
            ax.fill_between(taus, prof["low"], prof["high"], color=colour, alpha=0.2)
    ax.axvline(1.0, color="0.6", linewidth=0.8, linestyle=":")
    ax.set_xscale("log")
    ax.set_ylim(0.0, 1.02)
    ax.set_xlabel("episodes to the bound / flat's Kaplan-Meier median (tau)")
    ax.set_ylabel("fraction of runs within tau")


def colour_group(name: str) -> str:
    """The colour group of a method's name: its option source, or the name itself."""
    return name.split("[", 1)[-1].rstrip("]")


def draw_profiles(taus: np.ndarray, curves: dict[str, dict[str, Any]], title: str,
                  path: Path, *, bands: bool = True) -> str:
    """:func:`profile_lines` of ``curves`` on one axis, titled, saved to ``path``."""
    from adpart.plotting import legend_below, new_figure

    fig, ax = new_figure((7.2, 4.8) if len(curves) > 2 else (6.4, 4.2))
    profile_lines(ax, taus, curves, bands=bands)
    ax.set_title(title)
    legend_below(ax, columns=3 if len(curves) > 2 else 2)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    return str(path)


def _profile_figure(profiles: dict[str, Any], out: Path) -> str:
    """:func:`_profiles` drawn: the fraction of runs within tau, chain and flat, log tau."""
    return draw_profiles(np.asarray(profiles["taus"]),
                         {"default chain": profiles["chain"], "flat Q-learning": profiles["flat"]},
                         f"performance profile over {profiles['cells']} cells "
                         "(95 % stratified bootstrap)", out / "benchmark-profile.png")


@experiment(
    "benchmark",
    "The default chain against flat Q-learning over every benchmark cell",
    "the any-environment benchmark (no figure of the seed)",
)
def benchmark(config: ExperimentConfig) -> ExperimentReport:
    """Run the pipeline's defaults on every cell and aggregate (module docstring)."""
    from adpart.errors import AdpartError
    from adpart.learning.transfer_metrics import iqm, probability_of_improvement
    from adpart.workflows.pipeline import PipelineConfig, run_pipeline
    from adpart.workflows.reports import folder_name
    from adpart.workflows.working_kb import working_kb

    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    cells = QUICK_BENCHMARK_CELLS if config.quick else BENCHMARK_CELLS
    sizes = ({"runs": min(config.runs, 3), "episodes": 60, "first_episodes": 150}
             if config.quick else {"runs": config.runs})
    report = ExperimentReport("benchmark", "the default chain against flat over every cell")
    report.seed_reports = ["(the dissertation has no such benchmark: chapter 5 runs its own "
                           + "three domains)"]
    results: list[CellResult] = []
    failed: list[tuple[Cell, str]] = []
    with working_kb(config.kb, "benchmark") as kb:
        for number, cell in enumerate(cells, 1):
            config.progress(f"cell {number}/{len(cells)}: {cell.env}: {' -> '.join(cell.tasks)}")
            pcfg = PipelineConfig(env=cell.env, tasks=cell.tasks, seed=config.seed,
                                  **{"eval_every": 1, **sizes, **cell.options})
            try:
                pipe = run_pipeline(kb, pcfg, out=out / f"{number:02d}-{folder_name(cell.env)}",
                                    progress=config.progress)
            except AdpartError as err:  # recorded; the other cells still run
                failed.append((cell, str(err).splitlines()[0]))
                continue
            results.append(_result(cell, pipe))
    lines = _table(results, failed)
    report.findings.append("per cell (the chain is the layer learner, or flat where the "
                           "pipeline fell back; ratios of Kaplan-Meier medians in episodes, "
                           "censored runs censored):\n\n" + "\n".join(lines))
    losses = [r for r in results if r.loses]
    report.findings.append(
        f"{len(results)} of {len(cells)} cells ran to the end"
        + (f"; {len(failed)} failed: " + "; ".join(f"{c.env} ({m})" for c, m in failed)
           if failed else " (exit 0 on every cell)")
        + f"; the chain learned on a layer in {sum(r.branch == 'layer' for r in results)} "
        f"and fell back to flat in {sum(r.branch == 'flat' for r in results)}; "
        f"{len(losses)} cell(s) where the chain's CI lies above {LOSS_BOUND}"
        + (": " + ", ".join(f"{r.cell.env} {r.cell.tasks[1]}" for r in losses) if losses
           else "."))
    scored = [r for r in results if r.chain.size and r.flat.size]
    data: dict[str, Any] = {
        "cells": [{"env": r.cell.env, "tasks": list(r.cell.tasks), "note": r.cell.note,
                   "branch": r.branch, "reason": r.reason, "chain_within": r.chain_within,
                   "flat_within": r.flat_within, "ratio_to_flat": r.ratio, "loses": r.loses,
                   "chain_runs": r.chain.tolist(), "flat_runs": r.flat.tolist()}
                  for r in results],
        "failed": [{"env": c.env, "tasks": list(c.tasks), "error": m} for c, m in failed],
        "settings": {"seed": config.seed, "eval_every": 1, **sizes,
                     "defaults": "adpart pipeline's", "regime": "learned-model",
                     "loss_bound": LOSS_BOUND},
    }
    if scored:
        agg = iqm([r.chain for r in scored], seed=config.seed)
        better = probability_of_improvement([r.chain for r in scored],
                                            [r.flat for r in scored], better="lower",
                                            seed=config.seed)
        data["iqm_chain_over_flat"] = list(agg)
        data["probability_chain_sooner"] = list(better)
        report.findings.append(
            f"over the {len(scored)} cells where flat's median lies within its budget: "
            f"interquartile mean of each chain run's episodes to the bound over flat's median "
            f"= {agg.estimate:.3g} (95 % stratified bootstrap CI {agg.low:.3g}-{agg.high:.3g}; "
            "a censored run counts as never); probability that a chain run reaches the bound "
            f"sooner than a flat run of the same cell = {better.estimate:.2f} "
            f"({better.low:.2f}-{better.high:.2f}; ties, as in the cells that fell back, "
            "count one half).")
        profiles = _profiles(results, config.seed)
        if profiles:
            data["profiles"] = profiles
            report.figures.append(_profile_figure(profiles, out))
    report.data = data
    return report

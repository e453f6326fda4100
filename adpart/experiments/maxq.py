"""``adpart experiment maxq-taxi`` and ``maxq-parr``: the MAXQ-Q comparisons of chapter 6.

**maxq-taxi** (Dietterich 2000 sec. 7.1, Fig. 6): fickle Taxi (``taxi-fickle``, 516 states) learned
by flat Q-learning, MAXQ-Q with and without Dietterich's state abstraction, and the transfer
pipeline (:func:`adpart.workflows.pipeline.run_pipeline`: ``deliver`` learned flat, subgoals by
the Monte Carlo count metric ``count-mc``, options, multi-phase partition, ``deliver`` learned
again by the hierarchical learner). Discounting: the abstractions are exact only for
``gamma = 1`` (docs/maxq.md), so flat Q and both MAXQ-Q variants learn the **undiscounted** task
and their greedy policies are scored exactly on it; a policy that does not deliver from every
start has no finite value (NaN gap), i.e. it is *not within the tolerance* - never a number
averaged in. The pipeline runs on the registered ``taxi-fickle`` task (``gamma = 0.95``, the
only one the pipeline can address) and is scored against its own ``V*``; its row is therefore
on a nearby but not identical scale, which the findings say.

**maxq-parr** (Figs. 6.2, 6.3): Parr's maze, the *mini* reconstruction
(``ParrMaze(mini=True)``, 1,988 states; not a registered environment, so the MDPs are built
directly and no knowledge base is used) because MAXQ-Q on the full 3,710-state maze does not fit
the time budget. A first task (reach the goal room's first cell from the start) is learned flat;
subgoals are found in its greedy policy by Monte Carlo sampling of the count metric
(:func:`adpart.subgoals.discover_monte_carlo`, section 4.1.1; samples, ratio mean/sd and mu
reported); options to them are computed (:func:`adpart.options.subgoal_options.subgoal_options`
with exact models). The maze task is then learned by (a) MAXQ-Q on the ``parr-maze`` graph,
(b) SMDP Q over the discovered options plus the primitives on the flat states, (c) the
hierarchical learner on the multi-phase partition over the same options. MAXQ-Q's call-time
parameters make its policy non-Markov in the state, so it is scored by executing the
hierarchical greedy policy (:func:`adpart.learning.maxq.hierarchical_rollouts`); (b) and (c)
exactly.

**Statistics.** Per run: primitive steps (and episodes) until the greedy policy's value gap
stays within a tolerance, ``inf`` when it never does (censored); medians with bootstrap CIs of
the median (``inverted_cdf`` percentiles, so ``inf`` is a legal value). Pairwise claims use
:func:`adpart.experiments.stats.compare` on per-run numbers that are always finite: total
primitive steps over the training (the area under the steps-per-episode curve that Figs.
6.2/6.3 plot) and steps-to-tolerance with censored runs set to the learner's whole step budget
(a lower bound, said in the sentence).
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from adpart.experiments.base import ExperimentConfig, ExperimentReport, experiment
from adpart.experiments.stats import compare, episodes_to_threshold

ALPHA, EPSILON = "1/n^0.6", "1/n^0.5"
#: Tolerance of the value gap (reward units, mean over the start distribution).
TAXI_TOL = 0.5
PARR_TOL = 2.0


# --------------------------------------------------------------------------- statistics


def steps_to_tolerance(gaps: np.ndarray, steps: np.ndarray, evaluated: np.ndarray,
                       tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Per run: ``(primitive steps, episodes)`` until the gap stays ``<= tol``; ``inf`` if never.

    Args:
        gaps: ``(K, N)`` value gaps, NaN where not evaluated *or* where the policy has no finite
            value (it then counts as not within the tolerance).
        steps: ``(K, N)`` primitive steps per episode.
        evaluated: 1-based evaluated episodes.
        tol: the tolerance.
    """
    episodes = episodes_to_threshold(gaps, evaluated, tol)
    cum = np.cumsum(steps, axis=1)
    idx = np.where(np.isfinite(episodes), episodes, 1).astype(np.int64) - 1
    at = cum[np.arange(cum.shape[0]), idx].astype(np.float64)
    return np.where(np.isfinite(episodes), at, np.inf), episodes


def median_ci(x: np.ndarray, *, level: float = 0.95, n_boot: int = 2000,
              seed: int = 0) -> tuple[float, float, float]:
    """Median and percentile-bootstrap CI of the median; ``inf`` (censored) values allowed."""
    x = np.asarray(x, dtype=np.float64)
    rng = np.random.default_rng(seed)
    meds = np.quantile(rng.choice(x, size=(n_boot, x.size)), 0.5, axis=1, method="inverted_cdf")
    lo, hi = np.quantile(meds, [0.5 - level / 2, 0.5 + level / 2], method="inverted_cdf")
    return float(np.quantile(x, 0.5, method="inverted_cdf")), float(lo), float(hi)


def evaluated(episodes: int, every: int) -> np.ndarray:
    """The 1-based episodes a learner scores: every ``every``-th and the last (as the learners
    do; taken from the schedule because a curve whose scores are all undefined has no marks)."""
    return np.array(sorted({*range(every, episodes + 1, every), episodes}), dtype=np.int64)


def fmt_steps(v: float) -> str:
    return "never" if not np.isfinite(v) else f"{v:,.0f}"


def _row(label: str, to_tol: np.ndarray, eps: np.ndarray, total: np.ndarray, final: np.ndarray,
         seed: int) -> dict[str, Any]:
    m, lo, hi = median_ci(to_tol, seed=seed)
    me, loe, hie = median_ci(eps, seed=seed)
    return {"learner": label, "runs": int(to_tol.size),
            "reached": int(np.isfinite(to_tol).sum()),
            "steps_to_tol_median": m, "steps_to_tol_ci": [lo, hi],
            "episodes_to_tol_median": me, "episodes_to_tol_ci": [loe, hie],
            "steps_to_tol": to_tol.tolist(), "total_steps_mean": float(total.mean()),
            "final_gap_median": float(np.nanmedian(final)) if np.isfinite(final).any()
            else float("nan"),
            "final_gap_undefined": int(np.isnan(final).sum())}


def _row_sentence(r: dict[str, Any]) -> str:
    lo, hi = r["steps_to_tol_ci"]
    med, eps = fmt_steps(r["steps_to_tol_median"]), fmt_steps(r["episodes_to_tol_median"])
    return (f"{r['learner']}: median primitive steps to tolerance {med}"
            f" [95% CI {fmt_steps(lo)}, {fmt_steps(hi)}], episodes {eps}; "
            f"{r['reached']}/{r['runs']} runs reached it; mean total steps "
            f"{r['total_steps_mean']:,.0f}; median final gap {r['final_gap_median']:.3g}"
            f" ({r['final_gap_undefined']} runs with an undefined value = never finishing)")


def _censored(to_tol: np.ndarray, total: np.ndarray) -> np.ndarray:
    return np.where(np.isfinite(to_tol), to_tol, total)


def _pairs(report: ExperimentReport, per_run: dict[str, np.ndarray], what: str,
           pairs: list[tuple[str, str]], seed: int,
           reached: dict[str, np.ndarray]) -> list[dict[str, Any]]:
    """``compare`` each pair; a to-tolerance pair where no run of either side got there is
    reported as not comparable (the censored values would only compare the budgets)."""
    out = []
    for a, b in pairs:
        if what.startswith("primitive steps to tolerance") and not (
                np.isfinite(reached[a]).any() or np.isfinite(reached[b]).any()):
            report.findings.append(f"{what}: {a} vs {b} - not comparable, no run of either "
                                   "reached the tolerance (only the budgets would differ)")
            continue
        comp = compare(per_run[a], per_run[b], a, b, seed=seed)
        out.append({"what": what, **comp.to_dict()})
        report.findings.append(comp.sentence(what))
    return out


def _plot(series: dict[str, tuple[np.ndarray, np.ndarray]], path: Path, xlabel: str,
          ylabel: str, title: str, log: bool = False) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.2))
    for name, (x, y) in series.items():
        ax.plot(x, y, label=name)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if log:
        ax.set_yscale("log")
    ax.set_title(title)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return str(path)


def _curve_plots(out: Path, prefix: str, steps: dict[str, np.ndarray],
                 gaps: dict[str, tuple[np.ndarray, np.ndarray]], title: str) -> list[str]:
    """Steps per episode vs episodes, and median gap vs cumulative primitive steps."""
    by_ep = {k: (np.arange(1, s.shape[1] + 1), s.mean(axis=0)) for k, s in steps.items()}
    by_steps = {}
    for k, (g, ev) in gaps.items():
        cum = np.cumsum(steps[k], axis=1).mean(axis=0)[ev - 1]
        with np.errstate(invalid="ignore"):
            gg = np.where(np.isnan(g), np.inf, g)
        by_steps[k] = (cum, np.quantile(gg, 0.5, axis=0, method="inverted_cdf"))
    return [
        _plot(by_ep, out / f"{prefix}_steps.png", "episode", "primitive steps per episode (mean)",
              f"{title}: steps per episode", log=True),
        _plot(by_steps, out / f"{prefix}_gap.png", "primitive steps (mean cumulative)",
              "median value gap (inf = never finishes)", f"{title}: value gap", log=True),
    ]


# --------------------------------------------------------------------------- maxq-taxi


def _taxi_settings(config: ExperimentConfig) -> dict[str, Any]:
    if config.quick:
        return {"runs": min(config.runs, 2), "maxq": 60, "maxq_noabs": 60, "flat": 200,
                "pipe_first": 100, "pipe": 60, "eval_every": 20, "horizon": 500}
    return {"runs": config.runs, "maxq": 3000, "maxq_noabs": 6000, "flat": 30000,
            "pipe_first": 2000, "pipe": 1500, "eval_every": 25, "horizon": 1000}


def _taxi_pipeline(config: ExperimentConfig, s: dict[str, Any]) -> tuple[Any, dict[str, Any]]:
    from adpart.store import KnowledgeBase
    from adpart.workflows.pipeline import PipelineConfig, run_pipeline

    pc = PipelineConfig(env="taxi-fickle", tasks=("deliver", "deliver"), detector="count-mc",
                        detector_params={"on_loop": "truncate"}, runs=s["runs"],
                        episodes=s["pipe"], first_episodes=s["pipe_first"], seed=config.seed,
                        eval_every=s["eval_every"], baseline=False,
                        flat_params={"alpha": ALPHA, "epsilon": EPSILON},
                        fallback=False)  # the decision layer is what is compared
    tmp = None
    location = config.kb
    if location is None:
        tmp = tempfile.TemporaryDirectory(prefix="adpart-maxq-taxi-")
        location = tmp.name
    kb = KnowledgeBase.open(location)
    try:
        rep = run_pipeline(kb, pc, progress=config.progress)
    finally:
        kb.close()
        if tmp is not None:
            tmp.cleanup()
    curve = next(iter(rep.curves["deliver"].values()))
    stages = {st.stage: st for st in rep.stages}
    info = {"first_task_steps_mean": rep.rows[0]["steps_total_mean"],
            "subgoals": stages["discover"].detail.get("subgoals"),
            "blocks": stages["partition"].detail.get("final_blocks"),
            "gamma": float(curve.metadata.get("gamma", 0.95))}
    return curve, info


@experiment(
    "maxq-taxi",
    "Fickle Taxi: flat Q vs MAXQ-Q (with/without abstraction) vs the transfer pipeline",
    "Dietterich (2000) Fig. 6; dissertation chapter 6",
)
def maxq_taxi(config: ExperimentConfig) -> ExperimentReport:
    """Primitive steps to the (hierarchically) optimal policy on fickle Taxi, four learners."""
    from adpart.envs.domains.taxi import Taxi
    from adpart.learning.maxq import maxq_q, taxi_graph
    from adpart.learning.qlearning import q_learning

    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    s = _taxi_settings(config)
    report = ExperimentReport("maxq-taxi", "MAXQ-Q on fickle Taxi")
    report.seed_reports = [
        ("Dietterich (2000) Fig. 6, fickle Taxi: MAXQ-Q with state abstraction reaches the "
        "hierarchically optimal policy after about 40,000 primitive steps, flat Q after about "
        "twice as many; MAXQ-Q without abstraction is slower than flat Q."),
        ("The dissertation (ch. 6) claims the partition-based hierarchical learner beats MAXQ "
        "(shown there on Parr's maze only)."),
    ]
    mdp = Taxi(fickle=True, gamma=1.0).mdp()
    common = {"runs": s["runs"], "seed": config.seed, "alpha": ALPHA, "epsilon": EPSILON,
              "eval_every": s["eval_every"], "max_steps_per_episode": s["horizon"]}
    curves: dict[str, Any] = {}
    for label, abstraction, key in (("MAXQ-Q (abstraction)", True, "maxq"),
                                    ("MAXQ-Q (no abstraction)", False, "maxq_noabs")):
        config.progress(f"fickle Taxi: {label}")
        g = taxi_graph().compile(mdp, abstraction=abstraction)
        curves[label] = maxq_q(mdp, g, episodes=s[key], **common).curve
    config.progress("fickle Taxi: flat Q")
    curves["flat Q"] = q_learning(mdp, episodes=s["flat"], **common).curve
    config.progress("fickle Taxi: pipeline (flat deliver, count-mc, options, partition)")
    curves["pipeline (hierarchical)"], pipe = _taxi_pipeline(config, s)

    rows, censored, totals, gaps, steps, raw = [], {}, {}, {}, {}, {}
    for label, c in curves.items():
        g_ = c.matrix("value_gap")
        st = c.matrix("steps")
        ev = evaluated(c.n_episodes, s["eval_every"])
        to_tol, eps = steps_to_tolerance(g_, st, ev, TAXI_TOL)
        totals[label] = st.sum(axis=1).astype(np.float64)
        censored[label], raw[label] = _censored(to_tol, totals[label]), to_tol
        rows.append(_row(label, to_tol, eps, totals[label], g_[:, -1], config.seed))
        gaps[label], steps[label] = (g_[:, ev - 1], ev), st
    report.data["settings"] = {**s, "alpha": ALPHA, "epsilon": EPSILON, "tolerance": TAXI_TOL,
                               "gamma": 1.0, "pipeline_gamma": pipe["gamma"],
                               "seed": config.seed}
    report.data["rows"] = rows
    report.data["pipeline"] = pipe
    report.findings.append(
        f"fickle Taxi, gamma = 1 (pipeline: gamma = {pipe['gamma']:g}, the registered task), "
        f"{s['runs']} runs, alpha = {ALPHA}, epsilon = {EPSILON}; tolerance: the greedy "
        f"(for MAXQ-Q the polled hierarchically greedy) policy's value gap to V* stays <= "
        f"{TAXI_TOL}; never = censored (inf).")
    report.findings += [_row_sentence(r) for r in rows]
    med = {r["learner"]: r["steps_to_tol_median"] for r in rows}
    ratio = med["flat Q"] / med["MAXQ-Q (abstraction)"]
    report.data["ratio_flat_over_maxq"] = ratio
    bound = totals["flat Q"].mean() / med["MAXQ-Q (abstraction)"]
    text = (f"{ratio:.3g}" if np.isfinite(ratio) else
            f"> {bound:.3g} (flat Q's median run never settled within {s['flat']} episodes; "
            "bound = its mean whole budget / MAXQ-Q's median)" if np.isfinite(bound)
            else "undefined (MAXQ-Q with abstraction never settled)")
    report.findings.append(
        f"flat Q / MAXQ-Q (abstraction), ratio of medians of steps to tolerance: {text} "
        "(Dietterich: about 2)")
    report.findings.append(
        f"pipeline: {pipe['subgoals'] and len(pipe['subgoals'])} subgoals by count-mc, "
        f"{pipe['blocks']} initial blocks; its first (flat) pass over the same task cost "
        f"{pipe['first_task_steps_mean']:,.0f} primitive steps per run on average, NOT included "
        "in its row (the pipeline transfers from deliver to deliver, the only Taxi task).")
    names = list(curves)
    pairs = [(a, b) for i, a in enumerate(names) for b in names[i + 1:]]
    report.data["comparisons"] = (
        _pairs(report, censored, "primitive steps to tolerance (censored runs = whole budget)",
               pairs, config.seed, raw)
        + _pairs(report, totals, "total primitive steps of training (unequal budgets)",
                 [("MAXQ-Q (abstraction)", "pipeline (hierarchical)")], config.seed, raw))
    report.figures += _curve_plots(out, "taxi", steps, gaps, "fickle Taxi")
    return report


# --------------------------------------------------------------------------- maxq-parr


def _parr_settings(config: ExperimentConfig) -> dict[str, Any]:
    if config.quick:
        return {"runs": min(config.runs, 2), "first": 150, "episodes": 6, "eval_every": 3,
                "rollouts": 2, "horizon": 3000, "max_samples": 300}
    return {"runs": config.runs, "first": 3000, "episodes": 150, "eval_every": 15,
            "rollouts": 10, "horizon": 5000, "max_samples": 5000}


def _first_task(maze: Any) -> Any:
    """Reach the goal room's first cell from the start (the seed's "particular goal point")."""
    from adpart.envs.base import GoalSpec
    from adpart.envs.domains.parr_maze import GAMMA

    base = maze.mdp()
    cell = int(np.flatnonzero(base.terminal)[0])
    goal = {"x": int(base.features["x"][cell]), "y": int(base.features["y"][cell])}
    return maze.mdp(GoalSpec(goal=goal, goal_reward=0.0, gamma=GAMMA, name="reach-cell")), goal


def _maxq_parr(mdp: Any, s: dict[str, Any], seed: int, v_star: float
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """MAXQ-Q on the parr-maze graph scored by hierarchical greedy rollouts."""
    from adpart.learning.curves import start_distribution
    from adpart.learning.maxq import get_graph, hierarchical_rollouts
    from adpart.learning.maxq.maxq_q import _Run
    from adpart.learning.schedules import parse_schedule

    g = get_graph("parr-maze").compile(mdp)
    K, N, M = s["runs"], s["episodes"], s["eval_every"]
    ev = evaluated(N, M)
    cdf = np.cumsum(start_distribution(mdp))
    rngs = np.random.default_rng(seed).spawn(K)
    steps = np.zeros((K, N), dtype=np.int64)
    gaps = np.full((K, N), np.nan)
    for k in range(K):
        agent = _Run(mdp, g, rngs[k], parse_schedule(ALPHA), parse_schedule(EPSILON),
                     s["horizon"])
        for e in range(N):
            s0 = int(min(np.searchsorted(cdf, agent.rng.random(), side="right"),
                         mdp.n_states - 1))
            steps[k, e] = agent.episode_run(s0)[0]
            if e + 1 in ev:
                ret, _, done = hierarchical_rollouts(mdp, g, agent.tables(), s["rollouts"],
                                                     seed=seed + 7919 * k + e,
                                                     max_steps=s["horizon"])
                gaps[k, e] = v_star - float(np.mean(ret)) if done.all() else np.nan
    return steps, gaps, ev


@experiment(
    "maxq-parr",
    "Parr's maze: MAXQ-Q vs SMDP Q on discovered options vs the partition space",
    "Figs. 6.2, 6.3; chapter 6",
)
def maxq_parr(config: ExperimentConfig) -> ExperimentReport:
    """First task flat, Monte Carlo subgoals, options; the maze task by three learners."""
    from adpart.envs.domains.parr_maze import ParrMaze
    from adpart.learning.hierarchical import hierarchical_learning
    from adpart.learning.qlearning import q_learning
    from adpart.learning.smdp_q import smdp_q_learning
    from adpart.options.models import option_models
    from adpart.options.subgoal_options import subgoal_options
    from adpart.subgoals import discover_monte_carlo

    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    s = _parr_settings(config)
    report = ExperimentReport("maxq-parr", "MAXQ-Q and the partition space on Parr's maze")
    report.seed_reports = [
        ("Subgoal discovery on the first task converged after 140 sample trajectories; gradient "
        "ratios mean about 7.3, sd about 18.2; mu = 32 at p = 0.025."),
        ("Fig. 6.2: MAXQ-Q outperforms SMDP Q over the discovered subgoal options on the flat "
        "states."),
        ("Fig. 6.3: the hierarchical learner on the action-dependent partition significantly "
        "outperforms MAXQ-Q."),
        "Dietterich (2000) sec. 7.3: MAXQ-Q converges about 10x faster than flat Q on this maze.",
    ]
    maze = ParrMaze(mini=True)
    mdp = maze.mdp()
    first, goal = _first_task(maze)
    config.progress(f"parr mini maze: first task flat ({s['first']} episodes)")
    fr = q_learning(first, runs=1, episodes=s["first"], seed=config.seed, alpha=ALPHA,
                    epsilon=EPSILON, eval_every=max(1, s["first"] // 10),
                    max_steps_per_episode=s["horizon"])
    found = discover_monte_carlo(first, fr.greedy_policies()[0],
                                 np.random.default_rng(config.seed), on_loop="truncate",
                                 horizon=s["horizon"], max_samples=s["max_samples"])
    sub = found.subgoals[~mdp.terminal[found.subgoals]]
    # the new task's goal room is one more subgoal (section 4.3.1: high-reward states): its
    # first cell that a non-goal state can enter in one step stands for the room
    entered = np.asarray(mdp.P[np.flatnonzero(np.tile(~mdp.terminal, mdp.n_actions))]
                         .sum(axis=0)).ravel() > 0
    goal_cells = np.flatnonzero(mdp.terminal & entered)
    states = np.unique(np.r_[sub, goal_cells[:1]])
    config.progress(f"{sub.size} subgoals; options and models")
    # SMDP Q (primitives everywhere) gets the options near their subgoals only; the decision
    # layer needs every state covered, so far states also get their nearest subgoal's option
    options = subgoal_options(mdp, states, initiation="local")
    models = option_models(mdp, options, duration=False)
    layer_options = subgoal_options(mdp, states, initiation="local", cover=True)
    layer_models = option_models(mdp, layer_options, duration=False)
    st = found.stats
    report.data["first_task"] = {
        "goal": goal, "episodes": s["first"],
        "final_gap": float(fr.curve.matrix("value_gap")[0, -1]),
        "samples": st["samples"], "ratio_mean": st["ratio_mean"], "ratio_sd": st["ratio_sd"],
        "mu": found.threshold, "stop_reason": st["stop_reason"], "subgoals": sub.tolist(),
        "truncated_trajectories": st["truncated_trajectories"]}
    report.findings.append(
        f"first task (reach cell x={goal['x']}, y={goal['y']}), flat Q {s['first']} episodes, "
        f"final gap {report.data['first_task']['final_gap']:.3g}; count-mc: "
        f"{st['samples']} sample trajectories (stop: {st['stop_reason']}), gradient ratios mean "
        f"{st['ratio_mean']:.3g}, sd {st['ratio_sd']:.3g}, mu = {found.threshold:.3g} "
        f"(p = 0.025) -> {sub.size} subgoals (seed: 140 samples, mean 7.3, sd 18.2, mu 32); "
        f"{len(options)} options incl. the goal room.")

    common = {"runs": s["runs"], "episodes": s["episodes"], "seed": config.seed,
              "eval_every": s["eval_every"], "max_steps_per_episode": s["horizon"],
              "alpha": ALPHA}
    config.progress("maze task: SMDP Q on the discovered options")
    smdp = smdp_q_learning(mdp, options, include_primitives=True, models=models,
                           epsilon=EPSILON, **common)
    v_star = float(smdp.v_star_start)
    config.progress("maze task: hierarchical learner on the multi-phase partition")
    hier = hierarchical_learning(mdp, layer_options, models=layer_models, delta=0.3,
                                 epsilon=10.0,
                                 epsilon_greedy=EPSILON, **common)
    config.progress("maze task: MAXQ-Q (hierarchical greedy rollouts)")
    m_steps, m_gaps, m_ev = _maxq_parr(mdp, s, config.seed, v_star)

    series: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {
        "(a) MAXQ-Q": (m_steps, m_gaps, m_ev)}
    for label, res in (("(b) SMDP Q (options)", smdp), ("(c) partition space", hier)):
        c = res.curve
        series[label] = (c.matrix("steps"), c.matrix("value_gap"),
                         evaluated(c.n_episodes, s["eval_every"]))
    rows, censored, totals, raw = [], {}, {}, {}
    for label, (st_, g_, ev) in series.items():
        to_tol, eps = steps_to_tolerance(g_, st_, ev, PARR_TOL)
        totals[label] = st_.sum(axis=1).astype(np.float64)
        censored[label], raw[label] = _censored(to_tol, totals[label]), to_tol
        rows.append(_row(label, to_tol, eps, totals[label], g_[:, ev[-1] - 1], config.seed))
    report.data["settings"] = {**s, "maze": "parr-maze mini (ParrMaze(mini=True), 1,988 states)",
                               "gamma": mdp.gamma, "tolerance": PARR_TOL, "v_star_start": v_star,
                               "alpha": ALPHA, "epsilon": EPSILON, "seed": config.seed,
                               "blocks_initial": int(hier.blocks[0, 0]),
                               "blocks_final_mean": float(hier.blocks[:, -1].mean())}
    report.data["rows"] = rows
    report.findings.append(
        f"maze task on the MINI maze (1,988 states, gamma {mdp.gamma:g}), {s['runs']} runs x "
        f"{s['episodes']} episodes (reduced from the seed's length to fit about 10 minutes), "
        f"tolerance: gap to V*(start) = {v_star:.2f} stays <= {PARR_TOL} (MAXQ-Q: mean of "
        f"{s['rollouts']} hierarchical greedy rollouts, undefined if one does not finish); "
        f"partition: {int(hier.blocks[0, 0])} initial blocks, "
        f"{float(hier.blocks[:, -1].mean()):.0f} after refinement (mean).")
    report.findings += [_row_sentence(r) for r in rows]
    claims = [("(a) MAXQ-Q", "(b) SMDP Q (options)"), ("(c) partition space", "(a) MAXQ-Q"),
              ("(c) partition space", "(b) SMDP Q (options)")]
    report.data["comparisons"] = (
        _pairs(report, totals, "total primitive steps over the episodes (Figs. 6.2/6.3)",
               claims, config.seed, raw)
        + _pairs(report, censored, "primitive steps to tolerance (censored = whole budget)",
                 claims, config.seed, raw))
    wins = {(c["label_a"], c["label_b"], c["what"][:5]): c["diff_ci"][1] < 0
            for c in report.data["comparisons"]}
    report.findings.append(
        "seed's claims vs ours (total primitive steps, 95% Welch CI): MAXQ beats (b): "
        f"{'confirmed' if wins[claims[0] + ('total',)] else 'not confirmed'}; (c) beats "
        f"MAXQ: {'confirmed' if wins[claims[1] + ('total',)] else 'not confirmed'}.")
    report.figures += _curve_plots(
        out, "parr", {k: v[0] for k, v in series.items()},
        {k: (v[1][:, v[2] - 1], v[2]) for k, v in series.items()}, "Parr mini maze")
    return report

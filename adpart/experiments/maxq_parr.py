"""``adpart experiment maxq-parr`` and ``maxq-parr-full``: MAXQ-Q against the partition space on
Parr's maze (chapter 6; the protocol and statistics are :mod:`adpart.experiments.maxq`'s).

**maxq-parr** (Figs. 6.2, 6.3): Parr's maze, the *mini* reconstruction
(``ParrMaze(mini=True)``, 1,988 states; not a registered environment, so the MDPs are built
directly and no knowledge base is used), and **maxq-parr-full** the same on the full 3,710-state
reconstruction (MAXQ-Q's learning and rollouts take about 1.7x the mini maze's time). A first
task (reach the goal room's first cell from the start) is learned flat; subgoals are found in
its greedy policy by Monte Carlo sampling of the count metric
(:func:`adpart.subgoals.discover_monte_carlo`, section 4.1.1; samples, ratio mean/sd and mu
reported); options to them are computed (:func:`adpart.options.subgoal_options.subgoal_options`
with exact models). The maze task is then learned by (a) MAXQ-Q on the ``parr-maze`` graph,
(b) SMDP Q over the discovered options plus the primitives on the flat states (basin initiation
sets, values learned from below: see :data:`SMDP_INITIATION`), (c) the
hierarchical learner on the multi-phase partition over the same options (values from below as
well, primitives explored only through the inconsistency test: see
:data:`LAYER_PRIMITIVE_EXPLORATION`). MAXQ-Q's call-time
parameters make its policy non-Markov in the state, so it is scored by executing the
hierarchical greedy policy (:func:`adpart.learning.maxq.hierarchical_rollouts`); (b) and (c)
exactly. MAXQ-Q, the slowest to settle, is then run on past the comparisons' budget
(:data:`SETTLE`) to measure where and when it settles against its own ceiling.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from adpart.experiments.base import ExperimentConfig, ExperimentReport, experiment
from adpart.experiments.maxq import (
    ALPHA,
    EPSILON,
    censored_at_total,
    claim,
    curve_plots,
    evaluated,
    line_plot,
    pair_auc,
    verdict_of,
)
from adpart.experiments.protocol import (
    layer_ceiling,
    option_chain_reach,
    options_only_optimum,
    score,
    sentence,
)
from adpart.workflows.progress import learning_progress

#: Tolerance of the value gap on the maze (reward units, mean over the start distribution).
PARR_TOL = 2.0
#: The gap an undefined value (a policy that never arrives) counts as in the areas.
PARR_CAP = 100.0


#: Initiation sets of SMDP Q's options (b) on Parr's maze, and its values start at the
#: never-arrive value ``r_min / (1 - gamma) = -100`` ("from below"). Measured on the mini and
#: full maze, 20 runs x 500 episodes each (docs/maxq.md): local radius-30 options from
#: optimistic values (Q = 0) reach the goal while learning in every run but the greedy policy
#: never does - after 1,500 episodes its values at the start are -25 against V* = -69, and
#: the greedy choice there is noise; from below, local options never reach the goal (they do
#: not chain to the goal room, and nothing is optimistic enough to explore); basin options from
#: below give a greedy policy that reaches the goal in 20 of 20 runs on both mazes. From below,
#: along a greedy path each value ``Q(s, o) = R + gamma^tau max Q(s')`` above the never-arrive
#: value forces a strictly higher value downstream, so in a deterministic MDP the path cannot
#: loop: it ends at the goal (the maze's slips make this an expectation, not a certainty).
SMDP_INITIATION = "basin"

#: The layer learner (c) starts from below too, and explores the primitives only through the
#: inconsistency test: its default ``"until-reward"`` explores them until a reward above the step
#: reward arrives, which on the maze (-1 a step, the goal included) never happens. Measured on
#: the mini maze, 5 runs x 500 episodes: with the defaults (Q = 0, ``until-reward``) and with
#: values from below alone, the final greedy policy never arrives (gap 30.9 in every run, episodes
#: of about 2,300 steps); from below with ``"never"``, 4 of 5 runs settle within 2 of the layer's
#: ceiling after a median of 175 episodes (final gap median 7.12, ceiling 6.12).
LAYER_PRIMITIVE_EXPLORATION = "never"


#: The settling run of the slowest learner (MAXQ-Q): runs, episodes, evaluated every, rollouts
#: per evaluation. Measured with seed 0, 4 runs, 30 rollouts: on the full maze its gap to V* is
#: 15.3 (never arriving) up to episode 3,000, 10.6-13.3 at 10,000 and 9.2-10.3 from 17,000 to
#: 20,000 (ceiling 9.13), 190 s per run; on the mini maze it falls from 27-31 after 1,000
#: episodes to 17.0-19.5 at 16,000 and stays at 16.8-19.1 up to 30,000 (ceiling 15.8), 97 s
#: per run.
#: The settling run has levelled off when its mean gap over the last third of the evaluations
#: differs from the mean over the third before by less than this (single evaluations are noisy:
#: in the mini maze's settling run one of 120 read 12.5 above its run's neighbours).
PLATEAU = 0.5
SETTLE = {"mini": (4, 30_000, 1_000, 30), "full": (4, 20_000, 1_000, 30)}


def _parr_settings(config: ExperimentConfig, which: str) -> dict[str, Any]:
    if config.quick:
        return {"runs": min(config.runs, 2), "first": 150, "episodes": 6, "eval_every": 3,
                "rollouts": 2, "horizon": 3000, "max_samples": 300,
                "settle": {"runs": 1, "episodes": 12, "eval_every": 6, "rollouts": 2}}
    runs, episodes, every, rollouts = SETTLE[which]
    return {"runs": config.runs, "first": 3000, "episodes": 500, "eval_every": 25,
            "rollouts": 10, "horizon": 5000, "max_samples": 5000,
            "settle": {"runs": min(runs, config.runs), "episodes": episodes,
                       "eval_every": every, "rollouts": rollouts}}


def goal_room_cell(mdp: Any) -> np.ndarray:
    """``(1,)`` the maze task's goal room as one more subgoal (section 4.3.1: high-reward
    states): its first cell that a non-goal state can enter in one step stands for the room."""
    entered = np.asarray(mdp.P[np.flatnonzero(np.tile(~mdp.terminal, mdp.n_actions))]
                         .sum(axis=0)).ravel() > 0
    return np.flatnonzero(mdp.terminal & entered)[:1]


def _first_task(maze: Any) -> Any:
    """Reach the goal room's first cell from the start (the seed's "particular goal point")."""
    from adpart.envs.base import GoalSpec
    from adpart.envs.domains.parr_maze import GAMMA

    base = maze.mdp()
    cell = int(np.flatnonzero(base.terminal)[0])
    goal = {"x": int(base.features["x"][cell]), "y": int(base.features["y"][cell])}
    return maze.mdp(GoalSpec(goal=goal, goal_reward=0.0, gamma=GAMMA, name="reach-cell")), goal


def _maxq_parr(mdp: Any, g: Any, s: dict[str, Any], seed: int, v_star: float
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """MAXQ-Q on the parr-maze graph scored by hierarchical greedy rollouts: ``(steps, gaps,
    evaluated episodes, fraction of rollouts that reached the goal)``."""
    from adpart.learning.curves import start_distribution
    from adpart.learning.maxq import hierarchical_rollouts
    from adpart.learning.maxq.maxq_q import AgentRun
    from adpart.learning.schedules import parse_schedule

    K, N, M = s["runs"], s["episodes"], s["eval_every"]
    ev = evaluated(N, M)
    cdf = np.cumsum(start_distribution(mdp))
    rngs = np.random.default_rng(seed).spawn(K)
    steps = np.zeros((K, N), dtype=np.int64)
    gaps = np.full((K, N), np.nan)
    finished = np.full((K, N), np.nan)
    for k in range(K):
        agent = AgentRun(mdp, g, rngs[k], parse_schedule(ALPHA), parse_schedule(EPSILON),
                     s["horizon"])
        for e in range(N):
            s0 = int(min(np.searchsorted(cdf, agent.rng.random(), side="right"),
                         mdp.n_states - 1))
            steps[k, e] = agent.episode_run(s0)[0]
            if e + 1 in ev:
                ret, _, done = hierarchical_rollouts(mdp, g, agent.tables(), s["rollouts"],
                                                     seed=seed + 7919 * k + e,
                                                     max_steps=s["horizon"])
                # gamma < 1: a rollout cut at the horizon has the value of never arriving up to
                # gamma^horizon / (1 - gamma) (< 1e-19 here), the scale the exact scores use
                gaps[k, e] = v_star - float(np.mean(ret))
                finished[k, e] = float(np.mean(done))
    return steps, gaps, ev, finished


def _settling(mdp: Any, g: Any, s: dict[str, Any], seed: int, v_star: float, ceiling_gap: float,
              out: Path, which: str) -> tuple[dict[str, Any], str]:
    """MAXQ-Q, the slowest learner, run past the comparison's budget (``s["settle"]``): does
    its hierarchical greedy policy settle within :data:`PARR_TOL` of its own ceiling, and
    after how many episodes? Returns the record and the figure (gap to the ceiling per run)."""
    from adpart.experiments.protocol import steps_to

    cfg = {**s, **s["settle"]}
    steps, gaps, ev, done = _maxq_parr(mdp, g, cfg, seed + 1, v_star)
    own = gaps[:, ev - 1] - ceiling_gap
    _steps, episodes = steps_to(gaps - ceiling_gap, steps, ev, PARR_TOL)
    tail = max(1, ev.size // 3)
    level = float(own[:, -tail:].mean())
    change = level - float(own[:, -2 * tail:-tail].mean())
    settled = np.isfinite(episodes)
    record = {**s["settle"], "seed": seed + 1, "evaluated": ev.tolist(),
              "gap_to_ceiling": own.tolist(), "episodes_to_settle": [
                  float(e) if np.isfinite(e) else None for e in episodes],
              "settled_runs": int(settled.sum()),
              "final_gap_to_ceiling": own[:, -1].tolist(),
              "last_third_gap_to_ceiling": level,
              "last_third_change": change,
              "rollouts_finished_final": float(np.mean(done[:, ev[-1] - 1]))}
    figure = line_plot({f"run {k + 1}": (ev, own[k]) for k in range(own.shape[0])},
                       out / "parr_maxq_settling.png", "episode",
                       "gap to its own ceiling (rollouts)",
                       f"Parr {which} maze: MAXQ-Q past the comparison's budget",
                       reference=(PARR_TOL, f"tolerance {PARR_TOL:g}"))
    return record, figure


def _settling_sentence(r: dict[str, Any], ceiling_gap: float, budget: int) -> str:
    n, k = r["episodes"], len(r["final_gap_to_ceiling"])
    final = np.asarray(r["final_gap_to_ceiling"])
    reached = [int(e) for e in r["episodes_to_settle"] if e is not None]
    when = f" (from episode {min(reached):,}-{max(reached):,} on)" if reached else ""
    level, change = r["last_third_gap_to_ceiling"], r["last_third_change"]
    if r["settled_runs"] == k:
        verdict = f"so a budget of about {max(reached):,} episodes lets the slowest learner settle"
    elif abs(change) < PLATEAU:
        where = ("inside the tolerance on average, though single evaluations cross it"
                 if level <= PARR_TOL else
                 "outside the tolerance, and at this rate a longer budget would not change that")
        verdict = (f"it has levelled off (the mean moved by {change:+.2g} from the third before): "
                   f"it settles {level:.3g} above its ceiling, {where}")
    else:
        verdict = f"so the budget that lets it settle is longer than {n:,} episodes"
    return (f"(a) MAXQ-Q past the comparison's budget ({budget} episodes): {k} run(s) x {n:,} "
            f"episodes, {r['rollouts']} rollouts every {r['eval_every']:,}: within {PARR_TOL:g} "
            f"of its ceiling ({ceiling_gap:.3g} below V*) at every evaluation from some episode "
            f"on in {r['settled_runs']} of {k} run(s){when}; final gap to the ceiling median "
            f"{np.median(final):.3g} (runs {final.min():.3g} to {final.max():.3g}), mean over "
            f"the last third of the evaluations {level:.3g}; {verdict}.")


@experiment(
    "maxq-parr",
    "Parr's mini maze: MAXQ-Q vs SMDP Q on discovered options vs the partition space",
    "Figs. 6.2, 6.3; chapter 6",
)
def maxq_parr(config: ExperimentConfig) -> ExperimentReport:
    """The mini maze (1,988 states): first task flat, Monte Carlo subgoals, options; the maze
    task by three learners."""
    return _parr(config, mini=True)


@experiment(
    "maxq-parr-full",
    "Parr's full maze: MAXQ-Q vs SMDP Q on discovered options vs the partition space",
    "Figs. 6.2, 6.3; chapter 6",
)
def maxq_parr_full(config: ExperimentConfig) -> ExperimentReport:
    """``maxq-parr`` on the full 3,710-state reconstruction of Parr's maze."""
    return _parr(config, mini=False)


def _parr(config: ExperimentConfig, *, mini: bool) -> ExperimentReport:
    from adpart.envs.domains.parr_maze import ParrMaze
    from adpart.learning.curves import start_distribution
    from adpart.learning.hierarchical import (
        decision_layer,
        flat_lower_bound,
        hierarchical_learning,
    )
    from adpart.learning.hierarchical_settings import HierarchicalSettings
    from adpart.learning.maxq import get_graph, recursively_optimal
    from adpart.learning.qlearning import q_learning
    from adpart.learning.settings import Run
    from adpart.learning.smdp_q import SMDPQSettings, option_set, smdp_q_learning
    from adpart.options.models import option_models
    from adpart.options.subgoal_options import subgoal_options
    from adpart.params import build_settings
    from adpart.subgoals import MonteCarloSettings, discover_monte_carlo

    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    name, which = ("maxq-parr", "mini") if mini else ("maxq-parr-full", "full")
    s = _parr_settings(config, which)
    report = ExperimentReport(name, f"MAXQ-Q and the partition space on Parr's {which} maze")
    report.seed_reports = [
        ("Subgoal discovery on the first task converged after 140 sample trajectories; gradient "
        "ratios mean about 7.3, sd about 18.2; mu = 32 at p = 0.025."),
        ("Fig. 6.2: MAXQ-Q outperforms SMDP Q over the discovered subgoal options on the flat "
        "states."),
        ("Fig. 6.3: the hierarchical learner on the action-dependent partition significantly "
        "outperforms MAXQ-Q."),
        "Dietterich (2000) sec. 7.3: MAXQ-Q converges about 10x faster than flat Q on this maze.",
    ]
    maze = ParrMaze(mini=mini)
    mdp = maze.mdp()
    first, goal = _first_task(maze)
    config.progress(f"parr {which} maze: first task flat ({s['first']} episodes)")
    with learning_progress(Run(runs=1, episodes=s["first"], seed=config.seed, alpha=ALPHA,
                               epsilon=EPSILON, eval_every=max(1, s["first"] // 10),
                               max_steps_per_episode=s["horizon"]), "first task") as run:
        fr = q_learning(first, run)
    found = discover_monte_carlo(first, fr.greedy_policies()[0],
                                 np.random.default_rng(config.seed),
                                 build_settings(MonteCarloSettings,
                                                {"on_loop": "truncate",
                                                 "max_samples": s["max_samples"]}),
                                 horizon=s["horizon"])
    sub = found.subgoals[~mdp.terminal[found.subgoals]]
    states = np.unique(np.r_[sub, goal_room_cell(mdp)])
    config.progress(f"{sub.size} subgoals; options and models")
    # SMDP Q (primitives everywhere) gets the basin options (SMDP_INITIATION); the decision
    # layer needs every state covered, so it gets local options plus each far state's nearest
    # subgoal's option - unless chaining those options cannot reach the goal from the start
    # (measured on this maze: local radius-30 options reach 26 of 30 subgoals and never the
    # goal room), in which case a layer over them could only ever learn never to arrive; it
    # then gets the options of every state that can reach their subgoal
    options = subgoal_options(mdp, states, initiation=SMDP_INITIATION)
    models = option_models(mdp, options, duration=False)
    from_below = flat_lower_bound(mdp, s["horizon"])
    mu = start_distribution(mdp)
    chain = {}
    for init in ("local", "reachable"):
        layer_options = subgoal_options(mdp, states, initiation=init, cover=init == "local")
        layer_models = option_models(mdp, layer_options, duration=False)
        full_smdp = option_set(mdp, layer_options, include_primitives=True,
                               models=layer_models)[1]
        chain[init] = option_chain_reach(full_smdp, mdp.n_actions, mu, mdp.terminal)
        if chain[init][1]:
            break
    layer_initiation = init
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
    report.data["smdp_q"] = {"initiation": SMDP_INITIATION, "q_init": from_below}
    report.data["layer_learner"] = {"initiation": layer_initiation,
                                    "q_init": from_below,
                                    "primitive_exploration": LAYER_PRIMITIVE_EXPLORATION}

    common = {"runs": s["runs"], "episodes": s["episodes"], "seed": config.seed,
              "eval_every": s["eval_every"], "max_steps_per_episode": s["horizon"],
              "alpha": ALPHA}
    config.progress("maze task: SMDP Q on the discovered options")
    with learning_progress(Run(epsilon=EPSILON, q_init=from_below, **common), "SMDP Q") as run:
        smdp = smdp_q_learning(mdp, options, SMDPQSettings(include_primitives=True), run,
                               models)
    v_star = float(smdp.v_star_start)
    smdp_final = smdp.curve.matrix("value_gap")[:, -1]
    never_gap = v_star - from_below
    smdp_arrive = int(np.sum(smdp_final < never_gap * (1 - 1e-9)))
    config.progress("maze task: hierarchical learner on the multi-phase partition")
    layer, _full, layer_smdp = decision_layer(mdp, layer_options, delta=0.3, epsilon=10.0,
                                              models=layer_models)
    with learning_progress(Run(epsilon=EPSILON, q_init=from_below, **common),
                           "hierarchical") as run:
        hier = hierarchical_learning(
            mdp, layer_options, layer,
            build_settings(HierarchicalSettings, {
                "delta": 0.3, "partition_epsilon": 10.0,
                "primitive_exploration": LAYER_PRIMITIVE_EXPLORATION}),
            run, layer_models)
    config.progress("maze task: MAXQ-Q (hierarchical greedy rollouts)")
    g = get_graph("parr-maze").compile(mdp)
    m_steps, m_gaps, m_ev, m_done = _maxq_parr(mdp, g, s, config.seed, v_star)
    config.progress("ceilings: the parr graph's recursively optimal value, the layers' optima")
    maxq_ceiling = float(mu @ recursively_optimal(mdp, g).V[g.root])
    config.progress(f"MAXQ-Q past the budget: {s['settle']['runs']} runs x "
                    f"{s['settle']['episodes']:,} episodes")
    settling, settle_figure = _settling(mdp, g, s, config.seed, v_star, v_star - maxq_ceiling, out,
                                        which)
    report.data["maxq_settling"] = settling
    layer_ceilings = np.array([layer_ceiling(p, layer_smdp, mu) for p in hier.partitions])
    initial_layer = layer_ceiling(layer, layer_smdp, mu)
    options_opt = options_only_optimum(layer_smdp, mdp.n_actions, mu)
    ceilings = {
        "(a) MAXQ-Q": (v_star - maxq_ceiling,
                       ("the recursively optimal value of the parr-maze graph, executed with its "
                       f"call stack (exact solve of its {g.n_composite} subtask instances)")),
        "(b) SMDP Q (options)": (0.0, "V* (the primitives are offered in every state)"),
        "(c) partition space": (v_star - layer_ceilings,
                                ("the executed point-model optimum of the run's final layer "
                                f"(initial layer: {v_star - initial_layer:.3g} below V*)")),
    }
    step_size = {"(a) MAXQ-Q": f"alpha = {ALPHA} per C/V table entry",
                 "(b) SMDP Q (options)": f"alpha = {ALPHA} per (state, option) decision",
                 "(c) partition space": f"alpha = {ALPHA} per (block, option) decision"}

    series: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {
        "(a) MAXQ-Q": (m_steps, m_gaps, m_ev)}
    for label, res in (("(b) SMDP Q (options)", smdp), ("(c) partition space", hier)):
        c = res.curve
        series[label] = (c.matrix("steps"), c.matrix("value_gap"),
                         evaluated(c.n_episodes, s["eval_every"]))
    rows, censored, totals, own = [], {}, {}, {}
    cum_at = {k: np.cumsum(st_, axis=1)[:, ev - 1] for k, (st_, _g, ev) in series.items()}
    gap_at = {k: (g_[:, ev - 1], ev) for k, (_st, g_, ev) in series.items()}
    for label, (st_, g_, ev) in series.items():
        row = score(label, g_, st_, ev, tol=PARR_TOL, ceiling_gap=ceilings[label][0],
                    cap=PARR_CAP, ceiling_name=ceilings[label][1],
                    step_size=step_size[label], seed=config.seed)
        rows.append(row)
        totals[label] = st_.sum(axis=1).astype(np.float64)
        censored[label] = censored_at_total(np.array(row["v_star"]["steps"]), totals[label])
        own[label] = censored_at_total(np.array(row["own"]["steps"]), totals[label])
    report.data["settings"] = {**s, "maze": f"parr-maze {which} (ParrMaze(mini={mini}), "
                                                    f"{mdp.n_states:,} states)",
                               "gamma": mdp.gamma, "tolerance": PARR_TOL, "v_star_start": v_star,
                               "alpha": ALPHA, "epsilon": EPSILON, "seed": config.seed,
                               "blocks_initial": int(hier.blocks[0, 0]),
                               "blocks_final_mean": float(hier.blocks[:, -1].mean()),
                               "maxq_ceiling": maxq_ceiling,
                               "layer_ceiling_initial": initial_layer,
                               "options_only_optimum": options_opt,
                               "layer_initiation": layer_initiation,
                               "option_chains": {k: {"states_reached": v[0], "goal": v[1]}
                                                 for k, v in chain.items()},
                               "layer_ceilings_final": layer_ceilings.tolist(),
                               "gap_cap": PARR_CAP,
                               "maxq_rollouts_finished_final": float(
                                   np.mean(m_done[:, m_ev[-1] - 1]))}
    report.data["rows"] = rows
    report.findings.append(
        f"maze task on the {which.upper()} maze ({mdp.n_states:,} states, gamma {mdp.gamma:g}), "
        f"{s['runs']} runs x {s['episodes']} episodes (reduced from the seed's length: MAXQ-Q's "
        "rollouts make 20 runs take 20-40 minutes on 2 cores), "
        f"tolerance {PARR_TOL} on the gap to V*(start) = {v_star:.2f} and to each learner's own "
        f"ceiling (MAXQ-Q: mean discounted return of {s['rollouts']} hierarchical greedy "
        f"rollouts cut at {s['horizon']} steps - a policy that never arrives is worth -100, "
        f"gap {v_star + 100:.3g}, as in the exact scores; at the end "
        f"{100 * float(np.mean(m_done[:, m_ev[-1] - 1])):.0f}% of its rollouts reached the goal;"
        f" the others exact); partition: {int(hier.blocks[0, 0])} initial "
        f"blocks, {float(hier.blocks[:, -1].mean()):.0f} after refinement (mean).")
    report.findings.append(
        "decision layer options: " + "; ".join(
            f"{k} initiation - option chains from the start reach {v[0]} states, "
            f"{'including' if v[1] else 'NOT'} the goal room" for k, v in chain.items())
        + f" -> the layer uses {layer_initiation} initiation (SMDP Q: {SMDP_INITIATION} options "
        "plus the primitives).")
    report.data["smdp_q"].update({"greedy_reaches_goal": smdp_arrive,
                                  "final_gap_median": float(np.median(smdp_final)),
                                  "never_arrive_gap": never_gap})
    report.findings.append(
        f"(b) SMDP Q over the discovered options ({SMDP_INITIATION} initiation, values from "
        f"{from_below:g}): the final greedy policy reaches the goal in {smdp_arrive} of "
        f"{s['runs']} runs (median final gap {np.median(smdp_final):.3g}; never arriving is "
        f"{never_gap:.3g}).")
    report.findings += [sentence(r) for r in rows]
    report.findings.append(_settling_sentence(settling, v_star - maxq_ceiling, s["episodes"]))
    claims = [("(a) MAXQ-Q", "(b) SMDP Q (options)"), ("(c) partition space", "(a) MAXQ-Q"),
              ("(c) partition space", "(b) SMDP Q (options)")]
    comps = []
    for la, lb in claims:
        comps.append(claim(report, f"total primitive steps over {s['episodes']} episodes "
                            "(the area under Figs. 6.2/6.3)", totals[la], totals[lb], la, lb,
                            config.seed))
        auc_a, auc_b, window = pair_auc(gap_at, cum_at, la, lb, PARR_CAP)
        comps.append(claim(report, f"mean gap to V* over {window} (the pair's common window)",
                            auc_a, auc_b, la, lb, config.seed))
        comps.append(claim(report, "primitive steps to within the tolerance of the own ceiling"
                            " (censored = budget)", own[la], own[lb], la, lb, config.seed))
    report.data["comparisons"] = comps
    verdict = {(c["label_a"], c["label_b"], c["what"].split()[0]): verdict_of(c) for c in comps}
    report.findings.append(
        "seed's claims vs ours (95% Welch CIs; the sequential test's decisions above): "
        f"Fig. 6.2 'MAXQ-Q beats SMDP Q over the discovered options' - total steps: "
        f"{verdict[claims[0] + ('total',)]}, mean gap to V*: {verdict[claims[0] + ('mean',)]};"
        f" Fig. 6.3 'the partitioned learner significantly beats MAXQ-Q' - total steps: "
        f"{verdict[claims[1] + ('total',)]}, mean gap to V*: {verdict[claims[1] + ('mean',)]}.")
    report.figures += curve_plots(
        out, "parr", {k: v[0] for k, v in series.items()},
        {k: (v[1][:, v[2] - 1], v[2]) for k, v in series.items()}, f"Parr {which} maze")
    report.figures.append(settle_figure)
    return report

"""``adpart experiment options-three-floor``: Figs. 5.2 and 5.4, sections 5.1.2-5.1.3.

On ``three-floor`` the source task ``reach-goal`` is solved exactly (its optimal policy is what a
converged Q-learner would hold; value iteration gives it without learning noise), subgoals are
discovered on that policy by the count metric (:func:`adpart.subgoals.discover_exhaustive`,
p = 0.025, section 4.1.1), and options to them are learned off-line on the *new* task's MDP
(:func:`adpart.options.subgoal_options.subgoal_options`, section 4.2.1) with *local* initiation
sets: the basin's states within ``radius`` steps of the subgoal (default 30; docs/options.md
has the measurement that chose it - whole basins made SMDP Q 11.9x slower than flat here).
The new task ``reach-top-west`` is then learned

* flat, by Q-learning over the primitive actions;
* by SMDP Q-learning (:func:`adpart.learning.smdp_q.smdp_q_learning`) over the discovered subgoal
  options, and over the hand-designed doorway/stair options of Fig. 5.1
  (:func:`adpart.options.handmade.doorway_options`).

Neither subgoal set contains the new task's goal, so options alone can never enter it. Two ways
to make the goal reachable, both run:

* **+ primitives** (Fig. 5.2's setting, where the seed reaches the goal by other means): the
  primitive actions are offered next to the options, so the last stretch is walked step by step;
* **+ goal option** (Fig. 5.4, reward variation, section 4.3.1): the new goal - the one state with
  reward above 0 on arrival - is one more subgoal, its option offered in every state that can
  reach it (reward variation's rule), and no primitives are offered.

All learners use the same seed, alpha = 1 (the world is deterministic, so a full step is the
exact Bellman backup of the sampled transition), epsilon = 0.1, Q initialised to 0, a step cap per
episode, and score their greedy policy exactly every ``eval_every`` episodes (value gap at the
start state against the flat V*, :mod:`adpart.learning.curves`). Episodes to threshold - the first
evaluation from which the gap stays <= 10 % of the gap of a policy that never reaches the goal,
the threshold of ``partition-three-floor`` - are compared pairwise with
:func:`adpart.experiments.stats.compare`; runs that never get there count as ``episodes + 1``
(censored, said in the findings).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from adpart.experiments.base import ExperimentConfig, ExperimentReport, experiment
from adpart.experiments.stats import compare, episodes_to_threshold
from adpart.workflows.progress import learning_progress

ENV = "three-floor"
SOURCE_TASK = "reach-goal"
NEW_TASK = "reach-top-west"
ALPHA = 1.0
EPSILON = 0.1
FLAT = "flat Q-learning"
#: Radius (steps) of the options' local initiation sets.
RADIUS = 30


def _settings(config: ExperimentConfig) -> dict[str, int]:
    if config.quick:
        return {"runs": min(config.runs, 2), "episodes": 60, "eval_every": 10, "horizon": 2000}
    return {"runs": config.runs, "episodes": 5000, "eval_every": 10, "horizon": 5000}


def _options(mdp: Any, states: np.ndarray, goal: np.ndarray | None = None
             ) -> tuple[list[Any], list[Any]]:
    """Options to ``states`` (local initiation) and to ``goal`` (from every state that can reach
    it, as reward variation builds it, section 4.3.1), with exact models."""
    from adpart.options.models import option_models
    from adpart.options.subgoal_options import subgoal_option, subgoal_options

    mask = np.zeros(mdp.n_states, dtype=bool)
    mask[states] = True
    options = subgoal_options(mdp, mask, initiation="local", radius=RADIUS, cover=False)
    if goal is not None:
        options += [subgoal_option(mdp, int(g), initiation="reachable", name=f"reward-{int(g)}")
                    for g in goal]
    return options, option_models(mdp, options, duration=False)


def _reached(curve: Any, threshold: float, episodes: int) -> np.ndarray:
    gaps = curve.matrix("value_gap")
    evaluated = curve.evaluated_episodes()
    reached = episodes_to_threshold(gaps, evaluated, threshold)
    return np.where(np.isfinite(reached), reached, episodes + 1.0)


@experiment(
    "options-three-floor",
    "A new task on three-floor learned flat vs on the SMDP of subgoal options",
    "Figs. 5.2, 5.4; sections 5.1.2-5.1.3",
)
def options_three_floor(config: ExperimentConfig) -> ExperimentReport:
    """Discover subgoals on reach-goal, learn options, learn reach-top-west flat and on SMDPs."""
    from adpart.learning.curves import plot_curves
    from adpart.learning.qlearning import q_learning
    from adpart.learning.settings import Run
    from adpart.learning.smdp_q import SMDPQSettings, option_set, smdp_q_learning
    from adpart.mdp.solvers import solve
    from adpart.subgoals import discover_exhaustive
    from adpart.workflows.resolve import resolve_domain as get_domain

    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    s = _settings(config)
    report = ExperimentReport("options-three-floor",
                              "Learning a new task with subgoal options on three-floor "
                              "(Figs. 5.2, 5.4)")
    report.seed_reports = [
        ("Section 5.1.2: on three-floor's Q-learned policy the gradient ratios have mean 5.427, "
         "sd 18.09; the t-test at p = 0.025 gives mu = 35; fewer subgoals are found than the "
         "hand-designed doorways and stairways."),
        ("Figs. 5.2 and 5.4: averaged over 50 runs, the policies learned on the SMDPs of the "
         "hand-designed and of the discovered subgoal options are almost optimal; their Q-values "
         "converge in about 300 iterations against about 500 on the flat MDP; discovered "
         "subgoals perform almost as well as hand-designed ones."),
    ]
    domain = get_domain(ENV)
    source = domain.mdp(SOURCE_TASK)
    mdp = domain.mdp(NEW_TASK)
    config.progress(f"solving {SOURCE_TASK} and discovering subgoals on its optimal policy")
    found = discover_exhaustive(source, solve(source).policy, np.random.default_rng(config.seed))
    discovered = found.subgoals[~mdp.terminal[found.subgoals]]
    feats = mdp.features
    hubs = np.flatnonzero((np.asarray(feats["doorway"]) == 1) | (np.asarray(feats["stair"]) == 1))
    hubs = hubs[~mdp.terminal[hubs]]
    goal = np.flatnonzero(mdp.terminal)
    config.progress("options to the discovered and the hand-designed subgoals")
    sets = {
        "discovered + primitives": (discovered, False),
        "hand-designed + primitives": (hubs, False),
        "discovered + goal option": (discovered, True),
        "hand-designed + goal option": (hubs, True),
    }
    built = {name: (*_options(mdp, np.unique(states), goal if with_goal else None),
                    not with_goal)
             for name, (states, with_goal) in sets.items()}
    flat_pairs = int(mdp.admissible[~mdp.terminal].sum())
    pairs = {FLAT: flat_pairs}
    for name, (options, models, prims) in built.items():
        _, layer = option_set(mdp, options, include_primitives=prims, models=models)
        pairs[f"SMDP Q, {name}"] = int(layer.admissible[~mdp.terminal].sum())
    init_sizes = {name: [int(o.initiation.sum()) for o in options]
                  for name, (options, _, _) in built.items()}
    v_star = solve(mdp).V
    mu0 = mdp.initial
    start = np.flatnonzero(mu0 > 0)
    goal_basin = {
        name: int(next(o for o in options if o.subgoal == int(goal[0])).initiation.sum())
        for name, (options, _, prims) in built.items() if not prims
    }
    start_in_goal_basin = {
        name: bool(next(o for o in options if o.subgoal == int(goal[0])).initiation[start].all())
        for name, (options, _, prims) in built.items() if not prims
    }
    v_opt = {}
    for name, (options, models, prims) in built.items():
        _, smdp = option_set(mdp, options, include_primitives=prims, models=models)
        v_opt[name] = float(solve(smdp).V @ mu0)

    common = {"runs": s["runs"], "episodes": s["episodes"], "seed": config.seed,
              "eval_every": s["eval_every"], "max_steps_per_episode": s["horizon"],
              "alpha": ALPHA, "epsilon": EPSILON, "reference_values": v_star}
    config.progress(f"learning {NEW_TASK}: flat ({s['runs']} runs x {s['episodes']} episodes)")
    with learning_progress(Run(**common), FLAT) as run:
        results: dict[str, Any] = {FLAT: q_learning(mdp, run)}
    for name, (options, models, prims) in built.items():
        config.progress(f"learning {NEW_TASK}: SMDP Q over {name}")
        with learning_progress(Run(**common), f"SMDP Q, {name}") as run:
            results[f"SMDP Q, {name}"] = smdp_q_learning(
                mdp, options, SMDPQSettings(include_primitives=prims), run, models)
    curves = {k: r.curve for k, r in results.items()}
    v_start = float(results[FLAT].v_star_start)
    never = -1.0 / (1.0 - mdp.gamma)  # the value of a policy that never reaches the goal
    threshold = 0.1 * (v_start - never)
    reached = {k: _reached(c, threshold, s["episodes"]) for k, c in curves.items()}

    report.figures.append(str(plot_curves(
        curves, out / "value_gap.png", "value_gap", band="sd",
        title=f"{ENV} / {NEW_TASK}: value gap of the greedy policy (Figs. 5.2, 5.4)")))
    report.figures.append(str(plot_curves(
        curves, out / "steps.png", "steps", band="sd",
        title=f"{ENV} / {NEW_TASK}: primitive steps per episode")))
    evaluated = curves[FLAT].evaluated_episodes()
    curve_json = {
        "episodes": evaluated.tolist(),
        "mean_value_gap": {k: np.nanmean(c.matrix("value_gap")[:, evaluated - 1], axis=0).tolist()
                           for k, c in curves.items()},
        "mean_steps": {k: c.matrix("steps").mean(axis=0).tolist() for k, c in curves.items()},
    }
    (out / "curves.json").write_text(json.dumps(curve_json))

    comparisons = []
    for name in built:
        comp = compare(reached[f"SMDP Q, {name}"], reached[FLAT], f"SMDP Q, {name}", FLAT,
                       seed=config.seed)
        comparisons.append(comp)
    for a, b in (("discovered + primitives", "hand-designed + primitives"),
                 ("discovered + goal option", "hand-designed + goal option")):
        comparisons.append(compare(reached[f"SMDP Q, {a}"], reached[f"SMDP Q, {b}"],
                                   f"SMDP Q, {a}", f"SMDP Q, {b}", seed=config.seed))
    censored = {k: int(np.sum(v > s["episodes"])) for k, v in reached.items()}
    report.data = {
        "settings": {**s, "env": ENV, "source_task": SOURCE_TASK, "new_task": NEW_TASK,
                     "alpha": ALPHA, "epsilon": EPSILON, "q_init": 0.0, "seed": config.seed,
                     "source_policy": "optimal (value iteration)",
                     "detector": "count-exhaustive", "p": 0.025, "initiation": "local",
                     "radius": RADIUS},
        "subgoals": {"discovered": discovered.tolist(), "hand_designed": int(hubs.size),
                     "goal": goal.tolist(), "mu": found.threshold,
                     "ratio_mean": found.stats["ratio_mean"], "ratio_sd": found.stats["ratio_sd"]},
        "options": {name: len(o) for name, (o, _, _) in built.items()},
        "goal_option_initiation_size": goal_basin,
        "start_in_goal_option_basin": start_in_goal_basin,
        "state_action_pairs": pairs,
        "v_star_start": v_start,
        "v_options_start": v_opt,
        "threshold": threshold,
        "episodes_to_threshold": {k: v.tolist() for k, v in reached.items()},
        "censored": censored,
        "final_value_gap": {k: float(np.nanmean(c.matrix("value_gap")[:, -1]))
                            for k, c in curves.items()},
        "comparisons": [c.to_dict() for c in comparisons],
        "curves_file": "curves.json",
    }
    report.findings = [
        (f"{SOURCE_TASK}'s optimal policy: ratio mean {found.stats['ratio_mean']:.2f}, sd "
         f"{found.stats['ratio_sd']:.2f}, mu {found.threshold:.1f} (seed: 5.427, 18.09, 35); "
         f"{discovered.size} discovered subgoals vs {hubs.size} hand-designed doorway/stair "
         f"cells; options: " + ", ".join(f"{k} {len(o)}" for k, (o, _, _) in built.items())
         + f" (+ {mdp.n_actions} primitives where marked); local initiation sets of radius "
         f"{RADIUS} steps (the goal option: every state that can reach the goal), "
         "sizes " + ", ".join(
             f"{k} {min(sizes)}-{max(sizes)}" for k, sizes in init_sizes.items()) + "."),
        (f"every option set can express the optimum: V*(start) = {v_start:.3f}, the SMDPs' "
         "optimal start values " + ", ".join(f"{k} {v:.3f}" for k, v in v_opt.items()) + "."),
        (f"learning {NEW_TASK}: {s['runs']} runs x {s['episodes']} episodes (step cap "
         f"{s['horizon']}, alpha {ALPHA:g}, epsilon {EPSILON:g}); threshold = value gap <= "
         f"{threshold:.3g} (10% of the gap of never reaching the goal); mean episodes to "
         "threshold " + ", ".join(f"{k} {np.mean(v):.0f}" for k, v in reached.items())
         + " (seed: about 300 SMDP, 500 flat); runs never reaching it (counted as episodes + 1): "
         + ", ".join(f"{k} {n}" for k, n in censored.items()) + "."),
    ]
    report.findings.append(
        "state-action (state-option) pairs the learner may try, each optimistic (Q = 0 against "
        "-1 a step) until tried: " + ", ".join(f"{k} {v:,}" for k, v in pairs.items()) + "."
    )
    report.findings.append(
        "the goal option's initiation set (every state that can reach the goal): "
        + ", ".join(f"{k} {goal_basin[k]} states, start "
                    + ("inside" if start_in_goal_basin[k] else "outside") for k in goal_basin)
        + "."
    )
    report.findings += [c.sentence("episodes to threshold") for c in comparisons]
    return report

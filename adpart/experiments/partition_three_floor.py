"""``adpart experiment partition-three-floor``: Figs. 5.3 and 5.5, sections 5.1.1-5.1.3.

``three-floor`` is partitioned by the multi-phase construction (section 4.2.1.2, delta = 0.3,
epsilon = 10 as in the seed) over two option sets, and a *new* task is learned on the flat MDP, on
the SMDP of the options, and on the partition space:

* **hand-designed** subgoals: every doorway and stair cell (Fig. 5.1;
  :func:`adpart.options.handmade.doorway_options` uses the same cells);
* **discovered** subgoals: the count-metric detector (:func:`adpart.subgoals.discover_exhaustive`,
  section 4.1.1) run on the optimal policy of the source task ``reach-goal``.

Subgoals are reward-independent and carry over to the new task ``reach-top-west``; the options
*to* them are built on the new task's MDP (basin initiation sets), and - as section 4.3.1 adds
"states with a high reward" as subgoals - the new task's goal is one more subgoal of both sets
(without it no option could ever enter the goal, and no learner on the options could reach it).
Every phase is stored in the knowledge base (:mod:`adpart.workflows.partitioning`).

**epsilon.** Our tasks pay -1 per move and +100 on arrival (gamma = 0.99), the seed's scale. Every
phase runs on the new task's model (its goal one absorbing block), and phase 3 compares the
options' discounted rewards *beyond the step cost*, ``R(s, o) + (1 - sum F(.|s, o)) / (1 - gamma)``
(:mod:`adpart.partition.layer`): the step cost's share is the option's duration, which eq. 4.6
already bounds through ``F``. epsilon = 10 then lets a block hold states whose discounted goal
reward differs by up to 10; compared on ``R(s, o)`` itself it would cut blocks into bands of about
ten moves of path length.

**Learning.** Q-learning on the flat MDP, SMDP Q-learning over the options
(:func:`adpart.learning.smdp_q.smdp_q_learning`) and the hierarchical learner on the stored
partition (:func:`adpart.learning.hierarchical.hierarchical_learning`, inconsistency mode), all
with the same seed, episodes and step cap; the greedy policy is scored exactly every few episodes.
Episodes to threshold (the value gap staying below 10% of the gap of a policy that never reaches
the goal) are compared pairwise with :func:`adpart.experiments.stats.compare`; runs that never get
there count as ``episodes + 1`` (censored, said in the findings).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from adpart.experiments.base import ExperimentConfig, ExperimentReport, experiment
from adpart.experiments.stats import compare, episodes_to_threshold
from adpart.partition.settings import PartitionSettings
from adpart.workflows.progress import learning_progress

if TYPE_CHECKING:
    from adpart.workflows.store import KnowledgeStore

ENV = "three-floor"
SOURCE_TASK = "reach-goal"
NEW_TASK = "reach-top-west"
#: The partition's settings: the package's defaults (delta 0.3, epsilon 10, section 5.1.2).
PARTITION = PartitionSettings()
DELTA, EPSILON = PARTITION.delta, PARTITION.reward_epsilon


def _settings(config: ExperimentConfig) -> dict[str, int]:
    if config.quick:
        return {"runs": min(config.runs, 2), "episodes": 40, "eval_every": 10, "horizon": 2000}
    return {"runs": config.runs, "episodes": 1500, "eval_every": 10, "horizon": 5000}


def _store_options(kb: KnowledgeStore, env: Any, task_rec: Any, mdp: Any, states: np.ndarray,
                   label: str) -> tuple[list[Any], list[Any], list[Any]]:
    """Options to ``states`` on ``mdp`` with exact models, stored (one record per option)."""
    from adpart.options.models import option_models
    from adpart.options.subgoal_options import subgoal_options
    from adpart.workflows.options import store_options

    mask = np.zeros(mdp.n_states, dtype=bool)
    mask[states] = True
    options = subgoal_options(mdp, mask, initiation="basin")
    models = option_models(mdp, options, duration=False)
    records = store_options(
        kb, env, mdp, options, models, plugin="adpart.experiments",
        name=lambda o: f"{label}:{o.name}",
        parameters=lambda o: {"task_id": task_rec.id, "subgoal_state": int(o.subgoal),
                              "initiation": "basin", "set": label})
    return records, options, models


def _to_threshold(curve: Any, threshold: float, episodes: int) -> np.ndarray:
    gaps = curve.matrix("value_gap")
    evaluated = np.flatnonzero(~np.isnan(gaps[0])) + 1
    reached = episodes_to_threshold(gaps, evaluated, threshold)
    return np.where(np.isfinite(reached), reached, episodes + 1.0)


def _plot_curves(curves: dict[str, Any], column: str, path: Path, ylabel: str, title: str
                 ) -> str:
    from adpart.plotting import new_figure

    fig, ax = new_figure((7, 4.2))
    for name, curve in curves.items():
        m = curve.matrix(column)
        x = np.arange(1, m.shape[1] + 1)
        keep = ~np.isnan(m[0])
        mean = np.nanmean(m[:, keep], axis=0) if m.shape[0] > 1 else m[0, keep]
        ax.plot(x[keep], mean, label=f"{name} (mean of {m.shape[0]} runs)")
    ax.set_xlabel("episode")
    ax.set_ylabel(ylabel)
    if column == "steps":
        ax.set_yscale("log")
    ax.set_title(title)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return str(path)


def _learn(mdp: Any, options: list[Any], models: list[Any], partition: Any, s: dict[str, int],
           seed: int, which: tuple[str, ...]) -> dict[str, Any]:
    from adpart.learning.hierarchical import hierarchical_learning
    from adpart.learning.hierarchical_settings import HierarchicalSettings, Refinement
    from adpart.learning.qlearning import q_learning
    from adpart.learning.settings import Run
    from adpart.learning.smdp_q import smdp_q_learning

    common = {"runs": s["runs"], "episodes": s["episodes"], "seed": seed,
              "eval_every": s["eval_every"], "max_steps_per_episode": s["horizon"]}
    out: dict[str, Any] = {}
    if "flat" in which:
        with learning_progress(Run(**common), "flat Q-learning") as run:
            out["flat Q-learning"] = q_learning(mdp, run)
    if "smdp" in which:
        with learning_progress(Run(**common), "SMDP Q (options)") as run:
            out["SMDP Q (options)"] = smdp_q_learning(mdp, options, None, run, models)
    if "hier" in which:
        with learning_progress(Run(**common), "partition space") as run:
            out["partition space"] = hierarchical_learning(
                mdp, options, partition,
                HierarchicalSettings(refinement=Refinement(delta=DELTA,
                                                           partition_epsilon=EPSILON)),
                run, models)
    return out


@experiment(
    "partition-three-floor",
    "Multi-phase partitioning of three-floor and learning a new task on the partition space",
    "Figs. 5.3, 5.5; sections 5.1.1-5.1.3",
)
def partition_three_floor(config: ExperimentConfig) -> ExperimentReport:
    """Partition three-floor over hand-designed and discovered subgoal options; learn a new task."""
    from adpart.mdp.solvers import solve
    from adpart.subgoals import discover_exhaustive
    from adpart.workflows.partitioning import (
        environment_record,
        partition_environment,
        plot_partition,
        task_record,
    )
    from adpart.workflows.working_kb import working_kb

    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    s = _settings(config)
    report = ExperimentReport("partition-three-floor", "Partitioning three-floor (Figs. 5.3, 5.5)")
    report.seed_reports = [
        ("Fig. 5.3: three-floor's 2,900 states partitioned with subgoal options (delta = 0.3, "
         "epsilon = 10) into about 63 blocks."),
        ("Fig. 5.5: a new task learned on the partition space converges in about 30 iterations, "
         "against about 300 on the SMDP of the options and about 500 on the flat MDP."),
    ]
    with working_kb(config.kb, "partition-three-floor") as kb:
        domain, env = environment_record(kb, ENV)
        _, source_mdp, _ = task_record(kb, domain, env, SOURCE_TASK)
        _, mdp, task_rec = task_record(kb, domain, env, NEW_TASK)
        feats = mdp.features
        hubs = np.zeros(mdp.n_states, dtype=bool)
        for key in ("doorway", "door", "stair"):
            if key in feats:
                hubs |= np.asarray(feats[key]) == 1
        goal = np.flatnonzero(mdp.terminal)
        config.progress("discovering subgoals on the optimal policy of reach-goal")
        policy = solve(source_mdp).policy
        found = discover_exhaustive(source_mdp, policy, np.random.default_rng(config.seed))
        discovered = found.subgoals[~mdp.terminal[found.subgoals]]
        kb.put_subgoal_set(env, "count-exhaustive", found.subgoals, scores=found.scores,
                           plugin="adpart.subgoals", parameters=dict(found.params))
        sets = {"hand-designed": np.r_[np.flatnonzero(hubs), goal],
                "discovered": np.r_[discovered, goal]}
        parts: dict[str, Any] = {}
        learned_on: dict[str, tuple[list[Any], list[Any]]] = {}
        for name, states in sets.items():
            config.progress(f"options and partition: {name}")
            records, options, models = _store_options(kb, env, task_rec, mdp, np.unique(states),
                                                      name)
            outcome = partition_environment(
                kb, ENV, ",".join(r.ref for r in records),
                PARTITION, task=NEW_TASK)
            parts[name] = outcome
            learned_on[name] = (options, models)
            fig = out / f"partition_{name}.png"
            plot_partition(ENV, outcome.final.labels, str(fig),
                           title=f"{ENV}, {name} subgoals: {outcome.final.n_blocks} blocks "
                           f"(delta {DELTA}, epsilon {EPSILON:g})")
            report.figures.append(str(fig))

    report.data["settings"] = {**s, "delta": DELTA, "epsilon": EPSILON, "env": ENV,
                               "source_task": SOURCE_TASK, "new_task": NEW_TASK,
                               "seed": config.seed, "subgoal_detector": "count-exhaustive"}
    report.data["subgoals"] = {"hand-designed": int(hubs.sum()),
                               "discovered": discovered.tolist()}
    report.data["partitions"] = {k: v.summary() for k, v in parts.items()}
    for name, o in parts.items():
        summ = o.summary()
        lay = summ["layer"]["phase3"]
        report.findings.append(
            f"{name} subgoals ({len(sets[name]) - 1} + the new goal = {len(o.phase1)} options): "
            f"{o.n_states} states -> phase 2 {o.phase2.blocks} blocks, phase 3 "
            f"{o.final.n_blocks} blocks = {lay['reachable']} decision blocks + "
            f"{lay['terminal']} terminal + {lay['unreachable']} unreachable (seed: about 63; "
            f"eq. 4.7 on the rewards beyond a step reward of {summ['reward_baseline']:g}); "
            "phase-1 partitions "
            f"{summ['phase1']['computed']} computed / {summ['phase1']['reused']} reused; "
            f"checker {'stable' if o.check.get('ok') else 'NOT stable'}; "
            f"||V* - V*_P|| = {o.gap['measured']:.3g} vs theorem 4.5 bound {o.gap['bound']:.4g}; "
            f"seconds {', '.join(f'{k} {v:.2f}' for k, v in o.seconds.items())}."
        )

    config.progress("learning the new task: flat, SMDP, partition space (hand-designed)")
    hand_opts, hand_models = learned_on["hand-designed"]
    results = _learn(mdp, hand_opts, hand_models, parts["hand-designed"].final, s, config.seed,
                     ("flat", "smdp", "hier"))
    if not config.quick:
        config.progress("learning the new task on the discovered partition")
        disc_opts, disc_models = learned_on["discovered"]
        extra = _learn(mdp, disc_opts, disc_models, parts["discovered"].final, s, config.seed,
                       ("hier",))
        results["partition space (discovered)"] = extra["partition space"]
    curves = {k: r.curve for k, r in results.items()}
    v_star = float(next(iter(results.values())).v_star_start)
    never = -1.0 / (1.0 - mdp.gamma)  # the value of a policy that never reaches the goal
    threshold = 0.1 * (v_star - never)
    reached = {k: _to_threshold(c, threshold, s["episodes"]) for k, c in curves.items()}
    report.data["learning"] = {
        "v_star_start": v_star,
        "threshold": threshold,
        "episodes_to_threshold": {k: v.tolist() for k, v in reached.items()},
        "final_value_gap": {k: float(np.nanmean(c.matrix("value_gap")[:, -1]))
                            for k, c in curves.items()},
        "mean_steps_last_10": {k: float(c.matrix("steps")[:, -10:].mean())
                               for k, c in curves.items()},
    }
    names = list(curves)
    comparisons = []
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            comp = compare(reached[a], reached[b], a, b, seed=config.seed)
            comparisons.append(comp.to_dict())
            report.findings.append(comp.sentence("episodes to threshold"))
    report.data["comparisons"] = comparisons
    censored = {k: int(np.sum(v > s["episodes"])) for k, v in reached.items()}
    report.findings.append(
        f"learning {NEW_TASK}: {s['runs']} runs x {s['episodes']} episodes (step cap "
        f"{s['horizon']}); threshold = value gap <= {threshold:.3g} (10% of the gap of never "
        f"reaching the goal, V*(start) = {v_star:.3g}); mean episodes to threshold "
        + ", ".join(f"{k} {np.mean(v):.0f}" for k, v in reached.items())
        + " (seed: about 30 partition space, 300 SMDP, 500 flat); runs never reaching it "
        "(counted as episodes + 1): " + ", ".join(f"{k} {n}" for k, n in censored.items())
    )
    report.figures.append(_plot_curves(
        curves, "value_gap", out / "value_gap.png", "value gap of the greedy policy at start",
        f"{ENV} / {NEW_TASK}: value gap (Fig. 5.5)"))
    report.figures.append(_plot_curves(
        curves, "steps", out / "steps.png", "primitive steps per episode",
        f"{ENV} / {NEW_TASK}: steps per episode"))
    return report

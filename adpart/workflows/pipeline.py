"""The transfer pipeline of the dissertation (Fig. 4.1, sections 4.1-4.3) as one procedure.

1. learn the first task flat (Q-learning);
2. discover subgoals in its best learned policy (a detector plugin);
3. learn options to the subgoals and their exact multi-time models;
4. partition the state space over the options - phases 1-2 before the next task's reward is
   used, phase 3 once it is - or, with ``hierarchy=NAME``, build the layer for each later task
   with that ``hierarchy-estimator`` plugin from the tasks of the sequence learned before it
   (section 4.4, Algorithm 3; :mod:`adpart.hierarchy`);
5. learn every later task on that decision layer with the hierarchical learner, refining it where
   flat and abstract values disagree (section 4.3.3, the learner's default ``inconsistency``
   mode), and flat without transfer for comparison. The run is linked to the stored layer it
   started on and to the layers its runs ended on (kind ``learned``). ``--hier-opt mode=``
   names another mode: the reward-variation modes (4.3.1) add options to the new task's reward
   states, solved on its true model, and build their own layer from them; their rows say so.

Every row carries what its learner knew (:mod:`adpart.learning.knowledge`): the layer
learner's own knowledge together with its inputs' (option policies solved on the true
dynamics; a layer partitioned on the new task's model and split by its rewards), and beside it
the planner that knows as much (value iteration on the same model: no episodes, its compute
time).

Two outcomes end the abstraction and are reported, not raised: the detector finds **no
subgoals** (stage ``no-subgoals``), and the knowledge base **predicts that abstraction will not
pay** - the ``expected-learning-time`` estimate (section 4.4) of the best layer it can build from
the tasks learned so far (to the bound, in some flat run) is not below that of the flat MDP, or no
earlier task was learned at all (stage ``fallback``; otherwise stage ``predict`` records the
comparison). The later tasks are then learned with the flat learner, and the row of the method
says why (``fallback``). The reward-variation modes (the default) build their layer from each
later task's own reward states, so neither missing subgoals (the layer is then those options
alone) nor an earlier task never learned to the bound (stage ``predict`` says so) ends it.

Every step first looks in the knowledge base for a result of exactly the same request and reuses
it, so a pipeline run again - or resumed after being killed - recomputes nothing it already has.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from adpart.errors import TaskError
from adpart.learning.comparison import best_observed_run, task_row, time_ratio
from adpart.learning.curves import SUCCESS_FRACTION, LearningCurve
from adpart.learning.hierarchical_settings import HierarchicalSettings
from adpart.learning.knowledge import PLANNER, REGIMES, Knowledge
from adpart.learning.settings import Run
from adpart.options.subgoal_options import InitiationSettings
from adpart.partition.settings import PartitionSettings
from adpart.workflows.discovery import discover_subgoals
from adpart.workflows.experience import estimated_environment
from adpart.workflows.hierarchy import Layer, hierarchy_layer
from adpart.workflows.learning import (
    LearnRequest,
    find_learning,
    load_curve,
    record_learning,
    run_learning,
)
from adpart.workflows.options import options_for_subgoals
from adpart.workflows.partitioning import DEFAULT_CRITERION, partition_environment
from adpart.workflows.pipeline_figures import write_figures
from adpart.workflows.refs import parse_ref
from adpart.workflows.regime import (
    agent_verdict,
    check_regime,
    first_task_judgement,
    layer_params,
    learned_threshold,
    learned_value_ceiling,
)
from adpart.workflows.resolve import resolve_domain
from adpart.workflows.store import KnowledgeStore

#: The run settings' defaults, the pipeline's too (one declaration: :class:`Run`).
_RUN = Run()


@dataclass(frozen=True)
class PipelineConfig:
    """Settings of one pipeline run.

    Attributes:
        env: environment name.
        tasks: the task sequence; the first is learned flat, the others on the decision layer.
        detector, detector_params: the subgoal detector plugin and its parameters.
        initiation: initiation sets of the subgoal options (``local`` with its radius in steps,
            ``basin`` or ``reachable``;
            :class:`~adpart.options.subgoal_options.InitiationSettings`).
        partition: the partition's delta (eq. 4.6) and reward epsilon (eq. 4.7).
        criterion, criterion_params: the ``partition-criterion`` plugin that refines every
            phase, and its parameters (:func:`adpart.workflows.partitioning.build_criterion`).
        runs, episodes, first_episodes: runs per learner, episodes per later task, episodes of
            the first (flat) task.
        seed, eval_every: root seed; exact scoring every this many episodes.
        flat_params, hierarchical_params: learner parameters (as on the command line).
        baseline: also learn each later task flat (no transfer) for the comparison.
        model_baseline: also learn each later task that is learned on a layer with the flat
            model-based learner that knows the layer learner's dynamics and observes the
            rewards (:mod:`adpart.learning.model_based`): ``known-dynamics`` (the true model)
            in the true-model regime, ``estimated-dynamics`` (the same counts) in the
            learned-model regime.
        gap_fraction: a run has "learned" a task once its greedy policy's value gap stays below
            this fraction of ``|V*|`` at the start distribution (reported as episodes-to-bound).
        hierarchy: a ``hierarchy-estimator`` plugin (``expected-learning-time``,
            ``all-subgoals``); when set, each later task starts from the layer that estimator
            builds from the earlier tasks of the sequence instead of the multi-phase partition
            (in the learned-model regime on the estimated model, from the Q tables the earlier
            tasks learned).
        hierarchy_params: that estimator's parameters.
        flat_learner: the learner plugin of the first task, the baseline and the fallback.
        fallback: ask the knowledge base before each later task whether abstraction pays
            (module docstring); False always learns on the layer.
        regime: what the off-line steps read (:data:`REGIMES`): ``learned-model`` builds the
            subgoals, the options and phases 1-2 on the model estimated from the first task's
            runs (:mod:`adpart.workflows.experience`), with no phase 3 from the later task's
            rewards, and calibrates the inconsistency threshold from the first task's learned
            values; ``true-model`` builds them on the true model of each later task (the
            seed's figures).
    """

    env: str
    tasks: tuple[str, ...]
    detector: str = "count-exhaustive"
    detector_params: dict[str, Any] = field(default_factory=dict)
    initiation: InitiationSettings = field(default_factory=InitiationSettings)
    partition: PartitionSettings = field(default_factory=PartitionSettings)
    criterion: str = DEFAULT_CRITERION
    criterion_params: dict[str, Any] = field(default_factory=dict)
    runs: int = _RUN.runs
    episodes: int = _RUN.episodes
    first_episodes: int = 500
    seed: int = _RUN.seed  # type: ignore[assignment]
    eval_every: int = _RUN.eval_every
    flat_params: dict[str, Any] = field(default_factory=dict)
    hierarchical_params: dict[str, Any] = field(default_factory=dict)
    baseline: bool = True
    model_baseline: bool = True
    gap_fraction: float = SUCCESS_FRACTION
    hierarchy: str | None = None
    hierarchy_params: dict[str, Any] = field(default_factory=dict)
    flat_learner: str = "q-learning"
    fallback: bool = True
    regime: str = REGIMES[0]

    def __post_init__(self) -> None:
        if self.regime not in REGIMES:
            raise TaskError(f"--regime {self.regime!r} is not one of {', '.join(REGIMES)}")
        Run(runs=self.runs, episodes=self.episodes, seed=self.seed, eval_every=self.eval_every)
        Run(episodes=self.first_episodes)  # the same checks, before any work
        if len(self.tasks) < 2:
            raise TaskError(
                "a pipeline needs at least two tasks: the first is learned flat, later ones "
                "transfer (e.g. --tasks reach-goal,reach-top-west)"
            )
        if self.hierarchy is not None and not self.baseline:
            raise TaskError(
                "--hierarchy builds each layer from the flat (primitive-action) Q values of the "
                "earlier tasks, which the flat baseline provides; drop --no-baseline"
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


class Learned(NamedTuple):
    """A learn stage's result: the stored ids, the curve, and what the run knew (its knowledge
    record's label)."""

    ids: dict[str, Any]
    curve: LearningCurve
    knowledge: str


def learn_stored(kb: KnowledgeStore, request: LearnRequest) -> tuple[Learned, bool]:
    """``request``'s runs from the knowledge base, learned and recorded first when it holds
    none; and whether they were found there."""
    ids = find_learning(kb, request)
    reused = ids is not None
    if ids is None:
        ids = record_learning(kb, run_learning(request, kb=kb))
    run = kb.get("run", parse_ref(ids["run"], "run"))
    known = run.metrics.get("knowledge")
    return Learned(ids, load_curve(kb, run), Knowledge.from_dict(known).label if known
                   else "not declared by the learner"), reused


def _learn(kb: KnowledgeStore, request: LearnRequest, report: PipelineReport, stage: str
           ) -> Learned:
    start = time.perf_counter()
    learned, reused = learn_stored(kb, request)
    report.stages.append(
        Stage(stage, request.task, learned.ids["run"], reused, time.perf_counter() - start)
    )
    return learned


def _row(task: str, label: str, learned: Learned, fraction: float,
         extra: dict[str, Any]) -> dict[str, Any]:
    """:func:`task_row` of a learn stage with what its run knew (its knowledge record, the
    learner's with its inputs')."""
    return task_row(task, label, learned.curve, fraction,
                    {"knowledge": learned.knowledge, **extra})


#: The stages that compute the layer off-line, before the later task is learned.
OFFLINE_STAGES = ("discover", "options", "predict", "partition", "hierarchy")


def _chain_cost(report: PipelineReport, config: PipelineConfig) -> dict[str, Any]:
    """What the layer cost before the later task began: the first task's episodes and primitive
    steps per run, and this run's seconds in the off-line stages (a reused stage counts its
    look-up only)."""
    first = report.rows[0]
    return {"first_task_episodes": config.first_episodes,
            "first_task_steps_mean": first["steps_total_mean"],
            "offline_seconds": sum(s.seconds for s in report.stages
                                   if s.stage in OFFLINE_STAGES),
            "offline_reused": all(s.reused for s in report.stages
                                  if s.stage in OFFLINE_STAGES and s.stage != "predict")}


def _firing_counts(curve: LearningCurve) -> dict[str, int] | None:
    """The layer runs' firings of the inconsistency test, and how many were real
    inconsistencies against the task's exact Q* (an audit; None for a run stored without it)."""
    fired, real = curve.metadata.get("firings"), curve.metadata.get("real_firings")
    if fired is None or real is None:
        return None
    # None: a run stored before ties (or own steps among them) were counted
    tied, own = curve.metadata.get("tied_firings"), curve.metadata.get("own_step_ties")
    return {"total": int(sum(fired)), "real": int(sum(real)),
            "tied": None if tied is None else int(sum(tied)),
            "own_step": None if own is None else int(sum(own))}


def planner_row(env: str, task: str) -> dict[str, Any]:
    """The learner that knows what a layer learner on the true model knows: value iteration
    on the task's exact model. It needs no episode; its cost is its compute time."""
    from adpart.mdp.solvers import solve
    mdp = resolve_domain(env).mdp(task)
    start = time.perf_counter()
    solve(mdp)
    seconds = time.perf_counter() - start
    return {"task": task, "learner": "planner", "runs": 1, "runs_within_bound": 1,
            "bound": float("nan"),  # no curve: nothing to draw
            "episodes_to_bound_median": 0.0, "final_gap_mean": 0.0, "final_gap_max": 0.0,
            "steps_total_mean": 0.0, "compute_seconds": seconds, "knowledge": PLANNER.label}


# --------------------------------------------------------------------------- hierarchy layers


def _task_layer(kb: KnowledgeStore, config: PipelineConfig, subgoal_ref: str, task: str,
                learned: list[int], option_ids: list[int], report: PipelineReport,
                say: Callable[[str], object], model_env: str | None = None) -> Layer:
    """The layer ``task`` starts from: the multi-phase partition, or with ``config.hierarchy``
    the layer that estimator builds from the tasks ``learned`` before it (stage ``hierarchy``).
    With ``model_env`` (the learned-model regime) either is built on that estimated model,
    without the task: phases 1-2 (no phase 3), or Algorithm 3 over the options and the earlier
    tasks' learned Q tables, each task's MDP that task on the estimate."""
    if model_env is not None and config.hierarchy is None:
        say(f"partitioning {model_env} over the options, phases 1-2 (delta "
            f"{config.partition.delta}, criterion {config.criterion}): {task}'s rewards are "
            "not read")
        return _partition_layer(kb, config, subgoal_ref, None, report, model_env, task)
    if config.hierarchy is None:
        say(f"partitioning for {task} (delta {config.partition.delta}, epsilon "
            f"{config.partition.reward_epsilon}, criterion {config.criterion})")
        return _partition_layer(kb, config, subgoal_ref, task, report)
    say(f"building the {config.hierarchy} layer for {task} from {len(learned)} tasks"
        + (f" on {model_env}: {task}'s model and rewards are not read" if model_env else ""))
    start = time.perf_counter()
    layer = hierarchy_layer(kb, model_env or config.env, config.hierarchy,
                            dict(config.hierarchy_params), list(learned), option_ids,
                            learned_in=config.env if model_env else None)
    report.stages.append(
        Stage("hierarchy", task, layer.ref, layer.reused, time.perf_counter() - start,
              {**layer.detail, "built": layer.built, "final_blocks": layer.blocks})
    )
    return layer


def _partition_layer(kb: KnowledgeStore, config: PipelineConfig, subgoal_ref: str,
                     task: str | None, report: PipelineReport, env: str | None = None,
                     for_task: str | None = None) -> Layer:
    """The multi-phase partition of ``env`` (default: the pipeline's) over the subgoal options,
    for ``task`` (phases 1-3) or for none (phases 1-2); the stage is ``for_task``'s."""
    part = partition_environment(
        kb, env or config.env, subgoal_ref, config.partition, task=task,
        criterion=config.criterion, criterion_params=config.criterion_params,
    )
    summary = part.summary()
    reused = (all(p.reused for p in part.phase1) and part.phase2.reused
              and (part.phase3 is None or part.phase3.reused))
    report.stages.append(
        Stage(
            "partition",
            task or for_task,
            part.final_record.ref,
            reused,
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
    return Layer(part.final_record.ref, int(part.final.n_blocks), part.final_record.ref,
                 [], reused)


def episode_defaults(env: str) -> dict[str, Any]:
    """Learner settings the pipeline uses unless ``--flat-opt``/``--hier-opt`` set them.

    * ``alpha = 1`` when every transition of the environment is deterministic (a full step is
      then the exact Bellman backup of the sampled transition), else the learners' ``1/n^0.8``;
    * ``max-steps = max(1000, 2 |S|)``: the learners' 1,000-step cap is shorter than one sweep of
      a 2,900-state building, and a cut episode teaches little.
    """
    dyn = resolve_domain(env).dynamics()
    deterministic = bool(np.all(np.diff(dyn.P.indptr) <= 1))
    return {"alpha": "1" if deterministic else "1/n^0.8",
            "max-steps": max(1000, 2 * dyn.n_states)}


def learner_defaults(learner: str, defaults: dict[str, Any]) -> dict[str, Any]:
    """The entries of ``defaults`` that the learner plugin ``learner`` declares.

    Raises:
        UnknownNameError: no learner plugin of that name (the message names ``--flat-learner``).
    """
    from adpart.errors import UnknownNameError
    from adpart.plugins import get_registry

    try:
        spec = get_registry().get("learner", learner)
    except UnknownNameError as exc:
        raise UnknownNameError(f"--flat-learner: {exc}") from None
    declared = {p.name for p in spec.params}
    return {k: v for k, v in defaults.items() if k in declared}


def predict_fallback(kb: KnowledgeStore, env: str, task_ids: list[int], params: dict[str, Any]
                     ) -> dict[str, Any]:
    """Whether the knowledge base predicts that abstraction will not pay for the next task.

    Builds (without storing) the ``expected-learning-time`` layer from ``task_ids`` and compares
    its ``E[t_learn]`` with the flat MDP's (:mod:`adpart.hierarchy.estimator`). Returns
    ``{"fallback": bool, "estimate": ..., "flat_estimate": ..., "blocks": ...}``.
    """
    from adpart.workflows.hierarchy import build_hierarchy

    res = build_hierarchy(kb, env, estimator="expected-learning-time", tasks=task_ids,
                          params=params, store=False)
    return {"fallback": bool(res.fallback), "estimate": res.estimate,
            "flat_estimate": res.flat_estimate, "blocks": res.n_blocks}


def _predicted_verdict(kb: KnowledgeStore, config: PipelineConfig, task: str,
                       evidence: list[int], own_layer: bool, mode: str) -> dict[str, Any]:
    """The true-model regime's fallback: section 4.4's estimate from the tasks learned to the
    bound (``evidence``), with the ``reason`` the stage and the row print."""
    params = (dict(config.hierarchy_params) if config.hierarchy == "expected-learning-time"
              else {})
    if evidence:
        verdict = predict_fallback(kb, config.env, list(evidence), params)
        falls = verdict["fallback"]
        return {**verdict, "reason": (
            f"the knowledge base predicts abstraction will {'not pay' if falls else 'pay'} for "
            f"{task}: E[t_learn] {verdict['estimate']:.4g} of the best layer "
            f"({verdict['blocks']} blocks) {'>=' if falls else '<'} "
            f"{verdict['flat_estimate']:.4g} flat")}
    if own_layer:  # the layer is built from the task's own rewards, not from evidence
        return {"fallback": False, "reason": (
            f"no earlier task was learned to the bound in any run, so the knowledge base holds "
            f"no values to predict from; {mode} builds its layer from {task}'s own reward "
            f"states, so {task} is learned on it")}
    return {"fallback": True, "reason": (
        f"no earlier task was learned to the bound in any run, so the knowledge base holds no "
        f"values to predict a layer from: {task} is learned flat")}


def _directed_without_ceiling(params: dict[str, Any]) -> bool:
    """Whether the layer learner's ``params`` ask for R-max exploration without a value
    ceiling (the learned-model regime then gives the first task's)."""
    from adpart.plugins import get_registry

    settings = get_registry().get("learner", "hierarchical").create(params).settings
    return settings.directed and settings.exploration.value_ceiling is None


def _rehearse(kb: KnowledgeStore, config: PipelineConfig, model_env: str, first: str,
              layer: Layer, flat: dict[str, Any], hierarchical: dict[str, Any],
              say: Callable[[str], object]) -> tuple[dict[str, Any], float]:
    """The learned-model regime's second fallback check (:mod:`adpart.workflows.rehearsal`):
    the layer and the flat learner rehearsed on hypothetical goals of the agent's own model;
    the verdict and its seconds."""
    from adpart.workflows.learning import load_decision_layer
    from adpart.workflows.rehearsal import (
        REHEARSAL_EVAL_EVERY,
        REHEARSAL_GOALS,
        REHEARSAL_RUNS,
        rehearse,
    )

    say(f"rehearsing {layer.ref} against flat on {REHEARSAL_GOALS} hypothetical goals of "
        f"{model_env} ({REHEARSAL_RUNS} runs each)")
    start = time.perf_counter()
    inputs = load_decision_layer(kb, config.env, partition=layer.ref)
    inputs.pop("option_ids", None)
    verdict = rehearse(resolve_domain(model_env), first, inputs,  # type: ignore[arg-type]
                       config.flat_learner, flat, hierarchical, episodes=config.episodes,
                       eval_every=max(config.eval_every, REHEARSAL_EVAL_EVERY),
                       seed=config.seed, fraction=config.gap_fraction)
    return verdict, time.perf_counter() - start


def _learned_flat(flat_run: Learned, report: PipelineReport, learned: list[int],
                  evidence: list[int]) -> None:
    """Count a task learned flat in place of its layer among the tasks learned so far (which
    ``--hierarchy`` builds the next layers from), and as evidence when a run reached the bound."""
    tid = parse_ref(flat_run.ids["task"], "task")
    if tid not in learned:
        learned.append(tid)
    if report.rows[-1]["runs_within_bound"] > 0 and tid not in evidence:
        evidence.append(tid)


def check_tasks(env: str, tasks: tuple[str, ...]) -> None:
    """Resolve every task of the sequence before any work is done: an unknown task name or a
    goal that matches no state raises here, naming it, not after the earlier tasks were learned
    and stored."""
    domain = resolve_domain(env)
    for task in tasks:
        domain.task(task)


def run_pipeline(
    kb: KnowledgeStore,
    config: PipelineConfig,
    *,
    out: Path | None = None,
    progress: Callable[[str], object] | None = None,
) -> PipelineReport:
    """Run (or resume) the pipeline for ``config``; figures go to ``out`` when given."""
    check_tasks(config.env, config.tasks)
    check_regime(config)
    say = progress or (lambda message: None)
    report = PipelineReport(config)
    first, *later = config.tasks
    defaults = episode_defaults(config.env)
    flat = {**learner_defaults(config.flat_learner, defaults), **config.flat_params}
    # a firing refines its block with the thresholds the layer was built with (eqs. 4.6-4.7)
    hierarchical = {**defaults, "delta": config.partition.delta,
                    "partition-epsilon": config.partition.reward_epsilon,
                    **layer_params(config)}
    hierarchical.setdefault("mode", HierarchicalSettings().mode)  # the seed's: inconsistency
    from adpart.learning.hierarchical import REWARD_OPTION_MODES

    # without --hierarchy, the reward-variation modes build their layer from the options plus the
    # task's reward states; on a --hierarchy layer they offer those options in its blocks
    own_layer = hierarchical["mode"] in REWARD_OPTION_MODES and not config.hierarchy

    def learn_flat(task: str, episodes: int, stage: str = "learn-flat") -> Learned:
        req = LearnRequest(env=config.env, task=task, learner=config.flat_learner,
                           params=dict(flat), runs=config.runs, episodes=episodes,
                           seed=config.seed, eval_every=config.eval_every)
        return _learn(kb, req, report, stage)

    def learn_instead(task: str, reason: str, label: str) -> Learned:
        """``task`` learned flat in place of the layer (its row says why), and as the baseline."""
        flat_run = learn_flat(task, config.episodes)
        report.curves[task] = {label: flat_run.curve}
        report.rows.append(_row(task, "flat-fallback", flat_run, config.gap_fraction,
                                {"fallback": reason}))
        if config.baseline:
            if label == "flat (fallback)":
                report.curves[task]["flat (no transfer)"] = flat_run.curve
            report.rows.append(_row(task, "flat", flat_run, config.gap_fraction, {}))
        return flat_run

    say(f"learning {first} flat ({config.runs} runs x {config.first_episodes} episodes)")
    first_req = LearnRequest(
        env=config.env,
        task=first,
        learner=config.flat_learner,
        params=flat,
        runs=config.runs,
        episodes=config.first_episodes,
        seed=config.seed,
        eval_every=config.eval_every,
    )
    first_learned = _learn(kb, first_req, report, "learn-flat")
    first_ids, first_curve = first_learned.ids, first_learned.curve
    report.curves[first] = {"flat": first_curve}
    report.rows.append(_row(first, "flat", first_learned, config.gap_fraction, {}))

    best = best_observed_run(first_curve)  # by its returns: V* is for scoring only
    policy = kb.get("policy", parse_ref(first_ids["policies"][best], "policy"))
    model_env = None
    if config.regime == "learned-model":
        start = time.perf_counter()
        model_env = estimated_environment(kb, config.env, [first_ids["run"]])
        known = resolve_domain(model_env).experience.summary()
        say(f"estimating the dynamics from {first_ids['run']}'s experience: {known['steps']} "
            f"steps, {known['pairs_tried']} of {known['pairs']} state-action pairs tried")
        report.stages.append(Stage("estimate", first, model_env, False,
                                   time.perf_counter() - start, known))
        start = time.perf_counter()
        judged = first_task_judgement(
            kb, [kb.get("policy", parse_ref(ref, "policy")) for ref in first_ids["policies"]],
            model_env, first, config.gap_fraction, best)
        say(judged["reason"])
        report.stages.append(Stage("judge", first, f"{judged['learned_runs']}/{judged['runs']}",
                                   False, time.perf_counter() - start, judged))
        # the inconsistency threshold from the first task's learned values, not from V*
        hierarchical.setdefault("threshold", learned_threshold(kb, policy, config.env, first))
    say(f"discovering subgoals in {policy.ref} with {config.detector}"
        + (f" on {model_env}" if model_env else ""))
    found = discover_subgoals(
        kb, policy, detector=config.detector, params=config.detector_params, seed=config.seed,
        environment=model_env,
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
    no_subgoals = found.result.subgoals.size == 0
    if no_subgoals and not own_layer:
        reason = (f"{config.detector} found no subgoals in {policy.ref}: no options to build a "
                  "layer from, so the later tasks are learned flat")
        say(reason)
        report.stages.append(Stage("no-subgoals", first, found.record.ref, found.reused, 0.0,
                                   {"reason": reason}))
        for task in later:
            learn_instead(task, reason, "flat (no subgoals)")
        write_figures(kb, report, config, out)
        return report
    option_ids: list[int] = []
    layer_options = found.record.ref  # the subgoal set's options (all of them, unless dropped)
    if no_subgoals:
        reason = (f"{config.detector} found no subgoals in {policy.ref}: each later task is "
                  f"learned on the layer of its reward-state options alone "
                  f"({hierarchical['mode']})")
        say(reason)
        report.stages.append(Stage("no-subgoals", first, found.record.ref, found.reused, 0.0,
                                   {"reason": reason}))
    else:
        say(f"learning options to {found.result.subgoals.size} subgoals")
        start = time.perf_counter()
        stored = options_for_subgoals(kb, found.record, config.initiation)
        report.stages.append(
            Stage(
                "options",
                None,
                ",".join(r.ref for r in stored.records),
                stored.reused,
                time.perf_counter() - start,
                {"dropped": [{"subgoal": s, "reason": why} for s, why in stored.dropped]}
                if stored.dropped else {},
            )
        )
        for subgoal, why in stored.dropped:
            say(f"subgoal {subgoal} dropped: {why}")
        option_ids = [r.id for r in stored.records]
        if stored.dropped:  # the layer is over the options that exist, not the whole set
            layer_options = ",".join(f"option:{i}" for i in option_ids)

    learned = [parse_ref(first_ids["task"], "task")]
    rehearsed: dict[str, tuple[dict[str, Any], float]] = {}
    # tasks learned to the bound in some flat run: the estimator's evidence (section 4.4 builds
    # on learned tasks T_i = (pi_i, P_i, Q_i); an unlearned task's Q predicts nothing)
    evidence = list(learned) if report.rows[0]["runs_within_bound"] > 0 else []
    for task in later:
        if config.fallback:
            start = time.perf_counter()
            verdict = (agent_verdict(first_curve, first, task) if model_env is not None else
                       _predicted_verdict(kb, config, task, evidence, own_layer,
                                          hierarchical["mode"]))
            falls = bool(verdict["fallback"])
            report.stages.append(Stage("fallback" if falls else "predict", task,
                                       "flat" if falls else "layer", False,
                                       time.perf_counter() - start, verdict))
            if falls:
                say(verdict["reason"])
                _learned_flat(learn_instead(task, verdict["reason"], "flat (fallback)"),
                              report, learned, evidence)
                continue
        # own_layer without subgoals learns on the layer of the reward-state options alone
        layer = None if no_subgoals else _task_layer(kb, config, layer_options, task, learned,
                                                     option_ids, report, say, model_env)
        if config.fallback and model_env is not None and layer is not None:
            if layer.ref not in rehearsed:  # one rehearsal per layer: it reads no later task
                rehearsed[layer.ref] = _rehearse(kb, config, model_env, first, layer, flat,
                                                 hierarchical, say)
            verdict, seconds = rehearsed[layer.ref]
            report.stages.append(Stage("rehearse", task, "flat" if verdict["fallback"] else
                                       "layer", False, seconds, verdict))
            if verdict["fallback"]:
                say(verdict["reason"])
                _learned_flat(learn_instead(task, verdict["reason"], "flat (fallback)"),
                              report, learned, evidence)
                continue
        say(f"learning {task} on the layer of the options and {task}'s reward states "
            f"({hierarchical['mode']})" if own_layer or layer is None else
            f"learning {task} on {layer.blocks} blocks (hierarchical)")
        params = dict(hierarchical)
        if model_env is not None and _directed_without_ceiling(params):
            params["value-ceiling"] = learned_value_ceiling(model_env, first, task,
                                                            int(hierarchical["max-steps"]))
        hier_req = LearnRequest(
            env=config.env,
            task=task,
            learner="hierarchical",
            params=params,
            runs=config.runs,
            episodes=config.episodes,
            seed=config.seed,
            eval_every=config.eval_every,
            partition=None if own_layer or layer is None else layer.ref,
            options=(",".join(f"option:{i}" for i in option_ids) or None) if own_layer else None,
            model=model_env,
        )
        hier_run = _learn(kb, hier_req, report, "learn-hierarchical")
        hier_curve = hier_run.curve
        start_blocks = int(hier_curve.metadata["initial_blocks"])
        if own_layer or layer is None:
            label = f"hierarchical, {hierarchical['mode']} ({start_blocks} blocks)"
        else:  # the blocks it started from: the layer's, split where offered reward options
            label = f"hierarchical on the {config.hierarchy or 'partition'} ({start_blocks} blocks)"
        after = hier_curve.metadata.get("final_blocks")
        if after:
            label = label.replace(" blocks)", f" blocks before refinement, median "
                                              f"{int(np.median(after))} after)")
        report.curves[task] = {label: hier_curve}
        report.rows.append(
            _row(
                task,
                "hierarchical",
                hier_run,
                config.gap_fraction,
                {"initial_blocks": start_blocks,
                 "firings": _firing_counts(hier_curve),
                 "partition": None if own_layer or layer is None else layer.ref,
                 "partition_blocks": None if own_layer or layer is None else layer.blocks,
                 "mode": hierarchical["mode"],
                 "chain_cost": _chain_cost(report, config)},
            )
        )
        task_id = parse_ref(hier_run.ids["task"], "task")
        hier_row = len(report.rows) - 1
        if config.baseline:
            say(f"learning {task} flat for comparison")
            base = learn_flat(task, config.episodes)
            report.curves[task]["flat (no transfer)"] = base.curve
            report.rows[hier_row]["ratio_to_flat"] = time_ratio(hier_curve, base.curve,
                                                                config.gap_fraction, config.seed)
            report.rows.append(_row(task, "flat", base, config.gap_fraction, {}))
            if report.rows[-1]["runs_within_bound"] > 0 and task_id not in evidence:
                evidence.append(task_id)
        if config.model_baseline:  # the flat learner that knows the layer learner's dynamics
            based = "known-dynamics" if model_env is None else "estimated-dynamics"
            knows = ("the true dynamics" if model_env is None
                     else f"the counts of {first_ids['run']}")
            say(f"learning {task} with {knows} ({based}) for comparison")
            model_req = LearnRequest(
                env=config.env, task=task, learner=based,
                params=learner_defaults(based, defaults), runs=config.runs,
                episodes=config.episodes, seed=config.seed, eval_every=config.eval_every,
                model=model_env)
            model = _learn(kb, model_req, report, f"learn-{based}")
            report.curves[task][f"{based} (flat, model-based)"] = model.curve
            report.rows[hier_row]["model_based"] = based
            report.rows[hier_row]["ratio_to_model_based"] = time_ratio(
                hier_curve, model.curve, config.gap_fraction, config.seed)
            report.rows.append(_row(task, based, model, config.gap_fraction, {}))
        report.rows.append(planner_row(config.env, task))
        if task_id not in learned:
            learned.append(task_id)
    write_figures(kb, report, config, out)
    return report

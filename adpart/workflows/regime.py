"""What the pipeline's learned-model regime decides from the agent's own experience.

In ``--regime learned-model`` (:mod:`adpart.workflows.experience`, docs/learned-model.md) nothing
of a later task is read before it is learned, so three of the pipeline's decisions are taken from
what the first task's runs gave the agent instead:

* :func:`learned_threshold` - the inconsistency test's ``L``, from the first task's learned
  values (the learner's own default reads ``|V*(start)|`` of the task it learns);
* :func:`agent_verdict` - whether to learn a later task on the layer at all: not if no episode
  of the first task ever ended in a terminal state;
* :func:`first_task_judgement` - whether the first task was learned, by the agent's own
  evaluation: each run's greedy policy against the optimum of the model it estimated, with the
  rewards it observed (reported; the rehearsal, not this, decides the fallback);
* :func:`check_regime` - which settings cannot run without the task's model or rewards, refused
  before any work.

It also holds the regime's one default of the layer learner, :data:`LEARNED_EXPLORATION`
(:func:`layer_params`): R-max on the layer, whose unknown pairs are worth the ceiling of the
rewards the first task paid (:func:`learned_value_ceiling`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from adpart.errors import TaskError
from adpart.learning.curves import LearningCurve
from adpart.workflows.resolve import resolve_domain
from adpart.workflows.store import KnowledgeStore

if TYPE_CHECKING:
    from adpart.workflows.pipeline import PipelineConfig

__all__ = ["LEARNED_EXPLORATION", "THRESHOLD_SCALE", "agent_verdict", "check_regime",
           "first_task_judgement", "layer_params", "learned_threshold", "learned_value_ceiling"]


#: The inconsistency threshold as a fraction of the first task's learned start value (the
#: hierarchical learner's own default fraction of |V*(start)|, on values the agent learned).
THRESHOLD_SCALE = 0.025

#: The layer learner's exploration in the learned-model regime unless ``--hier-opt explore=``
#: names another: R-max on the run's own counts (docs/learned-model.md: on three-floor's 20
#: random goals the layer's interquartile mean is 0.24 of flat Q-learning's time with it,
#: infinite with the optimistic flat action, whose runs stall a few steps off optimal).
LEARNED_EXPLORATION = "r-max"


def layer_params(config: PipelineConfig) -> dict[str, Any]:
    """The layer learner's parameters in ``config``'s regime: the user's ``--hier-opt``
    entries over the regime's default exploration (:data:`LEARNED_EXPLORATION` in the
    learned-model regime; the learner's own default in the true-model regime)."""
    params = dict(config.hierarchical_params)
    if config.regime == "learned-model":
        params.setdefault("explore", LEARNED_EXPLORATION)
    return params


def learned_threshold(kb: KnowledgeStore, policy: Any, env: str, task: str) -> float:
    """``L = THRESHOLD_SCALE * |sum_s mu(s) max_a Q_1(s, a)|``: the scale of the values the
    agent learned in the first task (``policy``'s stored Q), where the learner's default reads
    ``|V*(start)|`` of the task it learns."""
    q = np.asarray(kb.load(policy, "q"), dtype=np.float64)
    best = np.nanmax(np.where(np.isnan(q), -np.inf, q), axis=1)
    mu = resolve_domain(env).task(task).initial  # where episodes start: observed in every run
    live = np.isfinite(best) & (mu > 0)
    value = float(mu[live] @ best[live] / mu[live].sum()) if live.any() else 0.0
    return THRESHOLD_SCALE * abs(value)


def learned_value_ceiling(model_env: str, first: str, task: str, horizon: int) -> float:
    """R-max's ``v_max`` for ``task`` from what the first task paid, on the model its runs
    estimated: where every positive reward of a tried pair came with a chance of ending the
    episode (a goal paid on arrival), the largest reward per unit of that chance
    (:func:`adpart.learning._rmax.episodic_ceiling`: a goal's reward is collected once);
    otherwise ``max(r, 0) / (1 - gamma)`` over the rewards of the tried pairs, with ``task``'s
    discount (its interface), or ``max(r, 0) * horizon`` where ``task`` is undiscounted. The
    later task is assumed to pay as the first did (the same kind of goal). The true-model
    regime's default reads the ceiling of ``task``'s own rewards instead."""
    from adpart.learning.hierarchical import episodic_ceiling

    domain = resolve_domain(model_env)
    earlier = domain.mdp(first)  # the estimated dynamics, the first task's rewards
    tried = domain.experience.tried & earlier.admissible  # type: ignore[attr-defined]
    live = tried & ~earlier.terminal[:, None]
    gamma = domain.base.mdp(task).gamma  # type: ignore[attr-defined]
    return episodic_ceiling(earlier, horizon, live, gamma)


def first_task_judgement(kb: KnowledgeStore, policies: list[Any], model_env: str, first: str,
                         fraction: float, chosen: int) -> dict[str, Any]:
    """Whether ``first`` was learned, judged from what the agent knows: the model its runs
    estimated (:mod:`adpart.workflows.experience`) with the rewards they were paid (a pair never
    tried pays the step reward most tried pairs paid), on which each run's greedy policy is
    evaluated exactly and compared with that model's optimum at the start distribution. A run
    has learned the task when its gap is at most ``fraction`` of ``|V-hat*(start)|`` (the
    pipeline's success bound, on the agent's model instead of the world's V*).

    Returns the stage detail: ``learned_runs`` of ``runs``, ``value_hat`` (``V-hat*(start)``),
    each run's ``gap_fraction``, whether the run the subgoals come from (``chosen``) learned it,
    and a ``reason`` sentence. The pipeline reports it and does not fall back on it: on
    FrozenLake random_map=8 no run learned its first task by this measure, yet the layer built
    from the best of them reached the moved goal in 0.06 of flat's episodes
    (docs/learned-model.md); the rehearsal decides.
    """
    from adpart.mdp.evaluation import policy_evaluation
    from adpart.mdp.solvers import solve
    from adpart.partition.layer import step_baseline

    domain = resolve_domain(model_env)
    mdp = domain.mdp(first)
    tried = domain.experience.tried & mdp.admissible  # type: ignore[attr-defined]
    step = step_baseline(mdp.R, tried, mdp.terminal, rule="mode")
    belief = mdp.with_rewards(np.where(tried, mdp.R, step))
    # a policy that never ends (gamma = 1) is worth the step reward for the horizon: no goal
    never = step * 1e6 if mdp.gamma >= 1.0 else None
    mu = belief.initial
    best = float(mu @ policy_evaluation(belief, solve(belief).policy, never=never))
    scale = max(abs(best), 1e-12)
    fractions = []
    for policy in policies:
        q = np.asarray(kb.load(policy, "q"), dtype=np.float64)
        greedy = np.argmax(np.where(np.isnan(q), -np.inf, q), axis=1)
        value = float(mu @ policy_evaluation(belief, greedy, never=never))
        fractions.append(max(best - value, 0.0) / scale)
    learned = [f <= fraction for f in fractions]
    said = (f"{sum(learned)} of {len(policies)} runs of {first} learned it by the agent's own "
            f"evaluation (greedy value within {fraction:.0%} of the optimum of the model they "
            f"estimated, {best:.4g} at the start); the subgoals come from run {chosen}, which "
            + ("did" if learned[chosen] else f"did not (gap {fractions[chosen]:.0%})"))
    return {"learned_runs": int(sum(learned)), "runs": len(policies), "value_hat": best,
            "gap_fraction": fractions, "chosen_learned": bool(learned[chosen]),
            "reason": said}


def agent_verdict(first_curve: LearningCurve, first: str, task: str) -> dict[str, Any]:
    """The learned-model regime's fallback, decided from what the agent saw: a first task none
    of whose episodes ever ended in a terminal state (every one ran to the step limit) gave the
    agent no goal, so nothing it learned is evidence for a layer and ``task`` is learned flat.
    (The true-model regime's fallback compares section 4.4's expected-learning-time estimate
    over the tasks its runs learned to the bound, scored against V*; this regime does not use
    it.)"""
    cap = int(first_curve.metadata.get("max_steps_per_episode") or 0)
    steps = np.asarray(first_curve["steps"])
    ended = int(np.count_nonzero(steps < cap)) if cap else int(steps.size)
    if ended == 0:
        return {"fallback": True, "episodes_ending_in_a_terminal": 0,
                "reason": f"no episode of {first} ever ended in a terminal state (each ran to "
                          f"the {cap}-step limit): the agent found no goal, so {task} is "
                          "learned flat"}
    return {"fallback": False, "episodes_ending_in_a_terminal": ended,
            "reason": f"{ended} episodes of {first} ended in a terminal state: {task} is learned "
                      "on the layer built from that experience (the true-model regime's "
                      "fallback, 4.4's estimate over tasks scored against V*, is not used "
                      "here)"}


def check_regime(config: PipelineConfig) -> None:
    """Refuse, before any work, a layer learner that could not learn in the config's regime
    (the learned-model regime's learner reads a belief model, not the task's rewards)."""
    if config.regime != "learned-model":
        return
    from adpart.learning.hierarchical import belief_problem
    from adpart.plugins import get_registry

    flat = get_registry().get("learner", config.flat_learner)
    if not getattr(flat.factory, "records_experience", False):
        raise TaskError(
            f"--flat-learner {config.flat_learner} does not record the transitions its runs take "
            "(records_experience), and the learned-model regime estimates the dynamics from "
            "them: give --regime true-model, or a flat learner that records them (q-learning)")
    spec = get_registry().get("learner", "hierarchical")
    params = layer_params(config)
    learner = spec.create(params)
    if learner.settings.directed and learner.settings.exploration.value_ceiling is None:
        # the pipeline gives R-max the ceiling of the first task's rewards (learned_value_ceiling)
        learner = spec.create({**params, "value-ceiling": 0.0})
    problem = belief_problem(learner.settings)
    if problem is not None:
        raise TaskError(f"--hier-opt: {problem}; or give --regime true-model, which reads the "
                        "new task's model")

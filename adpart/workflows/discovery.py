"""Discover subgoals in a stored policy with a detector plugin, and keep them in the KB."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from adpart.errors import TaskError
from adpart.plugins import get_registry
from adpart.subgoals.result import SubgoalResult
from adpart.workflows.options import environment_and_mdp
from adpart.workflows.partitioning import environment_record
from adpart.workflows.store import KnowledgeStore


@dataclass(frozen=True, eq=False)
class Discovery:
    """A detector's result and the subgoal-set record that keeps it."""

    result: SubgoalResult
    record: Any
    seconds: float
    reused: bool


def discover_subgoals(
    kb: KnowledgeStore,
    policy: Any,
    *,
    detector: str = "count-exhaustive",
    params: dict[str, Any] | None = None,
    seed: int = 0,
    environment: str | None = None,
) -> Discovery:
    """Run ``detector`` on ``policy``'s greedy actions in its task's MDP; store the subgoal set.

    ``environment`` names the model the detector reads instead of the policy's own environment
    (the same states and actions: a model estimated from experience,
    :mod:`adpart.workflows.experience`); the subgoal set is stored under it.

    A subgoal set already stored for the same policy, detector, parameters and seed is returned
    instead of being recomputed (``reused=True``). The record keeps the parameters the detector
    ran with (``detector_params``, with the seed) and the ones its result states (``params``:
    the built-in detectors' settings, :func:`adpart.params.settings_dict`), which a reused
    result states again.
    """
    spec = get_registry().get("subgoal-detector", detector)
    resolved = spec.resolve_params(params or {})
    if "q_columns" in policy.provenance.parameters:
        raise TaskError(
            f"{policy.ref} was learned over options; subgoals are discovered in a policy over "
            "primitive actions (learn the task with a flat learner first)"
        )
    task = kb.get("task", policy.task_id)
    if environment is None:
        env, _, mdp = environment_and_mdp(kb, task.environment_id, task.id)
    else:
        domain, env = environment_record(kb, environment)
        mdp = domain.mdp(task.name)
    wanted = {**resolved, "seed": seed}
    for existing in kb.records("subgoal-set", environment=env):
        prov = existing.provenance.parameters
        if (
            existing.policy_id == policy.id
            and existing.detector == detector
            and prov.get("detector_params") == wanted
        ):
            stored = SubgoalResult(
                subgoals=np.asarray(existing.states, dtype=np.int64),
                scores=kb.load(existing, "scores"),
                threshold=prov.get("threshold"),
                stats=prov.get("stats", {}),
                params=prov.get("params", resolved),
                detector=detector,
            )
            return Discovery(stored, existing, float(prov.get("seconds", 0.0)), reused=True)
    pi = kb.load(policy, "pi")
    start = time.perf_counter()
    detector_obj = spec.create(params or {})
    result = detector_obj.detect(mdp, pi, np.random.default_rng(seed))
    seconds = time.perf_counter() - start
    record = kb.put_subgoal_set(
        env,
        detector,
        result.subgoals,
        scores=result.scores,
        policy=policy,
        plugin_version=spec.version,
        parameters={
            "detector_params": wanted,
            "params": dict(result.params),
            "threshold": result.threshold,
            "stats": dict(result.stats),
            "seconds": round(seconds, 4),
        },
    )
    return Discovery(result, record, seconds, reused=False)

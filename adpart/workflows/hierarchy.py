"""Hierarchy construction over a knowledge base: read learned tasks and options, store the layer.

:func:`load_inputs` turns the tasks learned so far in one environment (their newest stored
policy's Q) and the options stored for it into :class:`~adpart.hierarchy.layers.HierarchyInputs`;
:func:`build_hierarchy` resolves a ``hierarchy-estimator`` plugin, loads the inputs, calls the
plugin on them (a pure function: it never sees the knowledge base) and stores the layer it
returns as a ``hierarchy`` partition whose parents are the partitions the used tasks were learned
on (:func:`store_layer`). :func:`hierarchy_layer` is the get-or-build the pipeline uses: the
layer an estimator built from exactly these tasks' current policies is reused when stored, and a
layer that offers no option is stored again over the pipeline's options, so the learner's
refinement has options to add.

Interpretations (docs/hierarchy.md): a task is learned when it has a stored policy; its newest
policy stands for it.
"""

from __future__ import annotations

import inspect
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from adpart.errors import AdpartError, PluginError, TaskError
from adpart.hierarchy.layers import HierarchyInputs, HierarchyResult
from adpart.hierarchy.settings import EstimateSettings
from adpart.hierarchy.tasks import task_from_model
from adpart.mdp.model import FiniteMDP
from adpart.plugins import get_registry
from adpart.workflows.options import load_options
from adpart.workflows.resolve import resolve_domain
from adpart.workflows.store import KnowledgeStore

# --------------------------------------------------------------------------- reading


def _task_mdp(kb: KnowledgeStore, domain: Any, task: Any, *, same_model: bool = True
              ) -> FiniteMDP:
    """The task's MDP, rebuilt from its name or the request of one of its runs on ``domain``;
    hash-checked when ``same_model`` (the task was recorded on this domain's dynamics; on a
    model the agent estimated, the recorded hash is the true model's and the name decides)."""
    wanted = task.spec.get("model_hash") if same_model else None
    candidates = [task.spec.get("task"), task.name]
    for run in kb.runs_for(task):
        request = run.provenance.parameters.get("request") or {}
        candidates.insert(0, request.get("task"))
    for text in dict.fromkeys(c for c in candidates if isinstance(c, str)):
        try:
            mdp = domain.mdp(text)
        except AdpartError:  # not a task of this domain: try the next candidate
            mdp = None
        if mdp is not None and (wanted is None or mdp.content_hash == wanted):
            return mdp
    raise TaskError(
        f"{task.ref} ({task.name!r}) cannot be rebuilt from the installed environment "
        f"{domain.name!r} (no task of that name with model hash {str(wanted)[:12]}); leave it out "
        "with --tasks"
    )


def _newest_policies(kb: KnowledgeStore, env: Any) -> dict[int, Any]:
    """Per learned task id, the policy that stands for it: its newest stored policy with a Q
    table over the environment's actions (a decision layer's Q over options does not count)."""
    policies: dict[int, Any] = {}
    for pol in kb.records("policy", environment=env):
        if pol.q is not None and not pol.provenance.parameters.get("q_columns"):
            policies[pol.task_id] = pol  # ascending ids: the newest wins
    return policies


def _select_tasks(
    kb: KnowledgeStore, env: Any, tasks: Sequence[str | int] | None
) -> list[tuple[Any, Any]]:
    """``(task record, newest policy)`` of the chosen (default: all learned) tasks."""
    policies = _newest_policies(kb, env)
    records = [t for t in kb.records("task", environment=env) if t.id in policies]
    if tasks is not None:
        chosen = []
        for ref in tasks:
            text = str(ref)
            match = [t for t in records if text in (t.name, t.ref, str(t.id))]
            if not match:
                known = ", ".join(f"{t.ref} ({t.name})" for t in records) or "none"
                raise TaskError(
                    f"no learned task {text!r} in environment {env.name!r}; learned tasks: {known}"
                )
            chosen.extend(m for m in match if m not in chosen)
        records = chosen
    if not records:
        raise TaskError(
            f"environment {env.name!r} has no learned task in the knowledge base; learn one first "
            f"(`adpart learn {env.name} --kb ...`)"
        )
    return [(t, policies[t.id]) for t in records]


def load_inputs(
    kb: KnowledgeStore,
    environment_name: str,
    *,
    tasks: Sequence[str | int] | None = None,
    options: Sequence[int] | None = None,
    weights: Mapping[str, float] | Sequence[float] | None = None,
    estimate: EstimateSettings | None = None,
    learned_in: str | None = None,
) -> HierarchyInputs:
    """Read the learned tasks and candidate options of ``environment_name`` (module docstring).

    Args:
        tasks: task names, ``task:N`` refs or ids (default: every task with a stored policy).
        learned_in: the environment the tasks were learned in, when it is not
            ``environment_name``: the learned-model regime builds the layer on the model the
            agent estimated (``ENV@experience:...``, where its options are) from the Q tables
            the tasks learned in ``ENV``; each task's MDP is that task on the estimate.
        options: option record ids (default: every option stored for the environment).
        weights: importance ``U(T_i)`` by task name/ref, or one per selected task (default 1).
        estimate: the threshold ``L`` of every task (default ``EstimateSettings()``:
            ``threshold_scale`` times each task's value range over its non-terminal states); an
            estimator sets its own
            (:meth:`~adpart.hierarchy.layers.HierarchyInputs.with_threshold`).
    """

    env = kb.find_environment(environment_name)
    domain = resolve_domain(env.name)
    dyn = domain.dynamics()
    if dyn.content_hash != env.model_hash:
        raise TaskError(
            f"environment {env.name!r} in the knowledge base was recorded with other dynamics "
            "than the installed one; use the adpart version that recorded it"
        )
    source = env if learned_in is None else kb.find_environment(learned_in)
    if (source.n_states, source.n_actions) != (env.n_states, env.n_actions):
        raise TaskError(f"the tasks of {source.name!r} ({source.n_states} states, "
                        f"{source.n_actions} actions) cannot be read on {env.name!r} "
                        f"({env.n_states} states, {env.n_actions} actions)")
    chosen = _select_tasks(kb, source, tasks)
    if options is None:
        option_records = kb.options_for(env)
    else:
        option_records = [kb.get("option", int(i)) for i in options]
        for rec in option_records:
            if rec.environment_id != env.id:
                raise TaskError(f"{rec.ref} belongs to another environment than {env.name!r}")
    opts = load_options(kb, option_records)[0] if option_records else []
    if isinstance(weights, Mapping):
        w = [float(weights.get(t.name, weights.get(t.ref, 1.0))) for t, _ in chosen]
    elif weights is not None:
        w = [float(x) for x in weights]
        if len(w) != len(chosen):
            raise TaskError(f"{len(w)} weights given for {len(chosen)} tasks; give one per task")
    else:
        w = [1.0] * len(chosen)
    learned, mdp = [], None
    for (task_rec, policy), wi in zip(chosen, w, strict=True):
        mdp = _task_mdp(kb, domain, task_rec, same_model=source.id == env.id)
        learned.append(task_from_model(mdp, kb.load(policy, "q"), opts, threshold=0.0,
                                       name=task_rec.name, weight=wi))
    task_ids = {t.id for t, _ in chosen}
    parents = {p.id for p in kb.records("partition", environment=env) if p.task_id in task_ids}
    for tid in task_ids:
        parents.update(r.partition_id for r in kb.runs_for(tid) if r.partition_id is not None)
    inputs = HierarchyInputs.from_tasks(
        mdp, learned, opts, environment=env.name, task_ids=[t.id for t, _ in chosen],
        option_ids=[r.id for r in option_records],
        to_subgoal=[r.subgoal_id is not None for r in option_records],
        policy_ids=[p.id for _, p in chosen], parent_ids=sorted(parents),
    )
    estimate = EstimateSettings() if estimate is None else estimate
    return inputs.with_threshold(estimate.threshold, estimate.threshold_scale)


def store_layer(kb: KnowledgeStore, inputs: HierarchyInputs, result: HierarchyResult, *,
                estimator: str) -> HierarchyResult:
    """Store ``result`` (built from ``inputs``) as a ``hierarchy`` partition with its lineage.

    The record's provenance is the estimator's name and parameters, the tasks and the policies
    standing for them, the estimate and the fallback decision; returns ``result`` with its
    ``partition_id``.
    """
    params = {**result.parameters, "tasks": list(result.task_ids),
              "policies": list(inputs.policy_ids), "estimate": result.estimate,
              "steps": len(result.steps), "flat_estimate": result.flat_estimate,
              "fallback": result.fallback}
    rec = kb.put_partition(
        kb.find_environment(inputs.environment), "hierarchy", result.partition.labels,
        options=list(result.option_ids), includes_primitives=True,
        epsilon=0.0, delta=0.0,  # Algorithm 3's layer claims no bound of eqs. 4.6-4.7
        block_actions=result.partition.admissible, parents=inputs.parent_ids, plugin=estimator,
        parameters=params,
    )
    return replace(result, partition_id=rec.id)


def build_hierarchy(
    kb: KnowledgeStore,
    environment_name: str,
    *,
    estimator: str = "expected-learning-time",
    tasks: Sequence[str | int] | None = None,
    params: Mapping[str, Any] | None = None,
    store: bool = True,
    learned_in: str | None = None,
) -> HierarchyResult:
    """Build the decision layer for the next task of ``environment_name`` with an estimator plugin.

    Resolves the plugin, loads its inputs (:func:`load_inputs`), calls
    ``plugin.build(inputs)`` and stores the layer it returns (:func:`store_layer`).

    Args:
        kb: an open knowledge base (:class:`~adpart.workflows.store.KnowledgeStore`).
        estimator: a ``hierarchy-estimator`` plugin (``expected-learning-time``,
            ``all-subgoals`` or a third-party one).
        tasks: learned tasks to use (names, ``task:N`` or ids; default all).
        params: the plugin's parameters (validated against its declaration).
        store: store the layer as a ``hierarchy`` partition.
        learned_in: the environment the tasks were learned in (:func:`load_inputs`).
    """
    spec = get_registry().get("hierarchy-estimator", estimator)
    plugin = spec.create(dict(params or {}))
    try:
        inspect.signature(plugin.build).bind(None)
    except TypeError as exc:
        raise PluginError(
            f"hierarchy estimator {estimator!r} ({spec.package}) has "
            f"build{inspect.signature(plugin.build)}; the contract is build(inputs), a pure "
            "function of the loaded inputs (docs/plugins.md)"
        ) from exc
    t0 = time.perf_counter()
    inputs = load_inputs(kb, environment_name, tasks=tasks, learned_in=learned_in)
    t1 = time.perf_counter()
    result = plugin.build(inputs)
    if not isinstance(result, HierarchyResult):
        raise PluginError(
            f"hierarchy estimator {estimator!r} ({spec.package}) returned a "
            f"{type(result).__name__}, not an adpart.hierarchy.HierarchyResult (build it with "
            "adpart.hierarchy.layer_result)"
        )
    t2 = time.perf_counter()
    if store:
        result = store_layer(kb, inputs, result, estimator=estimator)
    seconds = {"inputs": t1 - t0, **result.seconds, "store": time.perf_counter() - t2}
    return replace(result, seconds=seconds)


# --------------------------------------------------------------------------- reuse


@dataclass(frozen=True)
class Layer:
    """A decision layer the hierarchical learner can start from.

    Attributes:
        ref: the stored partition the learner loads (``partition:N``).
        blocks: its number of blocks.
        built: the partition the estimator stored (``ref`` differs when options were added).
        options: option refs the estimator's layer offers somewhere.
        reused: whether the layer came from the knowledge base.
        detail: the estimator's summary (trace, estimate, tasks) when it was built here.
    """

    ref: str
    blocks: int
    built: str
    options: list[str]
    reused: bool
    detail: dict[str, Any] = field(default_factory=dict)


def _stored_hierarchy(
    kb: KnowledgeStore, env: Any, estimator: str, params: dict[str, Any], task_ids: list[int],
    source: Any = None,
) -> Any:
    """A ``hierarchy`` partition of ``env`` built by ``estimator`` with ``params`` from exactly
    these tasks' current policies (in ``source``, default ``env``), or None - so a pipeline run
    again does not build it again."""
    newest = _newest_policies(kb, env if source is None else source)
    policies = [newest[t].id for t in task_ids if t in newest]
    wanted = {k.replace("-", "_"): v for k, v in params.items()}
    for rec in reversed(kb.records("partition", environment=env)):
        prov = rec.provenance
        if rec.kind != "hierarchy" or prov.plugin != estimator:
            continue
        got = prov.parameters
        if sorted(got.get("tasks", [])) != sorted(task_ids):
            continue
        if sorted(got.get("policies", [])) != sorted(policies):
            continue
        if all(got.get(k) == v for k, v in wanted.items()):
            return rec
    return None


def _with_options(kb: KnowledgeStore, env: Any, rec: Any, option_ids: list[int]
                  ) -> tuple[Any, bool]:
    """``rec`` itself when it offers options; otherwise the same blocks over ``option_ids``.

    The hierarchical learner needs at least one option (its refinement may add any of them,
    section 4.3); a layer that offers only primitive actions is stored again over the
    pipeline's options with every option column off, child of ``rec``. Returns
    ``(record, reused)``.
    """
    if rec.option_ids or not option_ids:
        return rec, True
    for cand in kb.records("partition", environment=env):
        if (cand.kind == "hierarchy" and tuple(cand.parent_ids) == (rec.id,)
                and list(cand.option_ids) == list(option_ids)
                and cand.provenance.plugin == "adpart.workflows.pipeline"):
            return cand, True
    labels = kb.load(rec, "labels")
    adm = kb.load(rec, "block_actions").astype(bool)
    adm = np.concatenate([adm, np.zeros((adm.shape[0], len(option_ids)), dtype=bool)], axis=1)
    padded = kb.put_partition(
        env, "hierarchy", labels, options=list(option_ids), includes_primitives=True,
        epsilon=rec.epsilon, delta=rec.delta,
        block_actions=adm, parents=[rec.id], plugin="adpart.workflows.pipeline",
        parameters={"from": rec.ref, "reason": "options offered in no block, for refinement"},
    )
    return padded, False


def hierarchy_layer(
    kb: KnowledgeStore, env_name: str, estimator: str, params: dict[str, Any], task_ids: list[int],
    option_ids: list[int], learned_in: str | None = None,
) -> Layer:
    """The layer ``estimator`` builds from the learned tasks ``task_ids`` (reused when stored).

    ``option_ids`` are the options the learner may fall back on when the layer offers none
    (:func:`_with_options`); ``learned_in``: the environment the tasks were learned in, when the
    layer is built on a model the agent estimated (:func:`load_inputs`).
    """
    resolved = get_registry().get("hierarchy-estimator", estimator).resolve_params(params)
    env = kb.find_environment(env_name)
    source = None if learned_in is None else kb.find_environment(learned_in)
    rec = _stored_hierarchy(kb, env, estimator, resolved, task_ids, source)
    detail: dict[str, Any] = {}
    reused = rec is not None
    if rec is None:
        result = build_hierarchy(kb, env_name, estimator=estimator, tasks=task_ids,
                                 params=params, learned_in=learned_in)
        rec = kb.get("partition", int(result.partition_id))
        detail = result.summary()
    else:
        got = rec.provenance.parameters
        detail = {"estimator": estimator, "partition": rec.ref, "blocks": rec.n_blocks,
                  "options": [f"option:{i}" for i in rec.option_ids],
                  "tasks": [f"task:{i}" for i in got.get("tasks", [])],
                  "estimate": got.get("estimate"), "steps": got.get("steps")}
    learnable, kept = _with_options(kb, env, rec, option_ids)
    return Layer(learnable.ref, int(rec.n_blocks), rec.ref,
                 [f"option:{i}" for i in rec.option_ids], reused and kept, detail)

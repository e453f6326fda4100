"""Hierarchy construction over a knowledge base: read learned tasks and options, store the layer.

:func:`load_inputs` turns the tasks learned so far in one environment (their newest stored
policy's Q) and the options stored for it into :class:`~adpart.hierarchy.tasks.LearnedTask`
objects over one column set (the primitive actions, then the options). :func:`expected_time_layer`
runs Algorithm 3 on them, :func:`all_subgoals_layer` is the seed's heuristic (every subgoal option
in every block where it is admissible, then the multi-phase partition) and :func:`build_hierarchy`
picks either through the ``hierarchy-estimator`` plugins and stores the result as a ``hierarchy``
partition whose parents are the partitions the used tasks were learned on.

Interpretations (docs/hierarchy.md): a task is learned when it has a stored policy; its newest
policy stands for it; the estimator's threshold ``L`` defaults to ``threshold_scale`` (1%) of the
task's value range; blocks the construction left without any action get the primitive actions
admissible in all their states (the hierarchical learner needs a decision in every block, and
where no learned task goes nothing better is known); only option columns some block offers are
stored with the layer.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from adpart.errors import AdpartError, TaskError
from adpart.hierarchy.estimator import expected_time, flat_time
from adpart.hierarchy.greedy import Step, column_splits, greedy_hierarchy
from adpart.hierarchy.tasks import LearnedTask, task_from_model
from adpart.mdp.model import FiniteMDP
from adpart.options.option import Option
from adpart.partition.partition import Partition, block_all

#: Default estimator threshold L as a fraction of each task's value range (module docstring).
DEFAULT_THRESHOLD_SCALE = 0.01


@dataclass(frozen=True, eq=False)
class HierarchyInputs:
    """Everything read from the knowledge base for one construction.

    Attributes:
        environment: the environment record.
        task_records, policy_records: the tasks used and the policy standing for each.
        tasks: the estimator's inputs, one per task record.
        option_records, options: the candidate options (columns ``A..A+O-1``).
        action_names: names of all ``A + O`` columns.
        admissible: ``(S, A+O)`` where each column may start.
        termination: ``(S, A+O)`` beta = 1 (True for every primitive column).
        mdp: the MDP of the newest task (dynamics shared by all).
        parent_ids: partitions the used tasks were learned on (their runs') or built for.
    """

    environment: Any
    task_records: list[Any]
    policy_records: list[Any]
    tasks: list[LearnedTask]
    option_records: list[Any]
    options: list[Option]
    action_names: list[str]
    admissible: np.ndarray
    termination: np.ndarray
    mdp: FiniteMDP
    parent_ids: list[int]


@dataclass(frozen=True, eq=False)
class HierarchyResult:
    """A decision layer built for the next task.

    Attributes:
        estimator: the plugin name that built it.
        partition: labels and per-block columns, columns = primitive actions then ``option_ids``.
        option_ids: the options the layer uses (record ids), in column order.
        column_names: names of the partition's columns.
        trace: ``E[t_learn]`` per step (Algorithm 3), or one value for a fixed layer.
        estimate: ``E[t_learn]`` of the stored layer (after filling empty blocks).
        steps: Algorithm 3's accepted refinements (empty for ``all-subgoals``).
        task_ids: the learned tasks used.
        partition_id: the stored ``hierarchy`` partition, or None when not stored.
        seconds: ``{"inputs": ..., "construction": ...}``.
        parameters: the estimator's parameters (stored as provenance).
        flat_estimate: ``E[t_learn | flat]`` (the "no abstraction" candidate), None when not
            compared.
        fallback: True when the flat MDP is predicted to learn faster than the layer: the next
            task should be learned flat (the layer is still stored, for the record).
    """

    estimator: str
    partition: Partition
    option_ids: list[int]
    column_names: list[str]
    trace: list[float]
    estimate: float | None
    steps: list[Step]
    task_ids: list[int]
    partition_id: int | None
    seconds: dict[str, float] = field(default_factory=dict)
    parameters: dict[str, Any] = field(default_factory=dict)
    flat_estimate: float | None = None
    fallback: bool = False

    @property
    def n_blocks(self) -> int:
        return self.partition.n_blocks

    def block_columns(self) -> list[list[str]]:
        """The names of the columns offered in each block."""
        names = np.asarray(self.column_names, dtype=object)
        return [list(names[row]) for row in self.partition.admissible]

    def summary(self) -> dict[str, Any]:
        """A JSON-able summary (for ``--json`` and experiment records)."""
        return {
            "estimator": self.estimator,
            "partition": None if self.partition_id is None else f"partition:{self.partition_id}",
            "blocks": self.n_blocks,
            "options": [f"option:{i}" for i in self.option_ids],
            "tasks": [f"task:{i}" for i in self.task_ids],
            "estimate": self.estimate,
            "flat_estimate": self.flat_estimate,
            "fallback": self.fallback,
            "trace": list(self.trace),
            "steps": len(self.steps),
            "seconds": dict(self.seconds),
            "parameters": dict(self.parameters),
        }


# --------------------------------------------------------------------------- reading


def _task_mdp(kb: Any, domain: Any, task: Any) -> FiniteMDP:
    """The task's MDP, rebuilt from its name or the request of one of its runs, hash-checked."""
    wanted = task.spec.get("model_hash")
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


def _select_tasks(kb: Any, env: Any, tasks: Sequence[str | int] | None) -> list[tuple[Any, Any]]:
    """``(task record, newest policy)`` of the chosen (default: all learned) tasks."""
    policies: dict[int, Any] = {}
    for pol in kb.records("policy", environment=env):
        if pol.q is not None and not pol.provenance.parameters.get("q_columns"):
            policies[pol.task_id] = pol  # ascending ids: the newest wins
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
    kb: Any,
    environment_name: str,
    *,
    tasks: Sequence[str | int] | None = None,
    options: Sequence[int] | None = None,
    weights: Mapping[str, float] | Sequence[float] | None = None,
    threshold: float | None = None,
    threshold_scale: float = DEFAULT_THRESHOLD_SCALE,
    subgoal_options_only: bool = False,
) -> HierarchyInputs:
    """Read the learned tasks and candidate options of ``environment_name`` (module docstring).

    Args:
        tasks: task names, ``task:N`` refs or ids (default: every task with a stored policy).
        options: option record ids (default: every option stored for the environment).
        weights: importance ``U(T_i)`` by task name/ref, or one per selected task (default 1).
        threshold: the estimator's ``L`` for every task (default: ``threshold_scale`` times each
            task's value range over its non-terminal states).
        subgoal_options_only: keep only options to subgoals (the ``all-subgoals`` heuristic).
    """
    from adpart.workflows.options import load_options
    from adpart.workflows.resolve import resolve_domain

    env = kb.find_environment(environment_name)
    domain = resolve_domain(env.name)
    dyn = domain.dynamics()
    if dyn.content_hash != env.model_hash:
        raise TaskError(
            f"environment {env.name!r} in the knowledge base was recorded with other dynamics "
            "than the installed one; use the adpart version that recorded it"
        )
    chosen = _select_tasks(kb, env, tasks)
    if options is None:
        option_records = kb.options_for(env)
    else:
        option_records = [kb.get("option", int(i)) for i in options]
        for rec in option_records:
            if rec.environment_id != env.id:
                raise TaskError(f"{rec.ref} belongs to another environment than {env.name!r}")
    if subgoal_options_only:
        option_records = [r for r in option_records if r.subgoal_id is not None]
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
        mdp = _task_mdp(kb, domain, task_rec)
        Q = kb.load(policy, "q")
        if threshold is None:
            V = np.where(mdp.admissible & np.isfinite(Q), Q, -np.inf).max(axis=1)[~mdp.terminal]
            V = V[np.isfinite(V)]
            L = threshold_scale * float(V.max() - V.min()) if V.size else 0.0
        else:
            L = float(threshold)
        learned.append(task_from_model(mdp, Q, opts, threshold=L, name=task_rec.name, weight=wi))
    A = dyn.n_actions
    S = dyn.n_states
    dyn_adm = (
        dyn.admissible
        if dyn.admissible is not None
        else np.ones((dyn.n_states, dyn.n_actions), dtype=bool)
    )
    adm = np.concatenate([dyn_adm] + [o.initiation[:, None] for o in opts], axis=1)
    term = np.concatenate([np.ones((S, A), dtype=bool)]
                          + [(o.beta >= 1.0)[:, None] for o in opts], axis=1)
    task_ids = {t.id for t, _ in chosen}
    parents = {p.id for p in kb.records("partition", environment=env) if p.task_id in task_ids}
    for tid in task_ids:
        parents.update(r.partition_id for r in kb.runs_for(tid) if r.partition_id is not None)
    return HierarchyInputs(
        environment=env, task_records=[t for t, _ in chosen],
        policy_records=[p for _, p in chosen], tasks=learned, option_records=option_records,
        options=opts, action_names=list(dyn.action_names) + [o.name for o in opts],
        admissible=adm, termination=term, mdp=mdp, parent_ids=sorted(parents),
    )


# --------------------------------------------------------------------------- layers


def fill_empty_blocks(partition: Partition, admissible: np.ndarray, n_primitives: int) -> Partition:
    """Blocks offering no column get every primitive action admissible in all their states."""
    adm = partition.admissible.copy()
    empty = ~adm.any(axis=1)
    if empty.any():
        allowed = block_all(partition.labels, partition.n_blocks, admissible[:, :n_primitives])
        adm[empty, :n_primitives] = allowed[empty]
    return partition.with_admissible(adm)


def _prune(partition: Partition, n_primitives: int) -> tuple[Partition, np.ndarray]:
    """Drop option columns no block offers; return the layer and the kept option indices."""
    used = np.flatnonzero(partition.admissible[:, n_primitives:].any(axis=0))
    cols = np.r_[np.arange(n_primitives), n_primitives + used]
    return partition.with_admissible(partition.admissible[:, cols]), used


def expected_time_layer(
    inputs: HierarchyInputs, *, c: float = 1.0, max_steps: int | None = None
) -> tuple[Partition, list[float], list[Step], float]:
    """Algorithm 3 over ``inputs``; returns ``(filled layer, trace, steps, its estimate)``."""
    A = inputs.mdp.n_actions
    result = greedy_hierarchy(
        inputs.tasks, inputs.admissible, n_primitives=A,
        splits=column_splits(inputs.admissible, inputs.termination), c=c, max_steps=max_steps,
    )
    filled = fill_empty_blocks(result.partition, inputs.admissible, A)
    est = expected_time(inputs.tasks, filled, n_primitives=A, c=c).total
    return filled, result.trace, result.steps, est


def flat_estimate(inputs: HierarchyInputs, *, c: float = 1.0) -> float:
    """``E[t_learn | flat]`` over the inputs' primitive actions (the "no abstraction" layer)."""
    return flat_time(inputs.admissible[:, :inputs.mdp.n_actions], c)


def all_subgoals_layer(
    inputs: HierarchyInputs, *, delta: float = 0.0, c: float = 1.0
) -> tuple[Partition, float]:
    """The seed's heuristic: multi-phase partition (phases 1-2) over every subgoal option.

    Every option is offered in every block where all states may start it; blocks left without
    one get the primitive actions (:func:`fill_empty_blocks`). Returns the layer over the
    inputs' columns and its ``E[t_learn]``.
    """
    from adpart.learning.smdp_q import option_set
    from adpart.partition import MultiPhasePartitioner, refine
    from adpart.partition.partition import combine_labels

    if not inputs.options:
        raise TaskError(
            f"environment {inputs.environment.name!r} has no stored subgoal options; build them "
            "with `adpart options` first"
        )
    _, smdp = option_set(inputs.mdp, inputs.options, include_primitives=True)
    cols = np.arange(inputs.mdp.n_actions, smdp.n_actions)
    partitioner = MultiPhasePartitioner(smdp, inputs.termination, delta=delta)
    start = combine_labels(*(partitioner.phase1(int(o)).labels for o in cols))
    # states no option may start (the subgoals themselves) stay in blocks of their own pattern;
    # they get the primitive actions below instead of failing the cover check of phase 2
    layer = refine(Partition.from_labels(start, smdp.admissible), smdp, options=cols,
                   delta=delta, epsilon=None, require_admissible=False)
    layer = layer.with_admissible(layer.admissible & block_all(
        layer.labels, layer.n_blocks, inputs.admissible))
    A = inputs.mdp.n_actions
    filled = fill_empty_blocks(layer, inputs.admissible, A)
    return filled, expected_time(inputs.tasks, filled, n_primitives=A, c=c).total


def store_layer(
    kb: Any, inputs: HierarchyInputs, partition: Partition, *, estimator: str,
    parameters: Mapping[str, Any],
) -> tuple[Partition, list[int], int]:
    """Prune unused options and store the layer as a ``hierarchy`` partition with its lineage."""
    A = inputs.mdp.n_actions
    pruned, used = _prune(partition, A)
    option_ids = [inputs.option_records[int(i)].id for i in used]
    rec = kb.put_partition(
        inputs.environment, "hierarchy", pruned.labels,
        options=option_ids, includes_primitives=True, block_actions=pruned.admissible,
        parents=inputs.parent_ids, plugin=estimator, parameters=dict(parameters),
    )
    return pruned, option_ids, rec.id


def build_hierarchy(
    kb: Any,
    environment_name: str,
    *,
    estimator: str = "expected-learning-time",
    tasks: Sequence[str | int] | None = None,
    params: Mapping[str, Any] | None = None,
    store: bool = True,
) -> HierarchyResult:
    """Build the decision layer for the next task of ``environment_name`` with an estimator plugin.

    Args:
        kb: an open :class:`~adpart.store.KnowledgeBase`.
        estimator: a ``hierarchy-estimator`` plugin (``expected-learning-time``,
            ``all-subgoals`` or a third-party one).
        tasks: learned tasks to use (names, ``task:N`` or ids; default all).
        params: the plugin's parameters (validated against its declaration).
        store: store the layer as a ``hierarchy`` partition.
    """
    from adpart.plugins import get_registry

    spec = get_registry().get("hierarchy-estimator", estimator)
    plugin = spec.create(dict(params or {}))
    return plugin.build(kb, environment_name, tasks=tasks, store=store)


def finish(
    kb: Any, inputs: HierarchyInputs, layer: Partition, *, estimator: str, trace: list[float],
    steps: list[Step], estimate: float, parameters: Mapping[str, Any], store: bool,
    seconds: dict[str, float], flat: float | None = None,
) -> HierarchyResult:
    """Prune, optionally store, and wrap a built layer (shared by the estimator plugins).

    With ``flat`` (``E[t_learn | flat]``) the result says whether to fall back to flat learning
    (``flat <= estimate``); the decision is stored with the layer's parameters.
    """
    t0 = time.perf_counter()
    task_ids = [t.id for t in inputs.task_records]
    fallback = flat is not None and flat <= estimate
    params = {**parameters, "tasks": task_ids, "policies": [p.id for p in inputs.policy_records],
              "estimate": estimate, "steps": len(steps), "flat_estimate": flat,
              "fallback": fallback}
    if store:
        pruned, option_ids, pid = store_layer(kb, inputs, layer, estimator=estimator,
                                              parameters=params)
    else:
        pruned, used = _prune(layer, inputs.mdp.n_actions)
        option_ids, pid = [inputs.option_records[int(i)].id for i in used], None
    A = inputs.mdp.n_actions
    names = inputs.action_names[:A] + [
        inputs.action_names[A + [r.id for r in inputs.option_records].index(i)]
        for i in option_ids]
    seconds = {**seconds, "store": time.perf_counter() - t0}
    return HierarchyResult(estimator, pruned, option_ids, names, list(trace), estimate,
                           list(steps), task_ids, pid, seconds, dict(parameters), flat, fallback)

"""Multi-phase partitioning of an environment over stored options, every phase kept in the KB.

The numeric phases are :mod:`adpart.partition.multiphase` (section 4.2.1.2); this workflow adds
what the dissertation's "knowledge base" promises (section 4.2.1.2, chapter 6):

* **The task's model.** Every phase runs on the model of the task asked for
  (:mod:`adpart.partition.layer`). Stored option models carry the rewards and the terminal states
  of the task they were built under. For another task they are recomputed on that task's MDP
  (:func:`adpart.options.models.option_models`) *before* phase 1. Its terminal states are one
  absorbing block, and the states it cannot reach from its start states are kept apart. Without a
  task, phases 1-2 run on the model the options were built under.
* **Phase 1** per option is reward-independent: it is stored as a ``per-option`` partition and
  *reused* whenever the knowledge base already holds one for the same option, delta, terminal set
  and gamma (the model it ran on; epsilon and the rewards play no part). Changing the option set
  therefore re-runs phases 2-3 only.
* **Phase 2** (intersection + refinement for the whole set) is stored as ``intersected`` with the
  phase-1 partitions as parents (key: also the start states).
* **Phase 3** (a task's rewards beyond its constant step reward within epsilon, eq. 4.7) is
  stored as ``reward-refined`` with the phase-2 partition as parent (key: also the task, epsilon
  and the reward baseline).

The artifact of each record is the block labels ``(S,)``; ``block_actions`` is the ``(B, K)``
mask of the options offered per block over the record's action set (the options in order, or the
primitive actions for ``--options primitive``). The final decision layer (the unreachable blocks
offering nothing) is verified by the independent checker
(:func:`adpart.partition.check_stability`), and with a task the measured ``||V* - V*_P||_inf`` of
the point model over the layer's states is reported next to theorem 4.5's bound
(:func:`adpart.partition.value_gap`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from adpart.errors import ModelError, TaskError
from adpart.execution import Executor
from adpart.mdp.model import FiniteMDP, SMDPModel
from adpart.options.models import OptionModel, option_models
from adpart.options.smdp import stack_models
from adpart.params import settings_dict
from adpart.partition import (
    MultiPhasePartitioner,
    Partition,
    check_stability,
    value_gap,
)
from adpart.partition.layer import decision_view, layer_counts, resolve_baseline
from adpart.partition.multiphase import Criterion
from adpart.partition.settings import DEFAULT_CRITERION, PartitionSettings
from adpart.workflows.options import OptionSet, resolve_option_set
from adpart.workflows.resolve import EXPERIENCE_MARK, register_domain, resolve_domain
from adpart.workflows.store import KnowledgeStore

PLUGIN = "adpart.partition"


@dataclass(frozen=True)
class PhaseRecord:
    """One stored partition of a run: its record id, block count, and whether it was reused."""

    kind: str
    id: int
    blocks: int
    reused: bool = False
    column: str = ""

    @property
    def ref(self) -> str:
        return f"partition:{self.id}"


@dataclass(frozen=True, eq=False)
class PartitionOutcome:
    """What :func:`partition_environment` computed and stored.

    Attributes:
        env, task: environment and task names (task None: phases 1-2 only).
        options: the option set as given (``primitive`` or record refs).
        columns: the action set of every stored record (option names, or primitive actions).
        phase1: one :class:`PhaseRecord` per option.
        phase2, phase3: the intersected and reward-refined records (phase3 None without task).
        final: the last :class:`Partition` (over ``columns``).
        seconds: wall time per phase (``phase1`` counts only the options computed anew).
        check: the checker's verdict on the final partition.
        gap: measured ``||V* - V*_P||_inf`` next to theorem 4.5 (with a task), else None.
        recomputed_models: whether option models were recomputed for the task.
    """

    env: str
    task: str | None
    options: str
    delta: float
    epsilon: float
    n_states: int
    columns: list[str]
    phase1: list[PhaseRecord]
    phase2: PhaseRecord
    phase3: PhaseRecord | None
    final: Partition
    seconds: dict[str, float]
    check: dict[str, Any]
    gap: dict[str, float] | None
    recomputed_models: bool
    environment_id: int
    task_id: int | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    terminal: np.ndarray | None = None
    unreachable: np.ndarray | None = None

    @property
    def decision_blocks(self) -> int:
        """Blocks of the decision layer: those holding a reachable non-terminal state."""
        return layer_counts(self.final, self.terminal, self.unreachable)["reachable"]

    @property
    def final_record(self) -> PhaseRecord:
        return self.phase3 if self.phase3 is not None else self.phase2

    def summary(self) -> dict[str, Any]:
        """JSON-ready: ids and block counts per phase, seconds, checker and value gap."""
        p1_blocks = [p.blocks for p in self.phase1]
        return {
            "env": self.env,
            "task": self.task,
            "options": self.options,
            "delta": self.delta,
            "epsilon": self.epsilon,
            "states": self.n_states,
            "environment": f"environment:{self.environment_id}",
            "task_id": None if self.task_id is None else f"task:{self.task_id}",
            "phase1": {
                "partitions": [
                    {"id": p.ref, "column": p.column, "blocks": p.blocks, "reused": p.reused}
                    for p in self.phase1
                ],
                "blocks_min": int(min(p1_blocks)),
                "blocks_max": int(max(p1_blocks)),
                "computed": sum(not p.reused for p in self.phase1),
                "reused": sum(p.reused for p in self.phase1),
            },
            "phase2": {"id": self.phase2.ref, "blocks": self.phase2.blocks},
            "phase3": None
            if self.phase3 is None
            else {
                "id": self.phase3.ref,
                "blocks": self.phase3.blocks,
                "recomputed_option_models": self.recomputed_models,
            },
            "final": {"id": self.final_record.ref, "blocks": self.final.n_blocks,
                      "decision_blocks": self.decision_blocks},
            "layer": self.extra.get("layer"),
            "reward_baseline": self.extra.get("reward_baseline"),
            "seconds": {k: round(v, 4) for k, v in self.seconds.items()},
            "check": self.check,
            "value_gap": self.gap,
        }


@dataclass(frozen=True, eq=False)
class _Base:
    """The model phases 1-2 run on and how each column is stored."""

    smdp: SMDPModel
    termination: np.ndarray
    columns: list[str]
    option_set: OptionSet
    mdp: FiniteMDP
    #: number of leading primitive columns offered only where no option can start (0 or A)
    fallback: int = 0

    def is_primitive(self, column: int) -> bool:
        return self.option_set.primitive or column < self.fallback

    def record_of(self, column: int) -> Any:
        return self.option_set.records[column - self.fallback]



def build_criterion(name: str, params: dict[str, Any] | None, settings: PartitionSettings
               ) -> tuple[Criterion | None, dict[str, Any]]:
    """The partition criterion ``name`` built from ``params`` and ``settings`` (None for the
    built-in default), and what it adds to the stored partitions' keys."""
    from adpart.plugins import get_registry

    spec = get_registry().get("partition-criterion", name)
    declared = {p.keyword for p in spec.params}
    given = {k.replace("-", "_"): v for k, v in (params or {}).items()}
    base = {k: v for k, v in settings_dict(settings).items() if k in declared}
    if name == DEFAULT_CRITERION and not given:
        return None, {}
    values = {**base, **given}
    built = spec.create(values)
    if not isinstance(built, Criterion):
        raise TaskError(f"partition-criterion {name!r} has no refine(partition, model, "
                        "**context) method")
    return built, {"criterion": name, "criterion_params": dict(sorted(
        (k, v) for k, v in values.items()))}


def environment_record(kb: KnowledgeStore, env_name: str) -> tuple[Any, Any]:
    """The domain and its get-or-put environment record (keyed by the dynamics' hash)."""
    domain = resolve_domain(env_name)
    dyn = domain.dynamics()
    env = kb.put_environment(
        env_name,
        model_hash=dyn.content_hash,
        n_states=dyn.n_states,
        n_actions=dyn.n_actions,
        spec={"name": env_name, "source": domain.source, "actions": list(dyn.action_names)},
    )
    if env.name != env_name and EXPERIENCE_MARK in env.name:  # the same estimate, named by
        register_domain(env.name, domain)  # the runs that first gave it: resolvable by both
    return domain, env


def task_record(kb: KnowledgeStore, domain: Any, env: Any, task: str) -> tuple[Any, FiniteMDP, Any]:
    """The task, its MDP and its get-or-put record (the same record ``adpart learn`` makes)."""
    task_obj = domain.task(task)
    task_mdp = domain.mdp(task_obj)
    task_rec = kb.put_task(
        env,
        task_obj.name,
        spec={**task_obj.spec, "name": task_obj.name, "model_hash": task_mdp.content_hash},
        gamma=task_obj.gamma,
    )
    return task_obj, task_mdp, task_rec


def _source_task(records: list[Any]) -> int | None:
    """The task the stored option models were built under, when all agree (else None)."""
    tasks = {rec.provenance.parameters.get("task_id") for rec in records}
    return tasks.pop() if len(tasks) == 1 else None


def _base_model(
    kb: KnowledgeStore, domain: Any, env_name: str, options_text: str, task_mdp: FiniteMDP | None
) -> _Base:
    """Phases 1-2 work on the stored option models (primitives: the task's own MDP)."""
    option_set = resolve_option_set(kb, options_text, env_name)
    if option_set.primitive:
        mdp = task_mdp if task_mdp is not None else domain.mdp(None)
        smdp = mdp.as_smdp()
        termination = np.zeros(smdp.R.shape, dtype=bool)  # one-step: {I, outside I} start
        return _Base(smdp, termination, list(mdp.action_names), option_set, mdp)
    if len({rec.id for rec in option_set.records}) != len(option_set.records):
        raise TaskError(f"--options {options_text!r} lists an option twice; name each once")
    source = _source_task(option_set.records)
    mdp = domain.mdp(kb.get("task", source).name if source is not None else None)
    # Primitive actions are offered only where no option can start (a subgoal is not in its own
    # option's initiation set): the layer stays over the options everywhere else.
    covered = np.stack([m.admissible for m in option_set.models], axis=1).any(axis=1)
    complete = np.all(covered | mdp.terminal)
    if task_mdp is not None:  # the task may make a state live that the options never start in
        starts = np.stack([o.initiation for o in option_set.options], axis=1).any(axis=1)
        complete = complete and np.all(starts | task_mdp.terminal)
    if complete:
        smdp = stack_models(mdp, option_set.models, include_primitives=False)
        termination = np.stack([o.beta >= 1.0 for o in option_set.options], axis=1)
        return _Base(smdp, termination, [rec.ref for rec in option_set.records], option_set, mdp)
    smdp = stack_models(mdp, option_set.models, include_primitives="uncovered")
    A = mdp.n_actions
    termination = np.concatenate(
        [
            np.ones((mdp.n_states, A), dtype=bool),
            np.stack([o.beta >= 1.0 for o in option_set.options], axis=1),
        ],
        axis=1,
    )
    columns = [*mdp.action_names, *(rec.ref for rec in option_set.records)]
    return _Base(smdp, termination, columns, option_set, mdp, fallback=A)


def _mask_key(column: np.ndarray) -> str:
    import hashlib

    return hashlib.sha256(np.ascontiguousarray(column, dtype=bool).tobytes()).hexdigest()


def _find_phase1(kb: KnowledgeStore, env: Any, base: _Base, column: int, delta: float,
                 key: dict[str, Any], admissible: np.ndarray) -> Any | None:
    """A stored per-option partition of this column with this delta and model ``key``, or None.

    ``key`` names the model phase 1 ran on (the task's terminal states and gamma): options'
    models, and so their phase-1 partitions, depend on where episodes end.
    """
    if base.is_primitive(column):
        mask = _mask_key(admissible[:, column])
        candidates = [
            p
            for p in kb.records("partition", environment=env)
            if p.kind == "per-option"
            and not p.option_ids
            and p.provenance.parameters.get("action") == column
            and p.provenance.parameters.get("admissible", mask) == mask
        ]
    else:
        rec = base.record_of(column)
        candidates = [
            p
            for p in kb.partitions_using([rec], exact=True, includes_primitives=False)
            if p.kind == "per-option"
        ]
    matching = [p for p in candidates if abs(p.delta - delta) <= 1e-12
                and _same_key(p.provenance.parameters, key)]
    return matching[-1] if matching else None


def _same_key(parameters: dict[str, Any], key: dict[str, Any]) -> bool:
    """Whether a stored record's parameters hold every entry of ``key``."""
    return all(parameters.get(k) == v for k, v in key.items())


def _find_later_phase(
    kb: KnowledgeStore,
    env: Any,
    base: _Base,
    kind: str,
    *,
    parents: list[int],
    delta: float,
    epsilon: float | None = None,
    task_id: int | None = None,
    key: dict[str, Any] | None = None,
) -> Any | None:
    """A stored phase-2/3 partition built from exactly these parents and settings, or None."""
    records = base.option_set.records
    candidates = (
        kb.partitions_using(records, exact=True)
        if records
        else [p for p in kb.records("partition", environment=env) if not p.option_ids]
    )
    for p in reversed(candidates):
        if (
            p.kind == kind
            and p.environment_id == env.id
            and sorted(p.parent_ids) == sorted(parents)
            and abs(p.delta - delta) <= 1e-12
            and (epsilon is None or abs(p.epsilon - epsilon) <= 1e-12)
            and (task_id is None or p.task_id == task_id)
            and _same_key(p.provenance.parameters, key or {})
        ):
            return p
    return None


def _store(
    kb: KnowledgeStore,
    env: Any,
    base: _Base,
    kind: str,
    partition: Partition,
    columns: np.ndarray,
    *,
    delta: float,
    epsilon: float,
    parents: list[int],
    task: Any = None,
    parameters: dict[str, Any],
) -> Any:
    prim_cols = [int(c) for c in columns if base.is_primitive(int(c))]
    opt_cols = [int(c) for c in columns if not base.is_primitive(int(c))]
    primitive = bool(prim_cols)
    A = base.mdp.n_actions
    options: list[Any] = [base.record_of(c) for c in opt_cols]
    if primitive:  # stored layout: all primitive actions first, then the options
        block_actions = np.zeros((partition.n_blocks, A + len(opt_cols)), dtype=bool)
        block_actions[:, prim_cols] = partition.admissible[:, prim_cols]
        block_actions[:, A:] = partition.admissible[:, opt_cols]
    else:
        block_actions = partition.admissible[:, opt_cols]
    return kb.put_partition(
        env,
        kind,
        partition.labels,
        options=options,
        includes_primitives=primitive,
        epsilon=epsilon,
        delta=delta,
        block_actions=block_actions,
        parents=parents,
        task=task,
        plugin=PLUGIN,
        parameters=parameters,
    )


def _later_phase(
    kb: KnowledgeStore, env: Any, base: _Base, mp: MultiPhasePartitioner, kind: str,
    compute: Callable[[], Partition], columns: np.ndarray, *, parents: list[int], delta: float,
    epsilon: float, task: Any = None, key: dict[str, Any],
    parameters: Callable[[Partition], dict[str, Any]],
) -> tuple[Partition, PhaseRecord, float]:
    """Phase 2 or 3: the stored partition of these parents and settings, else computed and
    stored with ``parameters(partition)`` as provenance; returns the partition, its row
    (``reused`` says which) and the seconds computing took (0 when reused)."""
    found = _find_later_phase(kb, env, base, kind, parents=parents, delta=delta,
                              epsilon=epsilon if task is not None else None,
                              task_id=None if task is None else task.id, key=key)
    if found is not None:
        part = Partition.from_labels(kb.load(found, "labels"), mp.layer_model.admissible)
        return part, PhaseRecord(kind, found.id, part.n_blocks, reused=True), 0.0
    t0 = time.perf_counter()
    part = compute()
    seconds = time.perf_counter() - t0
    record = _store(kb, env, base, kind, part, columns, delta=delta, epsilon=epsilon,
                    parents=parents, task=task, parameters={**parameters(part), **key})
    return part, PhaseRecord(kind, record.id, part.n_blocks, reused=False), seconds


def _phase1_all(
    kb: KnowledgeStore, env: Any, base: _Base, mp: MultiPhasePartitioner, key: dict[str, Any]
) -> tuple[dict[int, Partition], list[PhaseRecord], float]:
    """Phase 1 of every column on ``mp``'s model: loaded when stored, else computed and stored."""
    smdp = mp.layer_model
    parts: dict[int, Partition] = {}
    rows: list[PhaseRecord] = []
    seconds = 0.0
    for o in range(smdp.n_actions):  # one refinement per option (each vectorised over states)
        found = _find_phase1(kb, env, base, o, mp.delta, key, mp.model.admissible)
        if found is not None:
            labels = kb.load(found, "labels")
            parts[o] = Partition.from_labels(labels, _only(smdp.admissible, o))
            mp.add_phase1(o, parts[o])
            rows.append(PhaseRecord("per-option", found.id, found.n_blocks, True, base.columns[o]))
            continue
        t0 = time.perf_counter()
        part = mp.phase1(o)
        seconds += time.perf_counter() - t0
        params: dict[str, Any] = {"phase": 1, "column": base.columns[o], **key}
        if base.is_primitive(o):
            params.update(action=o, admissible=_mask_key(mp.model.admissible[:, o]))
        rec = _store(
            kb,
            env,
            base,
            "per-option",
            part,
            np.array([o]),
            delta=mp.delta,
            epsilon=0.0,
            parents=[],
            parameters=params,
        )
        parts[o] = part
        rows.append(PhaseRecord("per-option", rec.id, part.n_blocks, False, base.columns[o]))
    return parts, rows, seconds


def _only(admissible: np.ndarray, column: int) -> np.ndarray:
    out = np.zeros_like(admissible)
    out[:, column] = admissible[:, column]
    return out


def _task_model(
    base: _Base, task_rec: Any, task_mdp: FiniteMDP, executor: Executor | None
) -> tuple[SMDPModel, list[OptionModel] | None, bool]:
    """The model phase 3 refines against: stored models if built under this very task."""
    if base.option_set.primitive:
        return task_mdp.as_smdp(), None, False
    same_task = _source_task(base.option_set.records) == task_rec.id
    same_gamma = all(
        rec.gamma is not None and abs(rec.gamma - task_mdp.gamma) <= 1e-12
        for rec in base.option_set.records
    )
    if same_task and same_gamma and base.mdp.content_hash == task_mdp.content_hash:
        return base.smdp, list(base.option_set.models), False
    models = option_models(
        task_mdp, list(base.option_set.options), executor=executor, duration=False
    )
    try:
        stacked = stack_models(
            task_mdp, models, include_primitives="uncovered" if base.fallback else False
        )
    except ModelError as exc:
        raise ModelError(
            f"under task {task_rec.name!r} the option set leaves a state with no admissible "
            f"option ({exc}); the options were built under another task, whose terminal states "
            f"they skip - build options for task {task_rec.name!r} or use --options primitive"
        ) from exc
    return stacked, models, True


def _baseline(reward_baseline: object, mdp: FiniteMDP) -> float | None:
    """The constant step reward phase 3 takes out of ``mdp``'s rewards (``resolve_baseline``)."""
    return resolve_baseline(reward_baseline, mdp.R, mdp.admissible, mdp.terminal)


def _start_states(mdp: FiniteMDP) -> np.ndarray:
    """The task's start states: ``mdp.initial``'s support off the terminal states."""
    start = (mdp.initial > 0) & ~mdp.terminal
    if not start.any():
        raise ModelError(
            "the start distribution puts all its mass on terminal states; give the task an "
            "initial distribution over non-terminal states"
        )
    return start


def partition_environment(
    kb: KnowledgeStore,
    env_name: str,
    options: str,
    settings: PartitionSettings,
    *,
    task: str | None = None,
    criterion: str = DEFAULT_CRITERION,
    criterion_params: dict[str, Any] | None = None,
    executor: Executor | None = None,
    check: bool = True,
    reward_baseline: str | float | None = "mode",
) -> PartitionOutcome:
    """Phases 1-3 of section 4.2.1.2 for ``env_name`` over a stored option set, stored in ``kb``.

    Every phase runs on the model of the task asked for (:mod:`adpart.partition.layer`): its
    option models (recomputed on the task's MDP unless built under it), its terminal states as
    one absorbing block, and only the states reachable from its start states refined (the others
    kept apart, one block per admissibility pattern). Without a task, phases 1-2 run on the model
    the options were built under, with that task's terminal and start states.

    Args:
        options: ``subgoal-set:N`` (its options), ``option:1,option:2``, or ``primitive``.
        settings: delta (eq. 4.6) and the reward epsilon (eq. 4.7, phase 3 only).
        task: a task name or ``goal:...`` spec; None stops after phase 2.
        criterion: the ``partition-criterion`` plugin that refines every phase
            (:class:`~adpart.partition.multiphase.Criterion`); the default, ``bisimulation``, is
            delta-stability with ``settings`` (eqs. 4.6-4.7). Another criterion is built from
            ``criterion_params`` (and ``settings``' fields where it declares them), and its
            name and parameters join the stored partitions' keys.
        executor: runs the option-model computations when a task needs them recomputed.
        check: run the independent checker on the final decision layer.
        reward_baseline: the constant step reward phase 3 takes out of the rewards before eq.
            4.7: ``"mode"`` (the step reward most pairs pay), ``"min"`` (the smallest, sections
            4.3.1-4.3.2), ``"none"`` (compare ``R(s, o)`` itself) or a number
            (:mod:`adpart.partition.layer`).

    Raises:
        ModelError: delta or epsilon out of range, or an option set leaving a state with no
            admissible option. TaskError / StoreError: unknown ids, options of another
            environment, options without stored models.
    """
    d, e = settings.delta, settings.reward_epsilon
    refiner, criterion_key = build_criterion(criterion, criterion_params, settings)
    domain, env = environment_record(kb, env_name)
    task_obj = task_mdp = task_rec = None
    if task is not None:
        task_obj = domain.task(task)
        task_mdp = domain.mdp(task_obj)
        task_rec = kb.put_task(
            env,
            task_obj.name,
            spec={**task_obj.spec, "name": task_obj.name, "model_hash": task_mdp.content_hash},
            gamma=task_obj.gamma,
        )
    base = _base_model(kb, domain, env_name, options, task_mdp)
    all_cols = np.arange(base.smdp.n_actions)
    seconds: dict[str, float] = {}

    # the model every phase runs on: the task's (module docstring of adpart.partition.layer)
    model, recomputed, layer_mdp = base.smdp, False, base.mdp
    if task_rec is not None:
        t0 = time.perf_counter()
        model, _, recomputed = _task_model(base, task_rec, task_mdp, executor)
        seconds["models"] = time.perf_counter() - t0
        layer_mdp = task_mdp
    baseline = _baseline(reward_baseline, layer_mdp) if task_rec is not None else None
    terminal = layer_mdp.terminal
    start = _start_states(layer_mdp)
    key = {"layer": 1, "terminal": _mask_key(terminal), "gamma": float(layer_mdp.gamma),
           **criterion_key}
    mp = MultiPhasePartitioner(model, base.termination, delta=d, terminal=terminal,
                               criterion=refiner)

    _, p1_rows, seconds["phase1"] = _phase1_all(kb, env, base, mp, key)

    t0 = time.perf_counter()
    # what the task can reach with its primitive actions: refinement may offer any of them
    unreachable = mp.unreachable(all_cols, start, through=layer_mdp)
    seconds["reach"] = time.perf_counter() - t0
    key2 = {**key, "start": _mask_key(start)}
    parent_ids = [r.id for r in p1_rows]
    p2, phase2_row, seconds["phase2"] = _later_phase(
        kb, env, base, mp, "intersected", lambda: mp.phase2(all_cols, unreachable=unreachable),
        all_cols, parents=parent_ids, delta=d, epsilon=0.0, key=key2,
        parameters=lambda part: {"phase": 2, "options": options,
                                 "layer_counts": layer_counts(part, terminal, unreachable)},
    )

    final, phase3_row, gap, rewards = p2, None, None, None
    if task_rec is not None:
        rewards = mp.decision_rewards(unreachable=unreachable, reward_baseline=baseline,
                                      gamma=task_mdp.gamma)
        key3 = {**key2, "reward_baseline": baseline}
        final, phase3_row, seconds["phase3"] = _later_phase(
            kb, env, base, mp, "reward-refined",
            lambda: mp.phase3(p2, all_cols, epsilon=e, rewards=rewards, unreachable=unreachable),
            all_cols, parents=[phase2_row.id], delta=d, epsilon=e, task=task_rec, key=key3,
            parameters=lambda part: {"phase": 3, "options": options, "task": task_obj.name,
                                     "recomputed_option_models": recomputed,
                                     "layer_counts": layer_counts(part, terminal, unreachable)},
        )
        t0 = time.perf_counter()
        gap = value_gap(final, model, epsilon=e, delta=d, options=all_cols,
                        states=~unreachable)
        seconds["value_gap"] = time.perf_counter() - t0

    verdict: dict[str, Any] = {"ran": False}
    if check:
        t0 = time.perf_counter()
        report = check_stability(
            decision_view(final, unreachable), model, options=all_cols, delta=d,
            epsilon=e if task_rec is not None else None, rewards=rewards,
        )
        seconds["check"] = time.perf_counter() - t0
        verdict = {
            "ran": True,
            "ok": report.ok,
            "max_mass_span": report.max_mass_span,
            "max_reward_span": report.max_reward_span,
            "violations": len(report.violations),
        }
    return PartitionOutcome(
        env=env_name,
        task=None if task_obj is None else task_obj.name,
        options=options,
        delta=d,
        epsilon=e,
        n_states=base.smdp.n_states,
        columns=base.columns,
        phase1=p1_rows,
        phase2=phase2_row,
        phase3=phase3_row,
        final=final,
        seconds=seconds,
        check=verdict,
        gap=gap,
        recomputed_models=recomputed,
        environment_id=env.id,
        task_id=None if task_rec is None else task_rec.id,
        extra={
            "layer": {
                "phase2": layer_counts(p2, terminal, unreachable),
                "phase3": None if phase3_row is None
                else layer_counts(final, terminal, unreachable),
            },
            "reward_baseline": baseline,
        },
        terminal=terminal,
        unreachable=unreachable,
    )


def plot_partition(
    env_name: str, labels: np.ndarray, path: str, *, title: str | None = None,
    task: str | None = None,
) -> str:
    """Draw a partition on the domain's map (as Fig. 4.5), touching blocks in different
    colours, with ``task``'s goal and start lettered (default: the domain's default task);
    return the path."""

    domain = resolve_domain(env_name)
    try:
        domain.render(path, labels=np.asarray(labels), title=title, task=task)
    except OSError as exc:
        raise TaskError(
            f"cannot write the plot to {path}: {exc.strerror}; choose another --plot"
        ) from exc
    return path

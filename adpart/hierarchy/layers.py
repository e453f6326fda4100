"""Decision layers for the next task from what earlier tasks learned (dissertation section 4.4).

:class:`HierarchyInputs` holds the learned tasks (:class:`~adpart.hierarchy.tasks.LearnedTask`)
and candidate options over one column set (the primitive actions, then the options).
:func:`expected_time_layer` runs Algorithm 3 on them; :func:`all_subgoals_layer` is the seed's
heuristic (every subgoal option in every block where it is admissible, then the multi-phase
partition); :func:`layer_result` wraps a layer as the :class:`HierarchyResult` an estimator plugin
returns. Everything here is a function of the inputs: reading them from a knowledge base and
storing the layer is the job of :mod:`adpart.workflows.hierarchy`.

Interpretations (docs/hierarchy.md): the estimator's threshold ``L`` defaults to
``threshold_scale`` (1%) of the task's value range; blocks the construction left without any
action get the primitive actions admissible in all their states (the hierarchical learner needs
a decision in every block, and where no learned task goes nothing better is known); only option
columns some block offers are kept with the layer.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from adpart.errors import TaskError
from adpart.hierarchy.estimator import expected_time, flat_time
from adpart.hierarchy.greedy import Step, column_splits, greedy_hierarchy
from adpart.hierarchy.tasks import LearnedTask
from adpart.mdp.model import FiniteMDP
from adpart.options.option import Option
from adpart.partition.partition import Partition, block_all


@dataclass(frozen=True, eq=False)
class HierarchyInputs:
    """Everything one construction needs: the learned tasks, the options, their columns.

    Plain data (no store records): the workflow that loads them from a knowledge base fills in
    the record ids, so a layer built from them can be stored with its lineage; anyone else builds
    them with :meth:`from_tasks`.

    Attributes:
        environment: the environment's name (for messages).
        tasks: the estimator's inputs, one per learned task, over all ``A + O`` columns.
        options: the candidate options (columns ``A..A+O-1``).
        action_names: names of all ``A + O`` columns.
        admissible: ``(S, A+O)`` where each column may start.
        termination: ``(S, A+O)`` beta = 1 (True for every primitive column).
        mdp: the MDP of the newest task (dynamics shared by all).
        task_ids: one id per task (its record id when loaded from a knowledge base).
        option_ids: one id per option (its record id), in column order.
        to_subgoal: per option, whether it leads to a stored subgoal (the candidates of the
            ``all-subgoals`` heuristic).
        policy_ids: the stored policy standing for each task (empty when not loaded).
        parent_ids: partitions the used tasks were learned on (their runs') or built for.
    """

    environment: str
    tasks: list[LearnedTask]
    options: list[Option]
    action_names: list[str]
    admissible: np.ndarray
    termination: np.ndarray
    mdp: FiniteMDP
    task_ids: list[int]
    option_ids: list[int]
    to_subgoal: list[bool]
    policy_ids: list[int] = field(default_factory=list)
    parent_ids: list[int] = field(default_factory=list)

    def __post_init__(self) -> None:
        n_opts = len(self.options)
        shape = (self.mdp.n_states, self.mdp.n_actions + n_opts)
        if self.admissible.shape != shape or self.termination.shape != shape:
            raise TaskError(f"admissible and termination must be {shape} (states, A + options)")
        if len(self.action_names) != shape[1]:
            raise TaskError(f"{len(self.action_names)} column names for {shape[1]} columns")
        if len(self.option_ids) != n_opts or len(self.to_subgoal) != n_opts:
            raise TaskError(f"{len(self.option_ids)} option ids and {len(self.to_subgoal)} "
                            f"subgoal flags for {n_opts} options; give one per option")
        if len(self.task_ids) != len(self.tasks):
            raise TaskError(f"{len(self.task_ids)} task ids for {len(self.tasks)} tasks")
        for task in self.tasks:
            if task.Q.shape != shape:
                raise TaskError(f"task {task.name!r}: Q has shape {task.Q.shape}; expected {shape}")

    @classmethod
    def from_tasks(
        cls, mdp: FiniteMDP, tasks: Sequence[LearnedTask], options: Sequence[Option] = (), *,
        environment: str | None = None, task_ids: Sequence[int] | None = None,
        option_ids: Sequence[int] | None = None, to_subgoal: Sequence[bool] | None = None,
        policy_ids: Sequence[int] = (), parent_ids: Sequence[int] = (),
    ) -> HierarchyInputs:
        """Inputs over ``mdp``'s primitive actions, then ``options`` (tasks built with the same
        options, e.g. by :func:`~adpart.hierarchy.tasks.task_from_model`).

        Ids default to positions; an option leads to a subgoal when it has one
        (``option.subgoal >= 0``).
        """
        S, A = mdp.n_states, mdp.n_actions
        admissible = np.concatenate([mdp.admissible] + [o.initiation[:, None] for o in options],
                                    axis=1)
        termination = np.concatenate([np.ones((S, A), dtype=bool)]
                                     + [(o.beta >= 1.0)[:, None] for o in options], axis=1)
        return cls(
            environment=environment or mdp.name, tasks=list(tasks), options=list(options),
            action_names=list(mdp.action_names) + [o.name for o in options],
            admissible=admissible, termination=termination, mdp=mdp,
            task_ids=list(range(len(tasks)) if task_ids is None else task_ids),
            option_ids=list(range(len(options)) if option_ids is None else option_ids),
            to_subgoal=([o.subgoal >= 0 for o in options] if to_subgoal is None
                        else [bool(x) for x in to_subgoal]),
            policy_ids=list(policy_ids), parent_ids=list(parent_ids),
        )

    def with_threshold(self, threshold: float | None, threshold_scale: float) -> HierarchyInputs:
        """The same inputs with every task's margin ``L = threshold``, or, with None,
        ``threshold_scale`` times the task's value range (:meth:`LearnedTask.value_range`)."""
        A = self.mdp.n_actions
        tasks = [t.with_threshold(threshold_scale * t.value_range(A) if threshold is None
                                  else threshold) for t in self.tasks]
        return replace(self, tasks=tasks)

    def select_options(self, keep: Sequence[bool] | np.ndarray) -> HierarchyInputs:
        """The same inputs over the primitive actions and the options where ``keep`` is True."""
        A = self.mdp.n_actions
        kept = np.flatnonzero(np.asarray(keep, dtype=bool))
        cols = np.r_[np.arange(A), A + kept]
        return replace(
            self, tasks=[t.with_columns(cols) for t in self.tasks],
            options=[self.options[i] for i in kept],
            action_names=[self.action_names[c] for c in cols],
            admissible=self.admissible[:, cols], termination=self.termination[:, cols],
            option_ids=[self.option_ids[i] for i in kept],
            to_subgoal=[self.to_subgoal[i] for i in kept],
        )


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
        partition_id: the stored ``hierarchy`` partition, or None when not stored (an estimator
            never stores; :func:`adpart.workflows.hierarchy.build_hierarchy` fills it in).
        seconds: ``{"construction": ...}`` from the estimator; the workflow adds ``"inputs"``
            and ``"store"``.
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


# --------------------------------------------------------------------------- layers


def fill_empty_blocks(partition: Partition, admissible: np.ndarray, n_primitives: int) -> Partition:
    """Blocks offering no column get every primitive action admissible in all their states."""
    adm = partition.admissible.copy()
    empty = ~adm.any(axis=1)
    if empty.any():
        allowed = block_all(partition.labels, partition.n_blocks, admissible[:, :n_primitives])
        adm[empty, :n_primitives] = allowed[empty]
    return partition.with_admissible(adm)


def prune_unused_options(partition: Partition, n_primitives: int) -> tuple[Partition, np.ndarray]:
    """Drop option columns no block offers; return the layer and the kept option indices."""
    used = np.flatnonzero(partition.admissible[:, n_primitives:].any(axis=0))
    cols = np.r_[np.arange(n_primitives), n_primitives + used]
    return partition.with_admissible(partition.admissible[:, cols]), used


def layer_result(
    inputs: HierarchyInputs, layer: Partition, *, estimator: str, trace: Sequence[float],
    steps: Sequence[Step], estimate: float | None, parameters: Mapping[str, Any],
    seconds: Mapping[str, float], flat: float | None = None,
) -> HierarchyResult:
    """Wrap a layer over ``inputs``' columns as an estimator's (unstored) result.

    Option columns no block offers are dropped (:func:`prune_unused_options`); the result's
    ``option_ids`` are the kept options' ids in column order. With ``flat``
    (``E[t_learn | flat]``) the result says whether to fall back to flat learning
    (``flat <= estimate``).
    """
    A = inputs.mdp.n_actions
    pruned, used = prune_unused_options(layer, A)
    option_ids = [inputs.option_ids[int(i)] for i in used]
    names = inputs.action_names[:A] + [inputs.action_names[A + int(i)] for i in used]
    fallback = flat is not None and estimate is not None and flat <= estimate
    return HierarchyResult(estimator, pruned, option_ids, names, list(trace), estimate,
                           list(steps), list(inputs.task_ids), None, dict(seconds),
                           dict(parameters), flat, fallback)


def stable_option_splits(mdp: FiniteMDP, options: Sequence[Option], admissible: np.ndarray,
                         termination: np.ndarray, *, delta: float) -> np.ndarray:
    """``(A+O, S)`` split labels: each option's own delta-stable partition (phases 1-2).

    ``admissible`` and ``termination`` are ``(S, A+O)`` over the primitive actions, then
    ``options`` (:class:`HierarchyInputs`' columns).

    "``B_j`` refined with ``o``" (Algorithm 3) is ``B_j`` refined by eq. 4.6 until it is stable
    for ``o``, as 4.3.3 refines a block for a new action: here ``B_j`` intersected with the
    partition of ``S`` that phase 1 of ``o`` (its termination states, the rest of its initiation
    set, the states outside it) refined to delta-stability for ``o`` alone gives. A subgoal
    option ends in its subgoal, so the split groups ``B_j``'s states by the discounted
    probability ``E[gamma^tau]`` of getting there, in bands of about ``delta`` - the same
    criterion and ``delta`` the ``all-subgoals`` layer applies to every option at once. Primitive
    columns (never candidates) keep phase 1's labels.
    """
    from adpart.partition import refine

    A = mdp.n_actions
    prim = column_splits(admissible[:, :A], termination[:, :A]).astype(np.int64)
    if not options:
        return prim
    smdp, partitioner = _option_partitioner(mdp, options, termination, delta)
    own = [refine(partitioner.phase1(o), smdp, options=[o], delta=delta, epsilon=None,
                  require_admissible=False).labels for o in range(A, smdp.n_actions)]
    return np.concatenate([prim, np.stack(own).astype(np.int64)])


def _option_partitioner(mdp: FiniteMDP, options: Sequence[Option], termination: np.ndarray,
                        delta: float) -> tuple[Any, Any]:
    """The options' SMDP (primitive actions first) and a multi-phase partitioner over it: what
    both layers split by."""
    from adpart.learning.smdp_q import option_set
    from adpart.partition import MultiPhasePartitioner

    _, smdp = option_set(mdp, list(options), include_primitives=True)
    return smdp, MultiPhasePartitioner(smdp, termination, delta=delta)


def expected_time_layer(
    inputs: HierarchyInputs, *, delta: float | None, c: float, max_steps: int | None = None,
) -> tuple[Partition, list[float], list[Step], float]:
    """Algorithm 3 over ``inputs``; returns ``(filled layer, trace, steps, its estimate)``.

    ``delta``: a block refined with an option is split by that option's delta-stable partition
    (:func:`stable_option_splits`); None splits by phase 1's initial blocks alone.
    """
    A = inputs.mdp.n_actions
    splits = (column_splits(inputs.admissible, inputs.termination) if delta is None
              else stable_option_splits(inputs.mdp, inputs.options, inputs.admissible,
                                        inputs.termination, delta=delta))
    result = greedy_hierarchy(
        inputs.tasks, inputs.admissible, n_primitives=A, splits=splits, c=c,
        max_steps=max_steps,
    )
    filled = fill_empty_blocks(result.partition, inputs.admissible, A)
    est = expected_time(inputs.tasks, filled, n_primitives=A, c=c).total
    return filled, result.trace, result.steps, est


def flat_estimate(inputs: HierarchyInputs, *, c: float) -> float:
    """``E[t_learn | flat]`` over the inputs' primitive actions (the "no abstraction" layer)."""
    return flat_time(inputs.admissible[:, :inputs.mdp.n_actions], c)


def all_subgoals_layer(
    inputs: HierarchyInputs, *, delta: float, c: float
) -> tuple[Partition, float]:
    """The seed's heuristic: multi-phase partition (phases 1-2) over every subgoal option.

    Every option is offered in every block where all states may start it; blocks left without
    one get the primitive actions (:func:`fill_empty_blocks`). Returns the layer over the
    inputs' columns and its ``E[t_learn]``.
    """
    from adpart.partition import refine
    from adpart.partition.partition import combine_labels

    if not inputs.options:
        raise TaskError(
            f"environment {inputs.environment!r} has no stored subgoal options; build them "
            "with `adpart options` first"
        )
    smdp, partitioner = _option_partitioner(inputs.mdp, inputs.options, inputs.termination,
                                            delta)
    cols = np.arange(inputs.mdp.n_actions, smdp.n_actions)
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



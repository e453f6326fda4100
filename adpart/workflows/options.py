"""Options to discovered subgoals: build them, compute their exact models, keep them in the KB.

The options of a subgoal set are built on the dynamics of the environment under the task whose
policy the subgoals came from (its gamma discounts the pseudo-reward and ``F``; its rewards give
``R``). ``F`` and the option itself are reward-independent and reused by later tasks; ``R`` is the
source task's and is recomputed for a new task (phase 3 of the partitioning does this).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from adpart.errors import TaskError
from adpart.execution import Executor
from adpart.mdp.model import FiniteMDP
from adpart.options.models import OptionModel, option_models
from adpart.options.option import Option
from adpart.options.subgoal_options import InitiationSettings, subgoal_options
from adpart.workflows.resolve import base_environment, resolve_domain
from adpart.workflows.store import KnowledgeStore


@dataclass(frozen=True, eq=False)
class StoredOptions:
    """Options with their exact models and the records that hold them."""

    records: list[Any]
    options: list[Option]
    models: list[OptionModel]
    reused: bool
    #: ``(subgoal state, why)`` of each subgoal left without an option (an empty initiation set)
    dropped: list[tuple[int, str]] = field(default_factory=list)


def environment_and_mdp(
    kb: KnowledgeStore, environment_id: int, task_id: int | None
) -> tuple[Any, Any, FiniteMDP]:
    """The environment record, its domain (checked against the stored dynamics) and the MDP."""
    env = kb.get("environment", environment_id)
    domain = resolve_domain(env.name)
    if domain.dynamics().content_hash != env.model_hash:
        raise TaskError(
            f"environment {env.name!r} in the knowledge base was recorded with other dynamics "
            f"(model hash {env.model_hash[:12]}) than the installed one "
            f"({domain.dynamics().content_hash[:12]}); use the adpart version that recorded it"
        )
    task_name = None
    if task_id is not None:
        task_name = kb.get("task", task_id).name
    return env, domain, domain.mdp(task_name)


def source_task_id(kb: KnowledgeStore, subgoal_set: Any) -> int | None:
    if subgoal_set.policy_id is None:
        return None
    return kb.get("policy", subgoal_set.policy_id).task_id


def options_for_subgoals(
    kb: KnowledgeStore,
    subgoal_set: Any,
    initiation: InitiationSettings | None = None,
    *,
    cover: bool = True,
    executor: Executor | None = None,
) -> StoredOptions:
    """Get-or-build the options to every subgoal of ``subgoal_set`` with exact models.

    Stored options serve decision layers, whose blocks must each offer an option, so ``local``
    sets are extended by default to cover every state that can reach a subgoal (``cover``,
    :func:`adpart.options.subgoal_options.subgoal_options`): without it, the states far from
    every subgoal fall back to primitive actions and phases 1-2 cut them into near-singletons
    (three-floor: 1,039 blocks against 63).

    Options already in the knowledge base for these subgoals with the same initiation rule (and,
    for ``local``, the same radius and cover) are loaded instead of rebuilt (``reused=True``).
    ``initiation`` defaults to ``InitiationSettings()``.
    """
    chosen = InitiationSettings() if initiation is None else initiation
    initiation, radius = chosen.initiation, chosen.radius
    rule: dict[str, Any] = {"initiation": initiation}
    if initiation == "local":
        rule["radius"] = radius
        rule["cover"] = bool(cover)
    task_id = source_task_id(kb, subgoal_set)
    env, _, mdp = environment_and_mdp(kb, subgoal_set.environment_id, task_id)
    wanted = dict(zip(subgoal_set.subgoal_ids, subgoal_set.states, strict=True))
    existing = [
        o
        for o in kb.options_for(env)
        if o.subgoal_id in wanted
        and all(o.provenance.parameters.get(k) == v for k, v in rule.items())
        and o.provenance.parameters.get("task_id") == task_id
    ]
    if wanted and {o.subgoal_id for o in existing} == set(wanted):
        by_subgoal = {o.subgoal_id: o for o in existing}
        records = [by_subgoal[i] for i in subgoal_set.subgoal_ids]
        options, models = load_options(kb, records)
        return StoredOptions(records, options, models, reused=True)
    states = np.asarray(subgoal_set.states, dtype=np.int64)
    dropped: list[tuple[int, str]] = []
    options = subgoal_options(mdp, states, initiation=initiation, radius=radius,
                              cover=bool(cover), dropped=dropped)
    if dropped and existing:  # stored before for every subgoal that has an option: reuse them
        by_subgoal = {o.subgoal_id: o for o in existing}
        kept = [i for i, state in wanted.items() if int(state) not in {d for d, _ in dropped}]
        if kept and set(kept) <= set(by_subgoal):
            loaded, loaded_models = load_options(kb, [by_subgoal[i] for i in kept])
            return StoredOptions([by_subgoal[i] for i in kept], loaded, loaded_models,
                                 reused=True, dropped=dropped)
    models = option_models(mdp, options, executor=executor, duration=False)
    subgoal_of_state = {int(s): i for i, s in wanted.items()}
    records = store_options(
        kb, env, mdp, options, models, plugin="adpart.options",
        subgoal=lambda o: subgoal_of_state[int(o.subgoal)],
        parameters=lambda o: {**rule, "task_id": task_id, "subgoal_set": subgoal_set.id,
                              "subgoal_state": int(o.subgoal)},
    )
    return StoredOptions(records, options, models, reused=False, dropped=dropped)


def store_options(
    kb: KnowledgeStore, env: Any, mdp: FiniteMDP, options: list[Option],
    models: list[OptionModel], *,
    plugin: str, parameters: Callable[[Option], dict[str, Any]],
    subgoal: Callable[[Option], int | None] = lambda option: None,
    name: Callable[[Option], str] = lambda option: option.name,
) -> list[Any]:
    """One option record per option, with its exact model (R, F), in one transaction.

    ``parameters(option)`` is the record's provenance, ``subgoal(option)`` its subgoal record id
    (None for an option to no stored subgoal), ``name(option)`` its name.
    """
    with kb.transaction():
        return [
            kb.put_option(env, name(option), initiation=option.initiation, policy=option.policy,
                          termination=option.beta, reward=model.R, transitions=model.F,
                          gamma=mdp.gamma, subgoal=subgoal(option), plugin=plugin,
                          parameters=parameters(option))
            for option, model in zip(options, models, strict=True)
        ]


def load_options(kb: KnowledgeStore, records: list[Any]) -> tuple[list[Option], list[OptionModel]]:
    """Options and their models back from their records (verified reads)."""
    options, models = [], []
    for rec in records:
        initiation = kb.load(rec, "initiation").astype(bool)
        option = Option(
            name=rec.name,
            initiation=initiation,
            policy=kb.load(rec, "policy"),
            beta=kb.load(rec, "termination"),
            subgoal=int(rec.provenance.parameters.get("subgoal_state", -1)),
            meta={"record": rec.ref},
        )
        F = kb.option_transitions(rec)
        R = kb.load(rec, "reward")
        if F is None or R is None:
            raise TaskError(f"{rec.ref} has no stored model; rebuild it with `adpart options`")
        S = initiation.shape[0]
        models.append(
            OptionModel(
                name=rec.name,
                R=R,
                F=F,
                duration=np.full(S, np.nan),
                admissible=initiation & (np.asarray(F.sum(axis=1)).ravel() > 0),  # I - terminals
            )
        )
        options.append(option)
    return options, models


@dataclass(frozen=True, eq=False)
class OptionSet:
    """The options a command was asked to use, with their records (empty for ``primitive``)."""

    records: list[Any]
    options: list[Option]
    models: list[OptionModel]
    primitive: bool

    @property
    def ids(self) -> list[int]:
        return [r.id for r in self.records]


def resolve_option_set(kb: KnowledgeStore, text: str, environment_name: str) -> OptionSet:
    """Parse ``--options``: ``subgoal-set:N`` (its stored options), ``option:1,option:2``, or
    ``primitive`` (the environment's primitive actions as one-step options).

    Raises:
        TaskError: malformed text, options of another environment, or a subgoal set whose options
            were never built (the message says to run ``adpart options``).
    """
    from adpart.workflows.refs import parse_ref

    text = text.strip()
    if text == "primitive":
        return OptionSet([], [], [], primitive=True)
    if text.startswith("subgoal-set:"):
        subgoal_set = kb.get("subgoal-set", parse_ref(text, "subgoal-set"))
        wanted = set(subgoal_set.subgoal_ids)
        records = [o for o in kb.options_for(subgoal_set.environment_id) if o.subgoal_id in wanted]
        latest: dict[int, Any] = {}
        for rec in records:  # the newest option per subgoal
            latest[rec.subgoal_id] = rec
        if set(latest) != wanted:
            raise TaskError(
                f"{subgoal_set.ref} has no stored options for every subgoal; build them with "
                f"`adpart options {environment_name} --subgoals {subgoal_set.ref}`"
            )
        records = [latest[i] for i in subgoal_set.subgoal_ids]
    else:
        records = [kb.get("option", parse_ref(part, "option")) for part in text.split(",") if part]
        if not records:
            raise TaskError(f"--options {text!r} names no option; write e.g. option:1,option:2")
    for rec in records:
        env = kb.get("environment", rec.environment_id)
        # an environment and its estimates (ENV@experience:...) share states and actions; one
        # record serves both where the estimate's model is the true one (environments are keyed
        # by their model's hash: a deterministic first task that tried every pair)
        if base_environment(env.name) != base_environment(environment_name):
            raise TaskError(
                f"{rec.ref} belongs to environment {env.name!r}, not {environment_name!r}"
            )
    options, models = load_options(kb, records)
    return OptionSet(records, options, models, primitive=False)

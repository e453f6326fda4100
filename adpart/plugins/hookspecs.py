"""Hook specifications for adpart plugins (project name and entry-point group ``adpart``).

A plugin is a module (or object) with functions marked ``@adpart.plugins.hookimpl`` whose names
match the hooks below. adpart's own built-ins are plugins of exactly this kind, registered through
the ``[project.entry-points.adpart]`` table of its ``pyproject.toml`` like any third-party package.

Every hook here is a *registration* hook: it is called once per process, when the registry is first
built (the first CLI command or :func:`adpart.plugins.get_registry` call), with a
:class:`~adpart.plugins.registry.Registrar` bound to the calling plugin. The hook registers zero or
more implementation classes and returns nothing. Each class must carry:

* ``name`` (str) - unique within its kind; stored in the knowledge base with every result;
* ``description`` (str) - one line for ``adpart plugins``;
* ``params`` (tuple of :class:`~adpart.plugins.registry.Param`) - declared parameters, which the
  CLI turns into ``--options`` and which are passed to the class's constructor as keywords;

and the call signature of its kind, documented on each hook below and in ``docs/plugins.md``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import pluggy

if TYPE_CHECKING:
    from adpart.plugins.registry import Registrar

PROJECT = "adpart"
hookspec = pluggy.HookspecMarker(PROJECT)
hookimpl = pluggy.HookimplMarker(PROJECT)


@hookspec
def register_environments(register: Registrar) -> None:
    """Register environment (domain) classes with ``register(cls)``.

    Each class subclasses :class:`adpart.envs.base.Domain`; ``cls()`` must build it with default
    parameters. Called once, when the registry is built.
    """


@hookspec
def register_learners(register: Registrar) -> None:
    """Register learner classes with ``register(cls)``.

    Call signature: ``cls(**params).learn(mdp, *, runs, episodes, seed, eval_every, progress)``
    returning an :class:`adpart.learning.LearnResult`-like object with ``Q`` (runs, S, A),
    ``curve`` (a LearningCurve) and ``seed``. ``mdp`` is a :class:`adpart.mdp.FiniteMDP`.
    """


@hookspec
def register_executors(register: Registrar) -> None:
    """Register executor classes with ``register(cls)``.

    Call signature: ``with cls(**params) as ex: ex.map(fn, items)`` returns ``[fn(i) for i in
    items]`` in order, possibly computed elsewhere; ``fn`` and items must be importable/serialisable
    by the executor (top-level functions and plain data for process pools).
    """


@hookspec
def register_subgoal_detectors(register: Registrar) -> None:
    """Register subgoal detector classes with ``register(cls)``.

    Call signature: ``cls(**params).detect(mdp, policy, rng)`` returning per-state scores and
    the subgoal states (section 4.1 of the dissertation).
    """


@hookspec
def register_partition_criteria(register: Registrar) -> None:
    """Register partition criterion classes with ``register(cls)``.

    Call signature: ``cls(**params).refine(partition, model, **context)`` returning a refined
    :class:`adpart.partition.Partition`; ``model`` is the options' stacked
    :class:`adpart.mdp.SMDPModel` and ``context`` may carry ``options``, ``rewards`` or
    ``termination`` (sections 3.2 and 4.2 of the dissertation).
    """


@hookspec
def register_hierarchy_estimators(register: Registrar) -> None:
    """Register hierarchy estimator classes with ``register(cls)``.

    Call signature: ``cls(**params).build(inputs)`` returning an unstored
    :class:`adpart.hierarchy.HierarchyResult` - the decision layer for the next task built from
    ``inputs``, an :class:`adpart.hierarchy.HierarchyInputs` holding the tasks learned so far and
    the candidate options (section 4.4 of the dissertation). A pure function of ``inputs``: the
    workflow loads them from the knowledge base and stores the layer.
    """

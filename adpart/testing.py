"""Conformance checks for plugin authors: run them on your classes, as ``check_env`` for Gymnasium.

Each ``check_*`` builds the class with its declared defaults, calls it on a small problem and
checks what comes back against an independent reference where one exists (the learner's
``v_star_start`` against value iteration, a criterion's result against the partition it
refines). A failed check raises :class:`ConformanceError` naming the plugin and the broken rule;
a passing check returns nothing. :func:`check_plugin` dispatches on a registry entry's kind and
:func:`check_registry` runs every installed plugin (adpart's CI runs it over the built-ins)::

    from adpart.testing import check_estimator, check_learner
    check_learner(MyLearner)                       # on two-rooms, 2 runs x 3 episodes
    check_estimator(MyEstimator)                   # on four-rooms' two tasks and doorways

The contracts themselves are :mod:`adpart.plugins.contracts`.
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Iterable
from typing import Any

import numpy as np

from adpart.envs.base import Domain
from adpart.errors import AdpartError, ModelError
from adpart.execution import Executor
from adpart.hierarchy.layers import HierarchyInputs, HierarchyResult
from adpart.hierarchy.settings import EstimateSettings
from adpart.hierarchy.tasks import task_from_model
from adpart.learning.curves import LearningCurve, start_distribution
from adpart.learning.result import LearnResult
from adpart.mdp.model import FiniteMDP
from adpart.mdp.solvers import q_from_v, solve
from adpart.params import Param
from adpart.partition.partition import Partition, block_all
from adpart.plugins.contracts import LEARNER_CONTEXT
from adpart.subgoals.result import SubgoalResult

__all__ = [
    "ConformanceError",
    "check_criterion",
    "check_detector",
    "check_environment",
    "check_estimator",
    "check_executor",
    "check_learner",
    "check_plugin",
    "check_plugin_class",
    "check_registry",
    "estimator_inputs",
]

#: The environment the checks run on when none is given (small, deterministic, two rooms).
DEFAULT_ENV = "two-rooms"
#: The environment the estimator checks run on when none is given (two tasks, four doorways).
ESTIMATOR_ENV = "four-rooms"


class ConformanceError(AdpartError, AssertionError):
    """A plugin class breaks its kind's contract; the message names the rule."""


def _fail(cls: type, rule: str) -> None:
    raise ConformanceError(f"{getattr(cls, 'name', cls.__name__)!r} ({cls.__qualname__}): {rule}")


def _start_value_by_iteration(mdp: FiniteMDP, sweeps: int = 200_000, tol: float = 1e-12) -> float:
    """``sum_s mu(s) V*(s)`` by plain Jacobi value iteration: a reference sharing no solver code.

    ``V <- max_a R(s, a) + gamma sum_s' P(s' | s, a) V(s')`` over admissible actions, with
    terminal states worth 0, from 0 until a sweep changes no value by more than ``tol``.
    """
    S, A = mdp.n_states, mdp.n_actions
    live = mdp.admissible & ~mdp.terminal[:, None]
    V = np.zeros(S)
    for _ in range(sweeps):
        Q = mdp.R.T + mdp.gamma * (mdp.P @ V).reshape(A, S)
        new = np.where(live.T, Q, -np.inf).max(axis=0)
        new[~live.any(axis=1)] = 0.0
        if np.max(np.abs(new - V)) <= tol:
            V = new
            break
        V = new
    return float(start_distribution(mdp) @ V)


def _default_mdp() -> FiniteMDP:
    from adpart.envs.registry import get_domain

    return get_domain(DEFAULT_ENV).mdp()


def check_plugin_class(cls: type) -> Any:
    """``name``, ``description``, ``params`` as the hookspecs say; returns ``cls(**defaults)``.

    Every declared parameter must be a constructor keyword whose default converts through its
    own declaration (so ``--help`` shows a value the plugin accepts).
    """
    name = getattr(cls, "name", None)
    if not isinstance(name, str) or not name or name != name.strip():
        _fail(cls, "class attribute `name` must be a non-empty string")
    if not isinstance(getattr(cls, "description", None), str):
        _fail(cls, "class attribute `description` must be a string (one line for `adpart plugins`)")
    params = getattr(cls, "params", ())
    if not isinstance(params, tuple) or not all(isinstance(p, Param) for p in params):
        _fail(cls, "class attribute `params` must be a tuple of adpart.params.Param")
    names = [p.name for p in params]
    if len(set(names)) != len(names):
        _fail(cls, f"parameter names repeat: {names}")
    signature = inspect.signature(cls)
    takes_any = any(p.kind is p.VAR_KEYWORD for p in signature.parameters.values())
    for p in params:
        if not takes_any and p.keyword not in signature.parameters:
            _fail(cls, f"declared parameter --{p.name} is not a constructor keyword {p.keyword!r}")
        try:
            p.convert(p.default, name)
        except AdpartError as exc:
            _fail(cls, f"the default of --{p.name} is refused by its own declaration: {exc}")
    try:
        return cls(**{p.keyword: p.default for p in params})
    except Exception as exc:  # noqa: BLE001 - any failure here is the plugin's
        _fail(cls, f"cls(**defaults) raised {type(exc).__name__}: {exc}")


def check_learner(cls: type, mdp: FiniteMDP | None = None, *, runs: int = 2, episodes: int = 3,
                  seed: int = 7) -> None:
    """A learner returns a :class:`LearnResult` of the asked shape, reproducibly.

    Checked: the result type and fields; ``Q`` is ``(runs, S, C)``; the curve has ``runs x
    episodes`` rows and finite value gaps ``>= -1e-6`` (no policy beats the optimum);
    ``v_star_start`` equals value iteration's ``sum_s mu(s) V*(s)``; the same seed gives the same
    curve; ``accepts`` lists only ``options`` and ``partition``. A learner with
    ``single_run = True`` (no randomness: the value-iteration reference) returns one run.
    """
    learner = check_plugin_class(cls)
    if not callable(getattr(learner, "learn", None)):
        _fail(cls, "a learner has a method learn(mdp, *, runs, episodes, seed, eval_every)")
    accepts = frozenset(getattr(cls, "accepts", ()))
    if not accepts <= LEARNER_CONTEXT:
        _fail(cls, f"`accepts` may list only {sorted(LEARNER_CONTEXT)}; got {sorted(accepts)}")
    mdp = mdp if mdp is not None else _default_mdp()
    kwargs: dict[str, Any] = {}
    if "options" in accepts:
        from adpart.options.option import primitive_options

        kwargs["options"] = primitive_options(mdp)

    def run() -> Any:
        return learner.learn(mdp, runs=runs, episodes=episodes, seed=seed, eval_every=1, **kwargs)

    result = run()
    if not isinstance(result, LearnResult):
        _fail(cls, f"learn() returned {type(result).__name__}, not an adpart.learning.LearnResult")
    runs = 1 if getattr(cls, "single_run", False) else runs
    Q = np.asarray(result.Q)
    if Q.ndim != 3 or Q.shape[:2] != (runs, mdp.n_states):
        _fail(cls, f"Q has shape {Q.shape}; expected ({runs}, {mdp.n_states}, C)")
    if not isinstance(result.curve, LearningCurve):
        _fail(cls, "result.curve is not a LearningCurve")
    gaps = result.curve.matrix("value_gap")
    if gaps.shape != (runs, episodes):
        _fail(cls, f"the curve has {gaps.shape} (runs, episodes); expected {(runs, episodes)}")
    if not np.isfinite(gaps).all() or (gaps < -1e-6).any():
        _fail(cls, "value gaps must be finite and >= 0 (no policy beats the optimal one)")
    reference = _start_value_by_iteration(mdp)
    if not math.isclose(result.v_star_start, reference, rel_tol=1e-6, abs_tol=1e-6):
        _fail(cls, f"v_star_start = {result.v_star_start} but value iteration gives {reference}")
    if not np.array_equal(run().curve.matrix("value_gap"), gaps):
        _fail(cls, "the same seed gave a different learning curve")


def check_detector(cls: type, mdp: FiniteMDP | None = None, policy: np.ndarray | None = None,
                   *, seed: int = 0) -> None:
    """A detector returns a :class:`SubgoalResult` of sorted, unique states, reproducibly.

    The default policy is the task's optimal one (value iteration's greedy policy).
    """
    detector = check_plugin_class(cls)
    if not callable(getattr(detector, "detect", None)):
        _fail(cls, "a subgoal detector has a method detect(mdp, policy, rng)")
    mdp = mdp if mdp is not None else _default_mdp()
    policy = policy if policy is not None else solve(mdp).policy
    out = detector.detect(mdp, policy, np.random.default_rng(seed))
    if not isinstance(out, SubgoalResult):
        _fail(cls, f"detect() returned {type(out).__name__}, not an adpart SubgoalResult")
    goals = np.asarray(out.subgoals)
    if goals.ndim != 1 or not np.issubdtype(goals.dtype, np.integer):
        _fail(cls, "subgoals must be a 1-d integer array of state ids")
    if goals.size and (goals.min() < 0 or goals.max() >= mdp.n_states):
        _fail(cls, f"subgoals must be state ids in [0, {mdp.n_states})")
    if not np.array_equal(goals, np.unique(goals)):
        _fail(cls, "subgoals must be sorted and unique")
    if np.asarray(out.scores).shape != (mdp.n_states,):
        _fail(cls, f"scores must have shape ({mdp.n_states},)")
    again = detector.detect(mdp, policy, np.random.default_rng(seed))
    if not np.array_equal(np.asarray(again.subgoals), goals):
        _fail(cls, "the same rng seed gave other subgoals")


def check_criterion(cls: type, mdp: FiniteMDP | None = None) -> None:
    """A criterion refines: every block it returns lies inside one block it was given.

    Run on the primitive actions' SMDP of ``mdp`` from the partition into reward-free and
    terminal states, with ``options`` (every column) as context.
    """
    criterion = check_plugin_class(cls)
    if not callable(getattr(criterion, "refine", None)):
        _fail(cls, "a partition criterion has a method refine(partition, model, **context)")
    from adpart.options.option import primitive_options
    from adpart.options.smdp import options_smdp

    mdp = mdp if mdp is not None else _default_mdp()
    model, _ = options_smdp(mdp, primitive_options(mdp), include_primitives=False)
    start = Partition.from_labels(mdp.terminal.astype(np.int64), model.admissible)
    out = criterion.refine(start, model, options=np.arange(model.n_actions), rewards=model.R,
                           termination=np.ones(model.admissible.shape, dtype=bool))
    if not isinstance(out, Partition):
        _fail(cls, f"refine() returned {type(out).__name__}, not a Partition")
    labels = np.asarray(out.labels)
    if labels.shape != (mdp.n_states,):
        _fail(cls, f"labels must have shape ({mdp.n_states},)")
    parents = np.full(out.n_blocks, -1)
    parents[labels] = start.labels
    if not np.array_equal(parents[labels], start.labels):
        _fail(cls, "a returned block mixes states of two input blocks (it must refine)")


def estimator_inputs(env: str = ESTIMATOR_ENV) -> HierarchyInputs:
    """Small real estimator inputs: every task of ``env`` learned exactly, options to its doors.

    Each task's Q is value iteration's; the options lead to the domain's doorway and stair cells
    (:func:`adpart.options.doorway_options`, none when it marks no doors). Task ids start at
    101 and option ids at 201, so a result that confuses ids with positions is caught.
    """
    from adpart.envs.registry import get_domain
    from adpart.options import doorway_options

    domain = get_domain(env)
    mdps = {name: domain.mdp(name) for name in domain.tasks()}
    first = next(iter(mdps.values()))
    try:
        options = doorway_options(first)
    except ModelError:  # no doorway or stair feature: the primitive actions only
        options = []
    tasks = [task_from_model(mdp, q_from_v(mdp, solve(mdp).V), options, threshold=0.0, name=name)
             for name, mdp in mdps.items()]
    inputs = HierarchyInputs.from_tasks(
        first, tasks, options, environment=env, task_ids=range(101, 101 + len(tasks)),
        option_ids=range(201, 201 + len(options)))
    default = EstimateSettings()
    return inputs.with_threshold(default.threshold, default.threshold_scale)


def _fingerprint(inputs: HierarchyInputs) -> list[Any]:
    """The inputs' contents, to see whether a build changed them."""
    arrays = [inputs.admissible, inputs.termination]
    for task in inputs.tasks:
        arrays += [task.Q, task.occupancy] + ([] if task.labels is None else [task.labels])
    for option in inputs.options:
        arrays += [option.initiation, option.policy, option.beta]
    return ([a.tobytes() for a in arrays] + [t.threshold for t in inputs.tasks]
            + [list(inputs.task_ids), list(inputs.option_ids), list(inputs.to_subgoal),
               list(inputs.action_names)])


def check_estimator(cls: type, inputs: HierarchyInputs | None = None) -> None:
    """An estimator returns an unstored layer over its inputs' columns, reproducibly, purely.

    Run on ``inputs`` (default: :func:`estimator_inputs`). Checked: the result is a
    :class:`HierarchyResult` named after the plugin; its partition labels every state and offers
    per block the primitive actions then its ``option_ids`` - ids of ``inputs.option_ids``, each
    once, in column order, with their names; every block offers a column all its states may
    start (the hierarchical learner needs a decision in every block); ``task_ids`` are the
    inputs'; ``partition_id`` is None (an estimator stores nothing); the estimate is finite and
    ``>= 0``; the same inputs give the same layer; and the inputs are unchanged afterwards.
    """
    estimator = check_plugin_class(cls)
    if not callable(getattr(estimator, "build", None)):
        _fail(cls, "a hierarchy estimator has a method build(inputs)")
    try:
        inspect.signature(estimator.build).bind(inputs)
    except TypeError as exc:
        _fail(cls, f"build{inspect.signature(estimator.build)} cannot be called as build(inputs) "
                   f"({exc}); an estimator is given the loaded inputs, not a knowledge base")
    inputs = inputs if inputs is not None else estimator_inputs()
    before = _fingerprint(inputs)
    out = estimator.build(inputs)
    if not isinstance(out, HierarchyResult):
        _fail(cls, f"build() returned {type(out).__name__}, not an adpart HierarchyResult "
                   "(adpart.hierarchy.layer_result builds one)")
    if _fingerprint(inputs) != before:
        _fail(cls, "build() changed its inputs; derive new ones instead "
                   "(inputs.with_threshold, inputs.select_options)")
    if out.estimator != cls.name:
        _fail(cls, f"the result names estimator {out.estimator!r}, not the plugin's name")
    part = out.partition
    if not isinstance(part, Partition):
        _fail(cls, f"result.partition is a {type(part).__name__}, not a Partition")
    S, A = inputs.mdp.n_states, inputs.mdp.n_actions
    if np.asarray(part.labels).shape != (S,):
        _fail(cls, f"the partition's labels must have shape ({S},)")
    position = {oid: k for k, oid in enumerate(inputs.option_ids)}
    used = [position.get(oid, -1) for oid in out.option_ids]
    if min(used, default=0) < 0 or used != sorted(set(used)):
        _fail(cls, f"option_ids {list(out.option_ids)} must be ids of inputs.option_ids, each "
                   "once, in column order")
    cols = np.r_[np.arange(A), A + np.asarray(used, dtype=np.int64)]
    if part.admissible.shape != (part.n_blocks, cols.size):
        _fail(cls, f"the partition offers {part.admissible.shape[1]} columns; expected "
                   f"{cols.size} (the {A} primitive actions, then option_ids)")
    if list(out.column_names) != [inputs.action_names[c] for c in cols]:
        _fail(cls, "column_names must name the primitive actions, then the options of option_ids")
    if not part.admissible.any(axis=1).all():
        _fail(cls, "a block offers no column (the learner needs a decision in every block)")
    if (part.admissible & ~block_all(part.labels, part.n_blocks, inputs.admissible[:, cols])).any():
        _fail(cls, "a block offers a column some of its states may not start")
    if list(out.task_ids) != list(inputs.task_ids):
        _fail(cls, f"task_ids {list(out.task_ids)} are not the inputs' {list(inputs.task_ids)}")
    if out.partition_id is not None:
        _fail(cls, "partition_id must be None: an estimator stores nothing (the workflow does)")
    if out.estimate is not None and not (math.isfinite(out.estimate) and out.estimate >= 0):
        _fail(cls, f"the estimate {out.estimate} must be a finite number >= 0")
    again = estimator.build(inputs)
    if not (np.array_equal(again.partition.labels, part.labels)
            and np.array_equal(again.partition.admissible, part.admissible)
            and list(again.option_ids) == list(out.option_ids)):
        _fail(cls, "the same inputs gave another layer")


def check_environment(cls: type) -> None:
    """An environment subclasses :class:`Domain`, builds by ``cls()``, and every task is an MDP.

    Each task's model passes :class:`FiniteMDP`'s own validation (stochastic rows, admissible
    actions in every non-terminal state) and shares the domain's dynamics.
    """
    if not (isinstance(cls, type) and issubclass(cls, Domain)):
        _fail(cls, "an environment class subclasses adpart.envs.base.Domain")
    domain = check_plugin_class(cls)
    dyn = domain.dynamics()
    tasks = domain.tasks()
    if not tasks:
        _fail(cls, "an environment defines at least one task")
    for name in tasks:
        mdp = domain.mdp(name)
        if (mdp.n_states, mdp.n_actions) != (dyn.n_states, dyn.n_actions):
            _fail(cls, f"task {name!r} has another state or action count than the dynamics")
        if not (mdp.admissible.any(axis=1) | mdp.terminal).all():
            _fail(cls, f"task {name!r} has a non-terminal state without an admissible action")


def check_executor(cls: type, items: Iterable[int] = (3, -1, 4, -1, -5, 9, -2, 6)) -> None:
    """An executor maps in order, as a context manager, and closes twice without error."""
    if not (isinstance(cls, type) and issubclass(cls, Executor)):
        _fail(cls, "an executor class subclasses adpart.execution.Executor")
    items = list(items)
    with check_plugin_class(cls) as ex:
        got = ex.map(abs, items)
    if list(got) != [abs(i) for i in items]:
        _fail(cls, f"map(abs, {items}) returned {list(got)}; results come back in item order")
    ex.close()


_CHECKS = {
    "learner": check_learner,
    "subgoal-detector": check_detector,
    "partition-criterion": check_criterion,
    "hierarchy-estimator": check_estimator,
    "environment": check_environment,
    "executor": check_executor,
}


def check_plugin(spec: Any) -> None:
    """Run the check of a registry entry's kind (:class:`adpart.plugins.PluginSpec`).

    A plugin that only fits some environments names one in ``example_environment``: learners,
    detectors and criteria then run on its default task, estimators on
    :func:`estimator_inputs` of it.
    """
    example = getattr(spec.factory, "example_environment", None)
    if spec.kind in {"learner", "subgoal-detector", "partition-criterion"} and example:
        from adpart.envs.registry import get_domain

        _CHECKS[spec.kind](spec.factory, get_domain(example).mdp())
        return
    if spec.kind == "hierarchy-estimator" and example:
        check_estimator(spec.factory, estimator_inputs(example))
        return
    if spec.kind not in _CHECKS:
        _fail(spec.factory, f"adpart.testing has no check for plugin kind {spec.kind!r}")
    _CHECKS[spec.kind](spec.factory)


def check_registry(registry: Any, kinds: Iterable[str] | None = None) -> list[str]:
    """Check every entry of ``registry`` (of ``kinds``); returns the failures, one line each."""
    failures = []
    for kind in kinds or registry.specs:
        for spec in registry.all(kind):
            try:
                check_plugin(spec)
            except ConformanceError as exc:
                failures.append(f"{kind} {exc}")
    return failures

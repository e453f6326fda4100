"""Conformance checks for plugin authors: run them on your classes, as ``check_env`` for Gymnasium.

Each ``check_*`` builds the class with its declared defaults, calls it on a small problem and
checks what comes back against an independent reference where one exists (the learner's
``v_star_start`` against value iteration, a criterion's result against the partition it
refines). A failed check raises :class:`ConformanceError` naming the plugin and the broken rule;
a passing check returns nothing. :func:`check_plugin` dispatches on a registry entry's kind and
:func:`check_registry` runs every installed plugin (adpart's CI runs it over the built-ins)::

    from adpart.testing import check_learner
    check_learner(MyLearner)                       # on two-rooms, 2 runs x 3 episodes

The contracts themselves are :mod:`adpart.plugins.contracts`.
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Iterable
from typing import Any

import numpy as np

from adpart.envs.base import Domain
from adpart.errors import AdpartError
from adpart.execution import Executor
from adpart.learning.curves import LearningCurve, start_distribution
from adpart.learning.result import LearnResult
from adpart.mdp.model import FiniteMDP
from adpart.mdp.solvers import solve
from adpart.params import Param
from adpart.partition.partition import Partition
from adpart.plugins.contracts import LEARNER_CONTEXT
from adpart.subgoals.result import SubgoalResult

__all__ = [
    "ConformanceError",
    "check_criterion",
    "check_detector",
    "check_environment",
    "check_executor",
    "check_learner",
    "check_plugin",
    "check_plugin_class",
    "check_registry",
]

#: The environment the checks run on when none is given (small, deterministic, two rooms).
DEFAULT_ENV = "two-rooms"


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
    model, _ = options_smdp(mdp, primitive_options(mdp))
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
    "environment": check_environment,
    "executor": check_executor,
}


def check_plugin(spec: Any) -> None:
    """Run the check of a registry entry's kind (:class:`adpart.plugins.PluginSpec`).

    ``hierarchy-estimator`` entries need a knowledge base with learned tasks; they get the
    class-level checks here (declarations and a ``build`` method).
    """
    example = getattr(spec.factory, "example_environment", None)
    if spec.kind in {"learner", "subgoal-detector", "partition-criterion"} and example:
        from adpart.envs.registry import get_domain

        _CHECKS[spec.kind](spec.factory, get_domain(example).mdp())
        return
    if spec.kind in _CHECKS:
        _CHECKS[spec.kind](spec.factory)
        return
    estimator = check_plugin_class(spec.factory)
    if not callable(getattr(estimator, "build", None)):
        _fail(spec.factory,
              "a hierarchy estimator has a method build(kb, environment, *, tasks, store)")


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

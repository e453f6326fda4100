"""Built-in hierarchy estimators ``expected-learning-time`` and ``all-subgoals`` (section 4.4).

Call signature (``register_hierarchy_estimators``): ``cls(**params).build(knowledge_base,
environment, *, tasks=None, store=True) -> HierarchyResult`` - the decision layer for the next task
of ``environment`` (its name in the knowledge base) from the tasks learned there so far (``tasks``
restricts them: names, ``task:N`` refs or ids), stored as a ``hierarchy`` partition unless
``store=False``. Both read and store through :mod:`adpart.workflows.hierarchy` and build with
:mod:`adpart.hierarchy.layers`; docs/hierarchy.md has the
formulas and interpretations.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

from adpart.errors import PluginError
from adpart.hierarchy.layers import (
    DEFAULT_DELTA,
    DEFAULT_THRESHOLD_SCALE,
    HierarchyResult,
    all_subgoals_layer,
    expected_time_layer,
    flat_estimate,
)
from adpart.params import Param
from adpart.plugins.hookspecs import hookimpl
from adpart.plugins.registry import Registrar
from adpart.workflows.hierarchy import finish, load_inputs

_COMMON = (
    Param("c", "float", 1.0, "constant c of T_conv = c |P|^2 |O|", min=0.0),
    Param("threshold", "float", -1.0,
          "significance margin L of P_refine; < 0 = threshold-scale x each task's value range"),
    Param("threshold-scale", "float", DEFAULT_THRESHOLD_SCALE,
          "default L as a fraction of each task's value range", min=0.0),
)


#: One text for both estimators' ``--delta`` (the command line shows one help per option).
_DELTA_HELP = ("delta of eq. 4.6: expected-learning-time splits a block refined with an option by "
               "the option's delta-stable partition (< 0: by its initiation and termination "
               "alone); all-subgoals refines its multi-phase partition to it")


def _delta_at_most_one(value: float) -> float:
    """Definition 4.4 bounds delta, a difference of transition masses, by 1."""
    if value > 1:
        raise PluginError(f"delta = {value} is above 1; it bounds a difference of probabilities")
    return value


class ExpectedLearningTime:
    """Algorithm 3: greedy (block, option) refinements minimising E[t_learn | P], or flat."""

    name = "expected-learning-time"
    description = "greedy layer minimising the expected learning time over learned tasks (4.4)"
    params = (*_COMMON,
              Param("delta", "float", DEFAULT_DELTA,
                    _DELTA_HELP, check=_delta_at_most_one),
              Param("max-steps", "int", 0, "cap on accepted refinements (0 = no cap)", min=0),
              Param("flat", "bool", True,
                    "compare with the flat MDP ('no abstraction'); fall back when it is cheaper"))

    def __init__(self, c: float = 1.0, threshold: float = -1.0,
                 threshold_scale: float = DEFAULT_THRESHOLD_SCALE, delta: float = DEFAULT_DELTA,
                 max_steps: int = 0, flat: bool = True) -> None:
        self.c, self.threshold, self.threshold_scale = c, threshold, threshold_scale
        self.delta, self.max_steps, self.flat = delta, max_steps, flat

    def build(self, knowledge_base: Any, environment: str, *,
              tasks: Sequence[str | int] | None = None, store: bool = True) -> HierarchyResult:
        t0 = time.perf_counter()
        inputs = load_inputs(knowledge_base, environment, tasks=tasks,
                             threshold=None if self.threshold < 0 else self.threshold,
                             threshold_scale=self.threshold_scale)
        t1 = time.perf_counter()
        layer, trace, steps, estimate = expected_time_layer(
            inputs, delta=None if self.delta < 0 else self.delta, c=self.c,
            max_steps=self.max_steps or None)
        t2 = time.perf_counter()
        params = {"c": self.c, "threshold": self.threshold,
                  "threshold_scale": self.threshold_scale, "delta": self.delta,
                  "max_steps": self.max_steps, "flat": self.flat}
        return finish(knowledge_base, inputs, layer, estimator=self.name, trace=trace,
                      steps=steps, estimate=estimate, parameters=params, store=store,
                      seconds={"inputs": t1 - t0, "construction": t2 - t1},
                      flat=flat_estimate(inputs, c=self.c) if self.flat else None)


class AllSubgoals:
    """The seed's heuristic: every subgoal option where admissible, multi-phase partition."""

    name = "all-subgoals"
    description = "every stored subgoal option in every block where admissible (phases 1-2)"
    params = (*_COMMON,
              Param("delta", "float", DEFAULT_DELTA,
                    _DELTA_HELP, min=0.0, check=_delta_at_most_one))

    def __init__(self, c: float = 1.0, threshold: float = -1.0,
                 threshold_scale: float = DEFAULT_THRESHOLD_SCALE,
                 delta: float = DEFAULT_DELTA) -> None:
        self.c, self.threshold, self.threshold_scale = c, threshold, threshold_scale
        self.delta = delta

    def build(self, knowledge_base: Any, environment: str, *,
              tasks: Sequence[str | int] | None = None, store: bool = True) -> HierarchyResult:
        t0 = time.perf_counter()
        inputs = load_inputs(knowledge_base, environment, tasks=tasks,
                             threshold=None if self.threshold < 0 else self.threshold,
                             threshold_scale=self.threshold_scale, subgoal_options_only=True)
        t1 = time.perf_counter()
        layer, estimate = all_subgoals_layer(inputs, delta=self.delta, c=self.c)
        t2 = time.perf_counter()
        params = {"c": self.c, "threshold": self.threshold,
                  "threshold_scale": self.threshold_scale, "delta": self.delta}
        return finish(knowledge_base, inputs, layer, estimator=self.name, trace=[estimate],
                      steps=[], estimate=estimate, parameters=params, store=store,
                      seconds={"inputs": t1 - t0, "construction": t2 - t1})


@hookimpl
def register_hierarchy_estimators(register: Registrar) -> None:
    register(ExpectedLearningTime)
    register(AllSubgoals)

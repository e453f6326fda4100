"""Built-in hierarchy estimators ``expected-learning-time`` and ``all-subgoals`` (section 4.4).

Call signature (``register_hierarchy_estimators``): ``cls(**params).build(inputs) ->
HierarchyResult`` - the decision layer for the next task from ``inputs``
(:class:`~adpart.hierarchy.layers.HierarchyInputs`: the tasks learned so far, their values over the
primitive actions and the candidate options, and the options), unstored. Both are pure functions
of the inputs built with :mod:`adpart.hierarchy.layers`; :mod:`adpart.workflows.hierarchy` loads
the inputs from a knowledge base and stores the layer. docs/hierarchy.md has the formulas and
interpretations.
"""

from __future__ import annotations

import time

from adpart.errors import PluginError
from adpart.hierarchy.layers import (
    DEFAULT_DELTA,
    DEFAULT_THRESHOLD_SCALE,
    HierarchyInputs,
    HierarchyResult,
    all_subgoals_layer,
    expected_time_layer,
    flat_estimate,
    layer_result,
)
from adpart.params import Param
from adpart.plugins.hookspecs import hookimpl
from adpart.plugins.registry import Registrar

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

    def build(self, inputs: HierarchyInputs) -> HierarchyResult:
        t0 = time.perf_counter()
        inputs = inputs.with_threshold(None if self.threshold < 0 else self.threshold,
                                       self.threshold_scale)
        layer, trace, steps, estimate = expected_time_layer(
            inputs, delta=None if self.delta < 0 else self.delta, c=self.c,
            max_steps=self.max_steps or None)
        flat = flat_estimate(inputs, c=self.c) if self.flat else None
        params = {"c": self.c, "threshold": self.threshold,
                  "threshold_scale": self.threshold_scale, "delta": self.delta,
                  "max_steps": self.max_steps, "flat": self.flat}
        return layer_result(inputs, layer, estimator=self.name, trace=trace, steps=steps,
                            estimate=estimate, parameters=params, flat=flat,
                            seconds={"construction": time.perf_counter() - t0})


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

    def build(self, inputs: HierarchyInputs) -> HierarchyResult:
        t0 = time.perf_counter()
        inputs = inputs.select_options(inputs.to_subgoal).with_threshold(
            None if self.threshold < 0 else self.threshold, self.threshold_scale)
        layer, estimate = all_subgoals_layer(inputs, delta=self.delta, c=self.c)
        params = {"c": self.c, "threshold": self.threshold,
                  "threshold_scale": self.threshold_scale, "delta": self.delta}
        return layer_result(inputs, layer, estimator=self.name, trace=[estimate], steps=[],
                            estimate=estimate, parameters=params,
                            seconds={"construction": time.perf_counter() - t0})


@hookimpl
def register_hierarchy_estimators(register: Registrar) -> None:
    register(ExpectedLearningTime)
    register(AllSubgoals)

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
from typing import TYPE_CHECKING

from adpart.errors import PluginError
from adpart.hierarchy.settings import EstimateSettings, ExpectedTimeSettings
from adpart.params import build_settings, settings_dict, settings_params
from adpart.plugins.hookspecs import hookimpl
from adpart.plugins.registry import Registrar

if TYPE_CHECKING:
    from adpart.hierarchy.layers import HierarchyInputs, HierarchyResult


class ExpectedLearningTime:
    """Algorithm 3: greedy (block, option) refinements minimising E[t_learn | P], or flat.

    Its parameters are :class:`~adpart.hierarchy.settings.ExpectedTimeSettings`' fields.
    """

    name = "expected-learning-time"
    description = "greedy layer minimising the expected learning time over learned tasks (4.4)"
    params = settings_params(ExpectedTimeSettings)

    def __init__(self, **values: object) -> None:
        self.settings = build_settings(ExpectedTimeSettings, values)

    def build(self, inputs: HierarchyInputs) -> HierarchyResult:
        from adpart.hierarchy.layers import expected_time_layer, flat_estimate, layer_result

        t0 = time.perf_counter()
        s, e = self.settings, self.settings.estimate
        inputs = inputs.with_threshold(e.threshold, e.threshold_scale)
        layer, trace, steps, estimate = expected_time_layer(
            inputs, delta=e.delta, c=e.c, max_steps=s.max_refinements or None)
        flat = flat_estimate(inputs, c=e.c) if s.flat else None
        return layer_result(inputs, layer, estimator=self.name, trace=trace, steps=steps,
                            estimate=estimate, parameters=settings_dict(s), flat=flat,
                            seconds={"construction": time.perf_counter() - t0})


class AllSubgoals:
    """The seed's heuristic: every subgoal option where admissible, multi-phase partition.

    Its parameters are :class:`~adpart.hierarchy.settings.EstimateSettings`' fields.
    """

    name = "all-subgoals"
    description = "every stored subgoal option in every block where admissible (phases 1-2)"
    params = settings_params(EstimateSettings)

    def __init__(self, **values: object) -> None:
        self.settings = build_settings(EstimateSettings, values)
        if self.settings.delta is None:
            raise PluginError("all-subgoals refines its multi-phase partition to delta: give a "
                              "number in [0, 1] (--delta 0.3)")

    def build(self, inputs: HierarchyInputs) -> HierarchyResult:
        from adpart.hierarchy.layers import all_subgoals_layer, layer_result

        t0 = time.perf_counter()
        e = self.settings
        inputs = inputs.select_options(inputs.to_subgoal).with_threshold(
            e.threshold, e.threshold_scale)
        layer, estimate = all_subgoals_layer(inputs, delta=float(e.delta), c=e.c)
        return layer_result(inputs, layer, estimator=self.name, trace=[estimate], steps=[],
                            estimate=estimate, parameters=settings_dict(e),
                            seconds={"construction": time.perf_counter() - t0})


@hookimpl
def register_hierarchy_estimators(register: Registrar) -> None:
    register(ExpectedLearningTime)
    register(AllSubgoals)

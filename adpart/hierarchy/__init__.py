"""Autonomous hierarchy construction (dissertation section 4.4).

* :mod:`adpart.hierarchy.tasks` - a learned task as the estimator sees it (Q over primitive
  actions and options, discounted block occupancies, importance weight);
* :mod:`adpart.hierarchy.estimator` - ``E[t_learn | P]`` of a layer (T_conv, P_refine);
* :mod:`adpart.hierarchy.greedy` - Algorithm 3, the greedy construction;
* :mod:`adpart.hierarchy.layers` - the decision layers Algorithm 3 and the all-subgoals heuristic
  build from learned tasks and options, as pure functions of them
  (:mod:`adpart.workflows.hierarchy` reads them from a knowledge base and stores the layer).
"""

from typing import TYPE_CHECKING

from adpart.lazy import lazy_exports

if TYPE_CHECKING:
    from adpart.hierarchy.estimator import (
        Estimate,
        expected_time,
        flat_time,
        good_columns,
        t_conv,
    )
    from adpart.hierarchy.greedy import GreedyResult, Step, column_splits, greedy_hierarchy
    from adpart.hierarchy.layers import (
        HierarchyInputs,
        HierarchyResult,
        all_subgoals_layer,
        expected_time_layer,
        layer_result,
    )
    from adpart.hierarchy.tasks import (
        LearnedTask,
        discounted_occupancy,
        option_values,
        task_from_model,
    )

lazy_exports(__name__, {
    "adpart.hierarchy.estimator": (
        "Estimate", "expected_time", "flat_time", "good_columns", "t_conv",
    ),
    "adpart.hierarchy.greedy": ("GreedyResult", "Step", "column_splits", "greedy_hierarchy"),
    "adpart.hierarchy.layers": (
        "HierarchyInputs", "HierarchyResult", "all_subgoals_layer", "expected_time_layer",
        "layer_result",
    ),
    "adpart.hierarchy.tasks": (
        "LearnedTask", "discounted_occupancy", "option_values", "task_from_model",
    ),
})

__all__ = [
    "Estimate",
    "GreedyResult",
    "HierarchyInputs",
    "HierarchyResult",
    "LearnedTask",
    "Step",
    "all_subgoals_layer",
    "column_splits",
    "discounted_occupancy",
    "expected_time",
    "expected_time_layer",
    "flat_time",
    "good_columns",
    "greedy_hierarchy",
    "layer_result",
    "option_values",
    "t_conv",
    "task_from_model",
]

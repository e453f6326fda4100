"""Autonomous hierarchy construction (dissertation section 4.4).

* :mod:`adpart.hierarchy.tasks` - a learned task as the estimator sees it (Q over primitive
  actions and options, discounted block occupancies, importance weight);
* :mod:`adpart.hierarchy.estimator` - ``E[t_learn | P]`` of a layer (T_conv, P_refine);
* :mod:`adpart.hierarchy.greedy` - Algorithm 3, the greedy construction;
* :mod:`adpart.hierarchy.kb` - the same over the tasks and options of a knowledge base.
"""

from adpart.hierarchy.estimator import (
    Estimate,
    expected_time,
    flat_time,
    good_columns,
    t_conv,
)
from adpart.hierarchy.greedy import GreedyResult, Step, column_splits, greedy_hierarchy
from adpart.hierarchy.kb import HierarchyResult, build_hierarchy, load_inputs
from adpart.hierarchy.tasks import (
    LearnedTask,
    discounted_occupancy,
    option_values,
    task_from_model,
)

__all__ = [
    "Estimate",
    "GreedyResult",
    "HierarchyResult",
    "LearnedTask",
    "Step",
    "build_hierarchy",
    "column_splits",
    "discounted_occupancy",
    "expected_time",
    "flat_time",
    "good_columns",
    "greedy_hierarchy",
    "load_inputs",
    "option_values",
    "t_conv",
    "task_from_model",
]

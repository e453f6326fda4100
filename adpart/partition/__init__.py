"""Action-dependent, multi-phase epsilon,delta-partitioning of the state space (section 4.2).

* :class:`Partition` - labels, per-block admissible options, intersect/refine/split/map values;
* :func:`refine` - delta-stability (eq. 4.6) and epsilon reward homogeneity (eq. 4.7);
* :func:`exact_lumping` - the delta = epsilon = 0 case by a splitter worklist;
* :func:`check_stability` - an independent checker of definition 4.4;
* :class:`MultiPhasePartitioner` - phases 1-3 of section 4.2.1.2, on the new task's model;
* :func:`reachable_states`, :func:`decision_rewards`, :func:`layer_counts` - partition hygiene
  (:mod:`adpart.partition.layer`: terminal block, unreachable states, eq. 4.7's rewards);
* :class:`BPSMDP` - interval models, interval value iteration and a point model (3.2.1, 4.3.3);
* :func:`check_delta`, :func:`check_epsilon`, :data:`DEFAULT_ATOL`, :func:`masked_rows`,
  :func:`block_rows` - the argument checks and the row selection the algorithms share, for
  callers that prepare inputs.
"""

from typing import TYPE_CHECKING

from adpart.lazy import lazy_exports

if TYPE_CHECKING:
    from adpart.partition._validate import (
        DEFAULT_ATOL,
        block_rows,
        check_delta,
        check_epsilon,
        masked_rows,
    )
    from adpart.partition.bpsmdp import (
        BPSMDP,
        IntervalValues,
        point_model,
        point_policy,
        theorem_4_5_bound,
        value_gap,
    )
    from adpart.partition.checker import StabilityReport, check_stability
    from adpart.partition.layer import decision_rewards, layer_counts, reachable_states
    from adpart.partition.lumping import exact_lumping
    from adpart.partition.multiphase import MultiPhasePartitioner, phase1, phase2, phase3
    from adpart.partition.partition import Partition, canonical_labels, combine_labels
    from adpart.partition.refine import refine

lazy_exports(__name__, {
    "adpart.partition._validate": (
        "DEFAULT_ATOL", "block_rows", "check_delta", "check_epsilon", "masked_rows",
    ),
    "adpart.partition.bpsmdp": (
        "BPSMDP", "IntervalValues", "point_model", "point_policy", "theorem_4_5_bound", "value_gap",
    ),
    "adpart.partition.checker": ("StabilityReport", "check_stability"),
    "adpart.partition.layer": ("decision_rewards", "layer_counts", "reachable_states"),
    "adpart.partition.lumping": ("exact_lumping",),
    "adpart.partition.multiphase": ("MultiPhasePartitioner", "phase1", "phase2", "phase3"),
    "adpart.partition.partition": ("Partition", "canonical_labels", "combine_labels"),
    "adpart.partition.refine": ("refine",),
})

__all__ = [
    "BPSMDP",
    "DEFAULT_ATOL",
    "IntervalValues",
    "MultiPhasePartitioner",
    "Partition",
    "StabilityReport",
    "block_rows",
    "canonical_labels",
    "check_delta",
    "check_epsilon",
    "check_stability",
    "combine_labels",
    "decision_rewards",
    "exact_lumping",
    "layer_counts",
    "masked_rows",
    "phase1",
    "phase2",
    "phase3",
    "point_model",
    "point_policy",
    "reachable_states",
    "refine",
    "theorem_4_5_bound",
    "value_gap",
]

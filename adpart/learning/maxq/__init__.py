"""MAXQ-Q (Dietterich 2000): declarative task graphs, the learner, and the built-in graphs.

See ``docs/maxq.md``. :class:`TaskGraph` / :class:`Subtask` describe a hierarchy,
:func:`maxq_q` learns it, :func:`get_graph` returns the built-in ``taxi`` and ``parr-maze`` graphs.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from adpart.lazy import lazy_exports

if TYPE_CHECKING:
    from adpart.learning.maxq.exact import (
        RecursiveSolution,
        polled_policy,
        reachable_states,
        recursively_optimal,
    )
    from adpart.learning.maxq.graphs import GRAPHS, get_graph, graph_for, parr_graph, taxi_graph
    from adpart.learning.maxq.maxq_q import (
        MaxQResult,
        MaxQTables,
        decomposed_values,
        greedy_hierarchical_policy,
        hierarchical_rollouts,
        maxq_q,
    )
    from adpart.learning.maxq.taskgraph import CompiledGraph, Subtask, TaskGraph

lazy_exports(__name__, {
    "adpart.learning.maxq.exact": (
        "RecursiveSolution", "polled_policy", "reachable_states", "recursively_optimal",
    ),
    "adpart.learning.maxq.graphs": ("GRAPHS", "get_graph", "graph_for", "parr_graph", "taxi_graph"),
    "adpart.learning.maxq.maxq_q": (
        "MaxQResult", "MaxQTables", "decomposed_values", "greedy_hierarchical_policy",
        "hierarchical_rollouts", "maxq_q",
    ),
    "adpart.learning.maxq.taskgraph": ("CompiledGraph", "Subtask", "TaskGraph"),
})

__all__ = [
    "GRAPHS",
    "CompiledGraph",
    "MaxQResult",
    "MaxQTables",
    "RecursiveSolution",
    "Subtask",
    "TaskGraph",
    "decomposed_values",
    "get_graph",
    "graph_for",
    "greedy_hierarchical_policy",
    "hierarchical_rollouts",
    "maxq_q",
    "parr_graph",
    "polled_policy",
    "reachable_states",
    "recursively_optimal",
    "taxi_graph",
]

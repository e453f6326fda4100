"""Which task graph MAXQ-Q learns over: the settings of :mod:`adpart.learning.maxq.graphs`.

Kept apart from the graphs (numpy) so that the command line builds ``--graph`` without them.
"""

from __future__ import annotations

from adpart.params import setting, settings

__all__ = ["GRAPH_NAMES", "GraphSettings"]

#: The built-in task graphs (:data:`adpart.learning.maxq.graphs.GRAPHS` builds each).
GRAPH_NAMES = ("taxi", "parr-maze")


@settings
class GraphSettings:
    """Which task graph MAXQ-Q learns over (Dietterich 2000; dissertation ch. 6)."""

    graph: str | None = setting(None, kind="str", none="auto", choices=GRAPH_NAMES)
    """Task graph (auto: picked from the MDP's features)."""
    abstraction: bool = setting(True)
    """Use the graph's state abstractions (Dietterich's max-node and leaf irrelevance)."""

"""Workflows: the library procedures the CLI, sweeps and experiments share.

They resolve names through the plugin registry, run the numeric cores, and record results in the
knowledge base; the CLI only parses arguments and prints.
"""

from typing import TYPE_CHECKING

from adpart.lazy import lazy_exports

if TYPE_CHECKING:
    from adpart.workflows.learning import (
        LearnOutcome,
        LearnRequest,
        find_learning,
        record_learning,
        run_learning,
        write_learning_outputs,
    )
    from adpart.workflows.resolve import resolve_domain

lazy_exports(__name__, {
    "adpart.workflows.learning": (
        "LearnOutcome", "LearnRequest", "find_learning", "record_learning", "run_learning",
        "write_learning_outputs",
    ),
    "adpart.workflows.resolve": ("resolve_domain",),
})

__all__ = [
    "LearnOutcome",
    "LearnRequest",
    "find_learning",
    "record_learning",
    "resolve_domain",
    "run_learning",
    "write_learning_outputs",
]

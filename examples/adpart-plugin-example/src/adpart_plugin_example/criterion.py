"""``capped-blocks``: delta-stability, then no block holds more than ``size`` states.

A decision layer whose blocks are large can put states far apart under one decision; some
researchers want layers whose blocks stay local. This criterion refines like adpart's
``bisimulation`` (delta-stability, eq. 4.6, and eq. 4.7 on the rewards it is given, with the same
settings, :class:`adpart.partition.settings.PartitionSettings`) and then cuts every block into
consecutive runs of at most ``size`` states in state order. The cut keeps it a refinement of the
partition it was given, as a partition criterion must be; it is no longer delta-stable, so the
next phase refines again.

``adpart partition ENV --options ID --criterion capped-blocks --criterion-opt size=8`` and
``adpart pipeline ... --criterion capped-blocks`` use it in every phase.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from adpart.params import Param, build_settings, settings_params
from adpart.partition import Partition
from adpart.partition.settings import PartitionSettings, StabilityCriterion
from adpart.plugins import hookimpl

__all__ = ["CappedBlocks", "capped_labels"]


def capped_labels(labels: np.ndarray, size: int) -> np.ndarray:
    """``(S,)`` the index of each state's run of ``size`` within its block, in state order."""
    order = np.argsort(labels, kind="stable")
    sorted_labels = labels[order]
    starts = np.r_[0, np.flatnonzero(np.diff(sorted_labels)) + 1]
    first = np.repeat(starts, np.diff(np.r_[starts, labels.size]))
    rank = np.empty_like(labels)
    rank[order] = np.arange(labels.size) - first
    return rank // size


class CappedBlocks(StabilityCriterion):
    """Delta-stability (eqs. 4.6-4.7), then blocks of at most ``size`` states."""

    name = "capped-blocks"
    description = "delta-stability, then no block larger than --size states (state order)"
    params = (*settings_params(PartitionSettings),
              Param("size", "int", 16, "the most states a block may hold", min=1))

    def __init__(self, size: int = 16, **values: Any) -> None:
        super().__init__(build_settings(PartitionSettings, values))
        self.size = int(size)

    def refine(self, partition: Partition, model: Any, **context: Any) -> Partition:
        stable = super().refine(partition, model, **context)
        return stable.refine_by(capped_labels(np.asarray(stable.labels), self.size))


@hookimpl
def register_partition_criteria(register) -> None:  # type: ignore[no-untyped-def]
    register(CappedBlocks)

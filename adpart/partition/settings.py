"""The settings of multi-phase epsilon,delta-partitioning (section 4.2), and the built-in criterion.

:class:`PartitionSettings` is the single declaration of the partition's ``delta`` (eq. 4.6) and
reward ``epsilon`` (eq. 4.7, phase 3): its defaults, ranges and help. The command line
(``adpart partition``, ``adpart pipeline``), the ``bisimulation`` partition-criterion plugin and
the stored provenance are derived from it. :class:`StabilityCriterion` is the criterion those
settings define - delta-stability in every phase, eq. 4.7 on the task's rewards in phase 3 - in
the :class:`~adpart.partition.multiphase.Criterion` form a partitioner takes.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from adpart.params import setting, settings

if TYPE_CHECKING:
    from adpart.partition.partition import Partition

__all__ = ["DEFAULT_ATOL", "DEFAULT_CRITERION", "PartitionSettings", "StabilityCriterion"]

#: Masses or rewards closer than this are equal: ``delta = 0`` means "equal up to rounding".
DEFAULT_ATOL = 1e-9

#: The partition-criterion plugin :class:`PartitionSettings` define (:class:`StabilityCriterion`).
DEFAULT_CRITERION = "bisimulation"


@settings
class PartitionSettings:
    """Thresholds of the epsilon,delta-partition (definition 4.4)."""

    delta: float = setting(0.3, min=0.0, max=1.0)
    """eq. 4.6: the largest spread of a block's discounted mass into another block, in [0, 1]
    (0: exact lumping)."""

    reward_epsilon: float = setting(10.0, min=0.0)
    """eq. 4.7: the largest spread of a block's option rewards beyond the step reward (phase
    3)."""


class StabilityCriterion:
    """Delta-stability (eq. 4.6) in phases 1-2, plus eq. 4.7 on the task's rewards in phase 3."""

    def __init__(self, settings: PartitionSettings, atol: float = DEFAULT_ATOL) -> None:
        self.settings, self.atol = settings, atol

    def refine(self, partition: Partition, model: Any, **context: Any) -> Partition:
        from adpart.partition.refine import refine

        rewards = context.get("rewards")
        return refine(partition, model, options=context.get("options"),
                      delta=self.settings.delta,
                      epsilon=self.settings.reward_epsilon if rewards is not None else None,
                      rewards=rewards, atol=self.atol,
                      require_admissible=bool(context.get("require_admissible", True)))

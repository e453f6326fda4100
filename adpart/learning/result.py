"""What every learner returns: the contract of a learner plugin's result.

A learner's result carries K runs' final values and their learning curve, scored as section
5.1's experiments score them: the exact value gap ``V*(start) - V^{pi_n}(start)`` of the greedy
policy after each episode. :class:`LearnResult` is the base every built-in result extends and the
type a third-party learner returns (``adpart.testing.check_learner`` checks the shapes).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from adpart.learning.curves import LearningCurve
from adpart.mdp.evaluation import greedy_policy

__all__ = ["LearnResult"]


@dataclass(frozen=True, eq=False, kw_only=True)
class LearnResult:
    """The fields the workflows, the store and the figures read of a learner's result.

    Attributes:
        Q: ``(K, S, C)`` float values of every run over the learner's ``C`` columns (primitive
            actions, or options); ``-inf`` where a column may not start.
        curve: the per-run, per-episode :class:`~adpart.learning.curves.LearningCurve`.
        seed: the seed actually used (recorded for provenance).
        v_star_start: ``sum_s mu(s) V*(s)``, the reference of the value gap.
        parameters: JSON-ready settings (schedules, limits, kernel) for provenance records.
    """

    Q: np.ndarray
    curve: LearningCurve
    seed: int
    v_star_start: float
    parameters: dict[str, object] = field(default_factory=dict)

    @property
    def runs(self) -> int:
        return int(self.Q.shape[0])

    def greedy_policies(self) -> np.ndarray:
        """``(K, S)`` int64 greedy columns (lowest index on ties), as evaluated."""
        K, S, C = self.Q.shape
        return greedy_policy(self.Q.reshape(K * S, C)).reshape(K, S)

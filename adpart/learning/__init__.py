"""Learners: flat Q-learning in lock-step, learning curves and step-size schedules.

Public API: :func:`q_learning` and its :class:`QLearningResult`; :class:`LearnResult`, the base of
every learner's result (the learner plugins' contract); :class:`LearningCurve` and
:func:`plot_curves`; the schedules :func:`constant`, :func:`visit_count`, :func:`exponential`
and :func:`parse_schedule`. See ``docs/learning.md``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from adpart.lazy import lazy_exports

if TYPE_CHECKING:
    from adpart.learning.curves import LearningCurve, plot_curves
    from adpart.learning.qlearning import QLearningResult, q_learning
    from adpart.learning.result import LearnResult
    from adpart.learning.schedules import (
        Schedule,
        constant,
        exponential,
        parse_schedule,
        visit_count,
    )

lazy_exports(__name__, {
    "adpart.learning.curves": ("LearningCurve", "plot_curves"),
    "adpart.learning.qlearning": ("QLearningResult", "q_learning"),
    "adpart.learning.result": ("LearnResult",),
    "adpart.learning.schedules": (
        "Schedule", "constant", "exponential", "parse_schedule", "visit_count",
    ),
})

__all__ = [
    "LearnResult",
    "LearningCurve",
    "QLearningResult",
    "Schedule",
    "constant",
    "exponential",
    "parse_schedule",
    "plot_curves",
    "q_learning",
    "visit_count",
]

"""Built-in MAXQ-Q learner plugin (Dietterich 2000; dissertation ch. 6)."""

from __future__ import annotations

from adpart.learning.maxq.learner import MaxQLearner
from adpart.plugins.hookspecs import hookimpl
from adpart.plugins.registry import Registrar


@hookimpl
def register_learners(register: Registrar) -> None:
    register(MaxQLearner)

"""The built-in ``maxq-q`` learner plugin: MAXQ-Q (Dietterich 2000; dissertation ch. 6) over a
built-in task graph (docs/maxq.md)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from adpart.learning.maxq.settings import GraphSettings
from adpart.learning.settings import Run
from adpart.params import build_settings, settings_params
from adpart.plugins.builtin.learners import RunLearner
from adpart.plugins.hookspecs import hookimpl
from adpart.plugins.registry import Registrar

if TYPE_CHECKING:
    from adpart.learning.maxq.maxq_q import MaxQResult
    from adpart.mdp.model import FiniteMDP


class MaxQLearner(RunLearner):
    """MAXQ-Q (Dietterich 2000) with the hierarchically greedy policy scored exactly per episode.

    Its parameters are :class:`~adpart.learning.maxq.settings.GraphSettings`' fields and the
    step-size, exploration and step-limit fields of :class:`~adpart.learning.settings.Run`.
    """

    name = "maxq-q"
    description = "MAXQ-Q hierarchical Q-learning over a task graph (taxi, taxi-fickle)"
    example_environment = "taxi"
    params = (*settings_params(GraphSettings),
              *settings_params(Run, only=("alpha", "epsilon", "max_steps_per_episode")))

    def __init__(self, **values: object) -> None:
        super().__init__(**values)
        self.settings = build_settings(GraphSettings, self.values)

    def learn_run(self, mdp: FiniteMDP, run: Run) -> MaxQResult:
        from adpart.learning.maxq.graphs import get_graph, graph_for
        from adpart.learning.maxq.maxq_q import maxq_q

        name = self.settings.graph or graph_for(mdp)
        compiled = get_graph(name).compile(mdp, abstraction=self.settings.abstraction)
        return maxq_q(mdp, compiled, run)


@hookimpl
def register_learners(register: Registrar) -> None:
    register(MaxQLearner)

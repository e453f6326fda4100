"""The built-in ``maxq-q`` learner plugin: MAXQ-Q (Dietterich 2000; dissertation ch. 6) over a
built-in task graph (docs/maxq.md)."""

from __future__ import annotations

from collections.abc import Callable

from adpart.learning.maxq.graphs import GRAPHS, get_graph, graph_for
from adpart.learning.maxq.maxq_q import MaxQResult, maxq_q
from adpart.mdp.model import FiniteMDP
from adpart.params import Param
from adpart.plugins.builtin.learners import MAX_STEPS
from adpart.plugins.hookspecs import hookimpl
from adpart.plugins.registry import Registrar


class MaxQLearner:
    """MAXQ-Q (Dietterich 2000) with the hierarchically greedy policy scored exactly per episode."""

    name = "maxq-q"
    description = "MAXQ-Q hierarchical Q-learning over a task graph (taxi, taxi-fickle)"
    example_environment = "taxi"
    params = (
        Param("graph", "str", "auto", "task graph; auto picks it from the MDP's features",
              choices=("auto", *GRAPHS)),
        Param("abstraction", "bool", True, "use the graph's state abstractions"),
        Param("alpha", "str", "0.5", "step-size schedule: 0.5 | 1/n^0.8 | exp:0.5,0.99"),
        Param("epsilon", "str", "0.1", "exploration schedule at every node, same forms"),
        MAX_STEPS,
    )

    def __init__(
        self,
        graph: str = "auto",
        abstraction: bool = True,
        alpha: str = "0.5",
        epsilon: str = "0.1",
        max_steps: int = 1000,
    ) -> None:
        self.graph, self.abstraction = graph, bool(abstraction)
        self.alpha, self.epsilon, self.max_steps = alpha, epsilon, max_steps

    def learn(
        self,
        mdp: FiniteMDP,
        *,
        runs: int,
        episodes: int,
        seed: int,
        eval_every: int,
        progress: Callable[[int, int], object] | None = None,
    ) -> MaxQResult:
        name = graph_for(mdp) if self.graph == "auto" else self.graph
        compiled = get_graph(name).compile(mdp, abstraction=self.abstraction)
        return maxq_q(
            mdp, compiled, runs=runs, episodes=episodes, seed=seed, alpha=self.alpha,
            epsilon=self.epsilon, max_steps_per_episode=self.max_steps, eval_every=eval_every,
            progress=progress,
        )


@hookimpl
def register_learners(register: Registrar) -> None:
    register(MaxQLearner)

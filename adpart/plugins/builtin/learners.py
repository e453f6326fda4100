"""Built-in learners: flat Q-learning (K runs at once) and the value-iteration reference."""

from __future__ import annotations

from collections.abc import Callable

from adpart.mdp.model import FiniteMDP
from adpart.params import Param
from adpart.plugins.hookspecs import hookimpl
from adpart.plugins.registry import Registrar


def _probability_schedule(what: str) -> Callable[[str], object]:
    """A validator: the spelling parses to a schedule that stays in [0, 1] (checked up front)."""
    def check(value: str) -> object:
        from adpart.learning.settings import schedule

        return schedule(value, what)

    return check


#: Parameters every sample-based learner declares alike (one declaration, one --help text).
ALPHA = Param("alpha", "str", "1/n^0.8", "step-size schedule: 0.1 | 1/n^0.8 | exp:0.5,0.99",
              check=_probability_schedule("alpha"))
EPSILON = Param("epsilon", "str", "0.1", "exploration schedule, same forms as --alpha",
                check=_probability_schedule("epsilon"))
MAX_STEPS = Param("max-steps", "int", 1000, "primitive-step limit of one episode", min=1)


#: The learners' starting value of every Q entry.
Q_INIT = 0.0


def q_init(what: str) -> Param:
    return Param("q-init", "float", Q_INIT, f"initial value of every {what}")


def kernel(*choices: str) -> Param:
    return Param("kernel", "str", "auto", "step kernel", choices=("auto", *choices))


class QLearner:
    """Flat epsilon-greedy Q-learning, K runs advanced together (see docs/learning.md)."""

    name = "q-learning"
    description = "flat epsilon-greedy Q-learning, all runs advanced together (numba, threaded)"
    params = (
        ALPHA,
        EPSILON,
        MAX_STEPS,
        q_init("Q(s, a)"),
        kernel("numba", "python"),
    )

    def __init__(
        self,
        alpha: str = "1/n^0.8",
        epsilon: str = "0.1",
        max_steps: int = 1000,
        q_init: float = 0.0,
        kernel: str = "auto",
    ) -> None:
        self.alpha, self.epsilon = alpha, epsilon
        self.max_steps, self.q_init = max_steps, q_init
        self.kernel = None if kernel == "auto" else kernel

    def learn(
        self,
        mdp: FiniteMDP,
        *,
        runs: int,
        episodes: int,
        seed: int,
        eval_every: int,
        progress: Callable[[int, int], object] | None = None,
    ) -> object:
        from adpart.learning.qlearning import q_learning

        return q_learning(
            mdp,
            runs=runs,
            episodes=episodes,
            seed=seed,
            alpha=self.alpha,
            epsilon=self.epsilon,
            max_steps_per_episode=self.max_steps,
            eval_every=eval_every,
            progress=progress,
            q_init=self.q_init,
            kernel=self.kernel,
        )


class ValueIterationLearner:
    """The model-based reference: one curve row per value-iteration sweep."""

    name = "value-iteration"
    description = "exact value iteration on the model (reference; one run, a row per sweep)"
    params = ()
    single_run = True

    def learn(
        self,
        mdp: FiniteMDP,
        *,
        runs: int,
        episodes: int,
        seed: int,
        eval_every: int,
        progress: Callable[[int, int], object] | None = None,
    ) -> object:
        from adpart.learning.reference import value_iteration_curve

        result = value_iteration_curve(mdp, sweeps=episodes, seed=seed)
        if progress is not None:
            progress(episodes, episodes)
        return result


@hookimpl
def register_learners(register: Registrar) -> None:
    register(QLearner)
    register(ValueIterationLearner)

"""Built-in learners: flat Q-learning (K runs at once) and the value-iteration reference."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from adpart.learning.settings import LEARNER_FIELDS, Run, SFGPISettings
from adpart.params import build_settings, settings_params
from adpart.plugins.hookspecs import hookimpl
from adpart.plugins.registry import Registrar

if TYPE_CHECKING:
    import numpy as np

    from adpart.mdp.experience import Experience
    from adpart.mdp.model import FiniteMDP

#: The parameters every sample-based learner takes: the update's fields of
#: :class:`~adpart.learning.settings.Run` (one declaration, one --help text).
LEARNER_PARAMS = settings_params(Run, only=LEARNER_FIELDS)
_RULE_KEYWORDS = frozenset(p.keyword for p in LEARNER_PARAMS)  # max_steps, q_init, ...


class RunLearner(ABC):
    """A learner plugin whose parameters include :data:`LEARNER_PARAMS`: it keeps them as a
    checked :class:`Run`, completes it with the experiment's settings at each :meth:`learn`
    and hands it to :meth:`learn_run`, the one method a subclass writes."""

    def __init__(self, **values: Any) -> None:
        rule = {k: values.pop(k) for k in list(values) if k in _RULE_KEYWORDS}
        self.rule = build_settings(Run, rule)
        self.values = values  # the plugin's own settings, for the subclass

    def run(self, *, runs: int, episodes: int, seed: int, eval_every: int,
            progress: Callable[[int, int], object] | None = None) -> Run:
        """The checked run settings of one call of ``learn``."""
        return replace(self.rule, runs=runs, episodes=episodes, seed=seed,
                       eval_every=eval_every, progress=progress)

    def learn(
        self,
        mdp: FiniteMDP,
        *,
        runs: int,
        episodes: int,
        seed: int,
        eval_every: int,
        progress: Callable[[int, int], object] | None = None,
        **inputs: Any,
    ) -> object:
        """The learner contract's ``learn``: :meth:`learn_run` with the completed :class:`Run`
        and the ``options``/``partition`` a learner that ``accepts`` them is given."""
        return self.learn_run(mdp, self.run(runs=runs, episodes=episodes, seed=seed,
                                            eval_every=eval_every, progress=progress), **inputs)

    @abstractmethod
    def learn_run(self, mdp: FiniteMDP, run: Run, **inputs: Any) -> object:
        """Learn ``mdp`` with the checked run settings ``run``."""


class QLearner(RunLearner):
    """Flat epsilon-greedy Q-learning, K runs advanced together (see docs/learning.md)."""

    name = "q-learning"
    description = "flat epsilon-greedy Q-learning, all runs advanced together (numba, threaded)"
    #: its result carries ``experience``, the transitions its runs took (the learned-model
    #: regime estimates the dynamics from them)
    records_experience = True
    params = LEARNER_PARAMS

    def learn_run(self, mdp: FiniteMDP, run: Run) -> object:
        from adpart.learning.qlearning import q_learning

        return q_learning(mdp, run)


class KnownDynamicsLearner(RunLearner):
    """Certainty-equivalent control with the true dynamics and observed rewards: the flat
    baseline that knows what a layer learner on the true model knows of the dynamics
    (:mod:`adpart.learning.model_based`)."""

    name = "known-dynamics"
    description = ("flat certainty-equivalent control: the true dynamics, rewards as observed "
                   "(optimistic where untried), re-planned after each episode")
    params = settings_params(Run, only=("epsilon", "max_steps_per_episode", "kernel"))

    def learn_run(self, mdp: FiniteMDP, run: Run) -> object:
        from adpart.learning.model_based import known_dynamics_learning

        return known_dynamics_learning(mdp, run)


class EstimatedDynamicsLearner(RunLearner):
    """Certainty-equivalent control on a counts model (earlier runs' experience, given as
    ``--model ENV@experience:run:N``, and its own steps) with observed rewards: the flat baseline
    that knows what a layer learner in the learned-model regime knows of the dynamics
    (:func:`adpart.learning.model_based.estimated_dynamics_learning`)."""

    name = "estimated-dynamics"
    description = ("flat certainty-equivalent control on the counts of earlier runs and its own "
                   "steps, rewards as observed (optimistic where untried)")
    params = settings_params(Run, only=("epsilon", "max_steps_per_episode", "kernel"))
    accepts = frozenset({"experience"})

    def learn_run(self, mdp: FiniteMDP, run: Run, experience: Experience | None = None
                  ) -> object:
        from adpart.learning.model_based import estimated_dynamics_learning

        return estimated_dynamics_learning(mdp, run, experience)


class SFGPILearner(RunLearner):
    """Successor features of the earlier runs' policies with generalised policy improvement
    (Barreto et al. 2017), the new task's reward weights learned online and its own Q-learning
    policy beside them (:mod:`adpart.learning.sf_gpi`). Given ``--model ENV@experience:run:N``,
    the successor features are computed on those runs' counts and transfer their greedy
    policies; without it there is nothing to transfer and it learns as Q-learning does."""

    name = "sf-gpi"
    description = ("successor features of the earlier runs' policies + GPI, reward weights "
                   "learned online (Barreto et al. 2017)")
    params = (*settings_params(SFGPISettings), *LEARNER_PARAMS)
    accepts = frozenset({"experience", "policies"})

    def __init__(self, **values: Any) -> None:
        super().__init__(**values)
        self.settings = build_settings(SFGPISettings, self.values)

    def learn_run(self, mdp: FiniteMDP, run: Run, experience: Experience | None = None,
                  policies: np.ndarray | None = None) -> object:
        from adpart.learning.sf_gpi import sf_gpi_learning

        if self.settings.dynamics == "true-model":
            experience = None  # the policies are the named runs'; the dynamics the true model
        return sf_gpi_learning(mdp, run, policies=policies, experience=experience)


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
    register(KnownDynamicsLearner)
    register(EstimatedDynamicsLearner)
    register(SFGPILearner)
    register(ValueIterationLearner)

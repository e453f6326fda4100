"""Built-in learner plugins ``smdp-q`` and ``hierarchical`` (docs/hierarchical-learning.md).

A plain ``learn(mdp, ...)`` call carries no options or partition, so both learners take them as
keywords of :meth:`learn` (``options=`` a list of :class:`adpart.options.Option`, ``partition=`` an
:class:`adpart.partition.Partition`); the CLI reads them from the knowledge base
(``adpart learn ENV --learner smdp-q --options ID``, ``--partition ID``). Without options
``smdp-q`` learns over the primitive actions alone (flat Q-learning in SMDP form) and
``hierarchical`` refuses to run.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from adpart.errors import TaskError
from adpart.learning.hierarchical_settings import HierarchicalSettings
from adpart.learning.result import LearnResult
from adpart.learning.smdp_q import SMDPQSettings
from adpart.mdp.model import FiniteMDP
from adpart.options.option import Option
from adpart.params import build_settings, settings_params
from adpart.partition.partition import Partition
from adpart.plugins.builtin.learners import ALPHA, EPSILON, MAX_STEPS, Q_INIT, kernel, q_init
from adpart.plugins.hookspecs import hookimpl
from adpart.plugins.registry import Registrar


class SMDPQLearner:
    """SMDP Q-learning over options, K runs in lock-step, scored exactly.

    Its parameters are :class:`~adpart.learning.smdp_q.SMDPQSettings`' fields and the run
    settings every learner takes.
    """

    name = "smdp-q"
    description = "SMDP Q-learning over options (plus primitive actions), runs in lock-step"
    accepts = frozenset({"options"})
    params = (
        ALPHA,
        EPSILON,
        *settings_params(SMDPQSettings),
        MAX_STEPS,
        q_init("Q(s, o)"),
        kernel("numba", "python"),
    )

    def __init__(self, alpha: str = ALPHA.default, epsilon: str = EPSILON.default,
                 max_steps: int = MAX_STEPS.default, q_init: float = Q_INIT, kernel: str = "auto",
                 **values: object) -> None:
        self.settings = build_settings(SMDPQSettings, values)
        self.alpha, self.epsilon = alpha, epsilon
        self.max_steps, self.q_init = max_steps, q_init
        self.kernel = None if kernel == "auto" else kernel

    def learn(self, mdp: FiniteMDP, *, runs: int, episodes: int, seed: int, eval_every: int,
              progress: Callable[[int, int], object] | None = None,
              options: Sequence[Option] | None = None,
              partition: Partition | None = None) -> LearnResult:
        from dataclasses import replace

        from adpart.learning.settings import Run
        from adpart.learning.smdp_q import smdp_q_learning

        opts = list(options or [])
        settings = self.settings if opts else replace(self.settings, include_primitives=True)
        run = Run(runs=runs, episodes=episodes, seed=seed, alpha=self.alpha,
                  epsilon=self.epsilon, max_steps_per_episode=self.max_steps,
                  eval_every=eval_every, q_init=self.q_init, kernel=self.kernel,
                  progress=progress)
        return smdp_q_learning(mdp, opts, settings, run)


class HierarchicalLearner:
    """Decision-layer learning with inconsistency refinement or its alternatives (4.3).

    Its parameters are :class:`~adpart.learning.hierarchical_settings.HierarchicalSettings`'
    fields (their defaults, ranges and help are declared there once) and the run settings every
    learner takes.
    """

    name = "hierarchical"
    description = "SMDP Q on a partition's blocks, refined where flat and abstract values disagree"
    accepts = frozenset({"options", "partition"})
    params = (
        *settings_params(HierarchicalSettings),
        ALPHA,
        EPSILON,
        MAX_STEPS,
        kernel("numba", "python"),
    )

    def __init__(self, alpha: str = ALPHA.default, epsilon: str = EPSILON.default,
                 max_steps: int = MAX_STEPS.default, kernel: str = "auto",
                 **values: object) -> None:
        self.settings = build_settings(HierarchicalSettings, values)
        self.alpha, self.epsilon, self.max_steps = alpha, epsilon, max_steps
        self.kernel = None if kernel == "auto" else kernel

    def learn(self, mdp: FiniteMDP, *, runs: int, episodes: int, seed: int, eval_every: int,
              progress: Callable[[int, int], object] | None = None,
              options: Sequence[Option] | None = None,
              partition: Partition | None = None) -> LearnResult:
        from adpart.learning.hierarchical import hierarchical_learning
        from adpart.learning.settings import Run

        if not options and not self.settings.reward_options:
            raise TaskError(
                "the hierarchical learner needs options (and optionally a partition); pass "
                "--options ID (and --partition ID) from the knowledge base, or use a "
                "reward-variation mode, which makes options to the task's reward states"
            )
        run = Run(runs=runs, episodes=episodes, seed=seed, alpha=self.alpha,
                  epsilon=self.epsilon, max_steps_per_episode=self.max_steps,
                  eval_every=eval_every, kernel=self.kernel, progress=progress)
        return hierarchical_learning(mdp, list(options or []), partition, self.settings, run)


@hookimpl
def register_learners(register: Registrar) -> None:
    register(SMDPQLearner)
    register(HierarchicalLearner)

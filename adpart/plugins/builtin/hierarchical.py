"""Built-in learner plugins ``smdp-q`` and ``hierarchical`` (docs/hierarchical-learning.md).

A plain ``learn(mdp, ...)`` call carries no options or partition, so both learners take them as
keywords of :meth:`learn` (``options=`` a list of :class:`adpart.options.Option`, ``partition=`` an
:class:`adpart.partition.Partition`); the CLI reads them from the knowledge base
(``adpart learn ENV --learner smdp-q --options ID``, ``--partition ID``). Without options
``smdp-q`` learns over the primitive actions alone (flat Q-learning in SMDP form) and
``hierarchical`` refuses to run.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from adpart.errors import TaskError
from adpart.learning.hierarchical_settings import HierarchicalSettings
from adpart.learning.settings import Run, SMDPQSettings
from adpart.params import build_settings, settings_params
from adpart.plugins.builtin.learners import LEARNER_PARAMS, RunLearner
from adpart.plugins.hookspecs import hookimpl
from adpart.plugins.registry import Registrar

if TYPE_CHECKING:
    from adpart.learning.result import LearnResult
    from adpart.mdp.model import FiniteMDP
    from adpart.options.option import Option
    from adpart.partition.partition import Partition


class SMDPQLearner(RunLearner):
    """SMDP Q-learning over options, K runs in lock-step, scored exactly.

    Its parameters are :class:`~adpart.learning.settings.SMDPQSettings`' fields and the run
    settings every learner takes.
    """

    name = "smdp-q"
    description = "SMDP Q-learning over options (plus primitive actions), runs in lock-step"
    #: ``experience`` (``--model ENV@experience:run:N``) names the estimated model its options
    #: were solved on, for its knowledge record; SMDP Q itself reads no model
    accepts = frozenset({"options", "experience"})
    params = (*settings_params(SMDPQSettings), *LEARNER_PARAMS)

    def __init__(self, **values: object) -> None:
        super().__init__(**values)
        self.settings = build_settings(SMDPQSettings, self.values)

    def learn_run(self, mdp: FiniteMDP, run: Run, options: Sequence[Option] | None = None,
                  partition: Partition | None = None, experience: object = None
                  ) -> LearnResult:
        from dataclasses import replace

        from adpart.learning.smdp_q import smdp_q_learning

        opts = list(options or [])
        settings = self.settings if opts else replace(self.settings, include_primitives=True)
        return smdp_q_learning(mdp, opts, settings, run)


class HierarchicalLearner(RunLearner):
    """Decision-layer learning with inconsistency refinement or its alternatives (4.3).

    Its parameters are :class:`~adpart.learning.hierarchical_settings.HierarchicalSettings`'
    fields (their defaults, ranges and help are declared there once) and the run settings every
    learner takes.
    """

    name = "hierarchical"
    description = "SMDP Q on a partition's blocks, refined where flat and abstract values disagree"
    accepts = frozenset({"options", "partition", "belief"})
    params = (*settings_params(HierarchicalSettings), *LEARNER_PARAMS)

    def __init__(self, **values: object) -> None:
        super().__init__(**values)
        self.settings = build_settings(HierarchicalSettings, self.values)

    def learn_run(self, mdp: FiniteMDP, run: Run, options: Sequence[Option] | None = None,
                  partition: Partition | None = None, belief: FiniteMDP | None = None
                  ) -> LearnResult:
        from adpart.learning.hierarchical import hierarchical_learning

        if not options and not self.settings.reward_options:
            raise TaskError(
                "the hierarchical learner needs options (and optionally a partition); pass "
                "--options ID (and --partition ID) from the knowledge base, or use a "
                "reward-variation mode, which makes options to the task's reward states"
            )
        return hierarchical_learning(mdp, list(options or []), partition, self.settings, run,
                                     belief=belief)


@hookimpl
def register_learners(register: Registrar) -> None:
    register(SMDPQLearner)
    register(HierarchicalLearner)

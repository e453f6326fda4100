"""Phase 3 of the partition done online, as the new task's rewards are observed (section 4.2).

Section 4.2: phases 1-2 "can be performed off-line ... prior to having knowledge of the specific
task"; phase 3, the split by the options' rewards (eq. 4.7), follows "once the task-specific
reward becomes available". In the learned-model regime the layer learner starts on phases 1-2
of the estimated model, and its belief (:func:`adpart.workflows.experience.belief_model`) holds
the earlier task's step reward and no terminal state. With ``online_phase3`` each run's belief
takes, at the end of every episode, what that run has observed:

* the reward of every pair it has tried - adpart pays ``R(s, a)`` on every step, so one try
  tells the pair's reward;
* every state an episode ended on arrival in - a successor R-max's counts hold (``xc``) that
  ended the episode.

Where that changes the run's belief, its option models are rebuilt on it (the option policies
stay; what they collect and where they end change), and every block holding a state whose
decision reward ``R~(s, o)`` (the reward beyond the step reward, eq. 4.7's quantity,
:func:`~adpart.learning.decision_layer.refinement_model`) or whose option model row changed is
refined with no new column: split by eq. 4.7 within the layer's ``epsilon`` and to
delta-stability (eq. 4.6), :func:`~adpart.learning.decision_layer.refine_block`. The true-model
regime's layer was built with phase 3 on the task's own rewards; this is the same criterion,
applied when the rewards it needs are known. The run's later refinements (4.3.3) split by its
updated model.

Pure: the caller reads what the run observed (inside :func:`~adpart.learning.knowledge.world`)
and installs the new layer in the kernel.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from adpart.learning.decision_layer import refine_block, refinement_model
from adpart.learning.smdp_q import option_set
from adpart.mdp.model import FiniteMDP, SMDPModel
from adpart.options.option import Option
from adpart.partition.layer import resolve_baseline
from adpart.partition.partition import Partition

__all__ = ["OnlinePhase3", "changed_states"]

#: a decision reward or model entry that moved by more than this has changed
CHANGE_ATOL = 1e-9


def changed_states(before: SMDPModel, after: SMDPModel, atol: float = CHANGE_ATOL
                   ) -> np.ndarray:
    """``(S,)`` the states where some column's reward or successor row differs between two
    models of the same columns (``F`` rows are ``column * S + state``)."""
    S = before.n_states
    moved = (np.abs(after.R - before.R) > atol).any(axis=1)
    diff = abs(after.F - before.F).sum(axis=1)
    rows = np.asarray(diff).reshape(-1, S) > atol  # (columns, S)
    return moved | rows.any(axis=0)


@dataclass
class OnlinePhase3:
    """Each run's belief of the task's rewards and terminal states, and phase 3 on it.

    Args:
        belief: the model the learner starts from (estimated dynamics, the earlier task's step
            reward, no terminal state).
        options: the layer's option columns after the primitive actions.
        base: the refinement model of ``belief`` (what every run splits by until it observes a
            reward or terminal state the belief lacks).
        delta, epsilon: the layer's thresholds (eqs. 4.6-4.7).
    """

    belief: FiniteMDP
    options: Sequence[Option]
    base: SMDPModel
    delta: float
    epsilon: float | None
    #: run -> its rewards, terminal states and refinement model, once they differ from belief's
    rewards: dict[int, np.ndarray] = field(default_factory=dict)
    terminal: dict[int, np.ndarray] = field(default_factory=dict)
    models: dict[int, SMDPModel] = field(default_factory=dict)

    def __post_init__(self) -> None:
        #: the step reward eq. 4.7's rewards are taken beyond: the belief's, fixed (the most
        #: common reward of what a run has seen could change with what it happens to try)
        self.step = resolve_baseline("mode", self.belief.R, self.belief.admissible,
                                     self.belief.terminal)

    def observe(self, k: int, partition: Partition, tried: np.ndarray,
                paid: np.ndarray, ended: np.ndarray
                ) -> tuple[Partition, np.ndarray] | None:
        """Take run ``k``'s observations into its belief and refine its layer where they change
        its option models.

        Args:
            partition: run ``k``'s layer now.
            tried: ``(S, A)`` the pairs the run has tried.
            paid: ``(S, A)`` the reward each tried pair paid (read only where ``tried``).
            ended: ``(S,)`` the states the run arrived in that ended an episode.

        Returns:
            ``(layer, split)``, the refined layer and the blocks of ``partition`` that were
            split, or None when the observations tell nothing new (the layer is unchanged).
        """
        rewards = self.rewards.get(k, self.belief.R)
        terminal = self.terminal.get(k, self.belief.terminal)
        new_rewards = np.where(tried, paid, rewards)
        new_terminal = terminal | ended
        if (np.array_equal(new_terminal, terminal)
                and not (np.abs(new_rewards - rewards) > CHANGE_ATOL).any()):
            return None
        self.rewards[k], self.terminal[k] = new_rewards, new_terminal
        seen = self.belief.with_rewards(new_rewards, terminal=new_terminal)
        smdp = option_set(seen, list(self.options), include_primitives=True)[1]
        model = refinement_model(seen, smdp, reward_baseline=self.step)
        moved = changed_states(self.models.get(k, self.base), model)
        self.models[k] = model
        split, first = np.unique(partition.labels[moved], return_index=True)
        layer = partition
        for s in np.flatnonzero(moved)[first]:  # one member of each block to split
            # (refine_block renumbers blocks; a block not yet split keeps its members)
            layer = refine_block(layer, int(layer.labels[s]), [], model, delta=self.delta,
                                 epsilon=self.epsilon)
        return layer, split

"""Reward-variation subgoals (section 4.3.1): states with a reward above the minimum.

With ``r_min = min {R(s, a)}`` over admissible pairs of non-terminal states, a state ``s`` is a
subgoal when ``R(s, a) > r_min`` for some admissible ``a`` (4.3.1; section 5.1.3 uses the level
``r_min = 0`` instead, which ``reward_level`` reproduces). adpart pays a goal's reward on the
*arrival* transition, i.e. in ``R(s, a)`` of the goal's predecessors, so with ``terminal_targets``
(default) the terminal states such a rewarded pair can reach are added too: they are the goal
states 4.3.1 wants among the subgoals. The result is added to a detected set with
:func:`with_reward_variation`. Both settings are
:class:`~adpart.subgoals.settings.RewardVariationSettings`'.
"""

from __future__ import annotations

import numpy as np

from adpart.mdp.model import FiniteMDP
from adpart.subgoals.policy import check_mdp
from adpart.subgoals.result import SubgoalResult
from adpart.subgoals.settings import RewardVariationSettings, given

#: Rewards within this distance of the level count as equal to it.
REWARD_ATOL = 1e-9


def reward_variation_states(
    mdp: FiniteMDP, settings: RewardVariationSettings | None = None
) -> np.ndarray:
    """Sorted int64 states whose reward exceeds ``settings.reward_level`` (None, the default:
    the minimum reward), with the terminal states they reach when ``terminal_targets``."""
    s = given(RewardVariationSettings, settings)
    mdp = check_mdp(mdp)
    live = mdp.admissible & ~mdp.terminal[:, None]
    if not live.any():
        return np.zeros(0, dtype=np.int64)
    floor = float(mdp.R[live].min()) if s.reward_level is None else s.reward_level
    high = live & (mdp.R > floor + REWARD_ATOL)
    states = np.flatnonzero(high.any(axis=1))
    if s.terminal_targets and high.any():
        S = mdp.n_states
        s_idx, a_idx = np.nonzero(high)
        reached = mdp.P[a_idx * S + s_idx]
        targets = np.unique(reached.indices[reached.data > 0])
        states = np.union1d(states, targets[mdp.terminal[targets]])
    return states.astype(np.int64)


def with_reward_variation(
    result: SubgoalResult, mdp: FiniteMDP, settings: RewardVariationSettings | None = None
) -> SubgoalResult:
    """``result`` with the reward-variation states added (scores and threshold unchanged)."""
    added = reward_variation_states(mdp, settings)
    stats = dict(result.stats)
    stats["reward_variation_states"] = added.tolist()
    stats["base_subgoals"] = result.subgoals.tolist()
    return SubgoalResult(
        np.union1d(result.subgoals, added), result.scores, result.threshold, stats,
        dict(result.params), result.detector,
    )

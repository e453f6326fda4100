"""Phase 3 online (issue 37): a belief's layer split by eq. 4.7 as the task's rewards are seen.

Independent checks: the option rewards of eq. 4.7 computed by walking each option step by step
on the deterministic two-rooms world (no linear algebra, no option model); the learner's reads
through the knowledge guard; and stopping the kernel after every episode, with nothing observed
that the belief lacks, changes nothing.
"""

from __future__ import annotations

import numpy as np
import pytest

from adpart.errors import TaskError
from adpart.learning import q_learning
from adpart.learning.decision_layer import refinement_model
from adpart.learning.hierarchical import hierarchical_learning
from adpart.learning.hierarchical_settings import HierarchicalSettings
from adpart.learning.knowledge import Knowledge, guard
from adpart.learning.online_phase3 import OnlinePhase3
from adpart.learning.settings import Run
from adpart.learning.smdp_q import option_set
from adpart.options.subgoal_options import subgoal_options
from adpart.params import build_settings
from adpart.partition import Partition
from adpart.partition.partition import row_codes
from adpart.workflows.experience import EstimatedDomain, belief_model
from adpart.workflows.resolve import resolve_domain

ATOL = 1e-6


@pytest.fixture(scope="module")
def world():
    """two-rooms' first task learned flat, the estimate, the new task, its belief, two options
    (to the doorway and to a cell of the far room) and a layer over them: a block per pattern of
    the options its states may start, the primitives where none starts."""
    domain = resolve_domain("two-rooms")
    learned = q_learning(domain.mdp("reach-goal"),
                         Run(runs=3, episodes=200, seed=3, alpha=1, epsilon=0.5))
    estimated = EstimatedDomain(domain, learned.experience, "two-rooms@experience:phase3")
    new = domain.mdp("goal:x=9,y=5")
    belief = belief_model(estimated, new, "reach-goal")
    options = subgoal_options(belief, [23, 40], initiation="reachable")
    full, smdp = option_set(belief, options, include_primitives=True)
    A = belief.n_actions
    starts = np.column_stack([o.initiation for o in options])
    labels = row_codes(starts)  # a block per pattern of options its states may start
    offers = np.zeros((int(labels.max()) + 1, A + len(options)), dtype=bool)
    offers[labels[:, None], A + np.arange(len(options))] = starts  # same within a block
    offers[~offers.any(axis=1), :A] = True  # where no option starts: the primitives
    return new, belief, options, Partition(labels, offers), full, smdp


def _walk_reward(mdp, option, s: int, rewards, terminal, step: float) -> float | None:
    """``R~(s, o)`` by walking the option on the deterministic world: the discounted rewards
    beyond the step reward until the option ends or the episode does (None: it may not start)."""
    if not option.initiation[s] or terminal[s]:
        return None
    P, S, g = mdp.P.tocsr(), mdp.n_states, mdp.gamma
    x, total, disc = s, 0.0, 1.0
    for _ in range(10 * S):
        a = int(option.policy[x])
        total += disc * (rewards[x, a] - step)
        x = int(P.indices[P.indptr[a * S + x]])
        disc *= g
        if terminal[x] or option.beta[x] == 1.0:
            return total
    raise AssertionError("the option never ended")


def test_seen_rewards_split_the_layer_until_every_block_meets_eq_4_7(world):
    new, belief, _, layer, full, smdp = world
    A, S = new.n_actions, new.n_states
    phase3 = OnlinePhase3(belief, full[A:], refinement_model(belief, smdp), 0.0, 0.0)
    tried = np.ones((S, A), dtype=bool)  # every pair tried: the task's rewards all seen
    found = phase3.observe(0, layer, tried, new.R, new.terminal)
    assert found is not None
    refined, split = found
    assert refined.n_blocks > layer.n_blocks and split.size
    assert np.array_equal(refined.parent_map(layer)[refined.labels], layer.labels)  # refines
    step = float(np.unique(belief.R)[0])
    for b in range(refined.n_blocks):
        members = np.flatnonzero((refined.labels == b) & ~new.terminal)
        if members.size == 0:  # the goal, split off: no decision there
            continue
        for col in np.flatnonzero(refined.admissible[b]):
            if col < A:  # a primitive: its reward beyond the step reward
                seen = new.R[members, col] - step
            else:
                seen = np.array([_walk_reward(new, full[col], int(s), new.R, new.terminal, step)
                                 for s in members])
            assert np.ptp(seen) <= ATOL, (b, col)
    # observing the same again tells nothing new
    assert phase3.observe(0, refined, tried, new.R, new.terminal) is None
    # another run has seen nothing yet: its belief is the prior's
    assert 1 not in phase3.models


def test_a_run_that_saw_only_the_step_reward_keeps_its_layer(world):
    new, belief, _, layer, full, smdp = world
    A, S = new.n_actions, new.n_states
    phase3 = OnlinePhase3(belief, full[A:], refinement_model(belief, smdp), 0.0, 0.0)
    tried = np.zeros((S, A), dtype=bool)
    tried[tuple(np.argwhere(belief.R == new.R)[:30].T)] = True  # pairs paying the step only
    assert phase3.observe(0, layer, tried, new.R, np.zeros(S, dtype=bool)) is None


def test_online_phase3_learns_on_the_belief_reading_only_what_it_saw(world):
    new, belief, options, layer, _, _ = world
    settings = build_settings(HierarchicalSettings, {
        "threshold": 0.5, "explore": "r-max", "value-ceiling": 20.0, "online-phase3": True})
    run = Run(runs=2, episodes=25, seed=2, alpha=1, epsilon=0.1)
    guarded = guard(new, Knowledge("estimated", "observed"))
    result = hierarchical_learning(guarded, options, layer, settings, run, belief=belief)
    meta = result.curve.metadata
    assert meta["online_phase3"] is True
    events = meta["phase3_events"]
    assert events and all(e["blocks_after"] >= e["blocks_before"] for e in events)
    assert {e["run"] for e in events} == {0, 1}
    assert meta["phase3_blocks"] == [sum(e["blocks_after"] - e["blocks_before"]
                                         for e in events if e["run"] == k) for k in (0, 1)]
    assert any("phase 3 online" in use for use in meta["knowledge"]["uses"])
    assert all(p.n_blocks >= layer.n_blocks for p in result.partitions)


def test_stopping_after_every_episode_changes_nothing_when_nothing_new_is_seen(world):
    """The task is the belief itself (its step reward everywhere, no terminal state): phase 3
    online sees nothing the belief lacks, so its per-episode stops leave every run as without
    it."""
    _, belief, options, layer, _, _ = world
    run = Run(runs=2, episodes=6, seed=7, alpha=1, epsilon=0.2, max_steps_per_episode=60,
              eval_every=3)
    common = {"threshold": 0.5, "explore": "r-max", "value-ceiling": 5.0}
    off = hierarchical_learning(belief, options, layer, build_settings(
        HierarchicalSettings, common), run, belief=belief)
    on = hierarchical_learning(belief, options, layer, build_settings(
        HierarchicalSettings, {**common, "online-phase3": True}), run, belief=belief)
    assert on.curve.metadata["phase3_events"] == []
    for key in ("steps", "decisions", "return", "eval_value"):
        assert np.array_equal(on.curve[key], off.curve[key], equal_nan=True), key
    assert np.array_equal(on.Q, off.Q)


def test_online_phase3_needs_a_belief_and_r_max(world):
    new, belief, options, layer, _, _ = world
    run = Run(runs=1, episodes=2, seed=0)
    with pytest.raises(TaskError, match="--regime learned-model"):
        hierarchical_learning(new, options, layer, build_settings(
            HierarchicalSettings, {"online-phase3": True}), run)
    with pytest.raises(TaskError, match="--explore r-max"):
        hierarchical_learning(new, options, layer, build_settings(
            HierarchicalSettings, {"threshold": 0.5, "online-phase3": True}), run,
            belief=belief)

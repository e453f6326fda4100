"""Partition sizes of the transfer setting (section 5.1) and their reasons (issue 15, item 3).

Options are stored under the first task (the pipeline's default initiation sets), the layer is
built for the new task by :func:`partition_environment`. The subgoals are those the pipeline's
detector found in a flat-learned first-task policy (seed 0): ``count-exhaustive`` on three-floor's
reach-goal, ``count-mc`` on urban's navigate-2.

* three-floor -> reach-top-west: before, phase 2 gave 26-27 blocks and the epsilon = 10 reward
  split 56-78 (R(s, o) with -1 a step is the discounted path length; local or basin initiation
  sets); the split on the rewards beyond the step reward adds no block.
* urban -> navigate-pickup: before, the 6,668 load-2 states the task cannot reach were 6,668
  singletons and its 6,668 terminal states sat in 6,665 blocks; the decision layer now counts only
  reachable, non-terminal blocks. The oracle for reachability is a plain BFS over the task's
  primitive transitions.
"""

from __future__ import annotations

from collections import deque

import numpy as np
import pytest

from adpart.envs.registry import get_domain
from adpart.partition.settings import PartitionSettings
from adpart.store import KnowledgeBase
from adpart.workflows.options import options_for_subgoals
from adpart.workflows.partitioning import environment_record, partition_environment, task_record

URBAN_SUBGOALS = (8853, 9402, 15618)
THREE_FLOOR_SUBGOALS = (1424, 1642, 1742, 2080, 2183, 2749)


def layer_for(tmp_path, env_name, first_task, subgoals, task, **kwargs):
    """Store options to ``subgoals`` under ``first_task``; partition ``env_name`` for ``task``."""
    kb = KnowledgeBase.open(str(tmp_path / "kb"))
    try:
        domain, env = environment_record(kb, env_name)
        _, _, first = task_record(kb, domain, env, first_task)
        pi = np.zeros(domain.dynamics().n_states, np.int64)  # the options need only its task
        policy = kb.put_policy(first, "given", pi=pi)
        subgoal_set = kb.put_subgoal_set(env, "given", list(subgoals), policy=policy)
        options_for_subgoals(kb, subgoal_set)
        return partition_environment(kb, env_name, subgoal_set.ref,
                                     PartitionSettings(delta=0.3, reward_epsilon=10.0),
                                     task=task, **kwargs)
    finally:
        kb.close()


def bfs(mdp) -> np.ndarray:
    S = mdp.n_states
    P = mdp.P.tocsr()
    seen = np.zeros(S, dtype=bool)
    queue = deque(int(s) for s in np.flatnonzero((mdp.initial > 0) & ~mdp.terminal))
    seen[list(queue)] = True
    while queue:
        s = queue.popleft()
        if mdp.terminal[s]:
            continue
        for a in range(mdp.n_actions):
            row = a * S + s
            for t in P.indices[P.indptr[row]:P.indptr[row + 1]]:
                if not seen[t]:
                    seen[t] = True
                    queue.append(int(t))
    return seen


@pytest.mark.slow
def test_three_floor_layer_is_small_and_the_step_cost_cuts_no_bands(tmp_path):
    out = layer_for(tmp_path, "three-floor", "reach-goal", THREE_FLOOR_SUBGOALS,
                    "reach-top-west")
    s = out.summary()
    assert s["phase3"]["blocks"] == s["phase2"]["blocks"] <= 40 and s["check"]["ok"]
    assert s["layer"]["phase3"]["terminal"] == 1 and s["layer"]["phase3"]["unreachable"] == 0
    raw = layer_for(tmp_path, "three-floor", "reach-goal", THREE_FLOOR_SUBGOALS,
                    "reach-top-west", reward_baseline="none")
    assert raw.phase2.blocks == out.phase2.blocks
    assert raw.phase3.blocks > 2 * out.phase3.blocks  # the path-length bands of R itself


@pytest.mark.slow
def test_urban_decision_layer_counts_reachable_non_terminal_blocks(tmp_path):
    out = layer_for(tmp_path, "urban", "navigate-2", URBAN_SUBGOALS, "navigate-pickup")
    mdp = get_domain("urban").mdp("navigate-pickup")
    reach = bfs(mdp)
    assert np.array_equal(out.unreachable, ~reach & ~mdp.terminal)
    s = out.summary()
    layer = s["layer"]["phase3"]
    assert layer["terminal"] == 1 and layer["terminal_states"] == int(mdp.terminal.sum()) == 6668
    assert layer["unreachable"] == 1 and layer["unreachable_states"] == 6668
    assert s["final"]["decision_blocks"] == layer["reachable"] == out.final.n_blocks - 2
    assert layer["reachable"] <= 40 and s["check"]["ok"]
    # the decision layer's blocks hold only reachable non-terminal states
    live = reach & ~mdp.terminal
    decision = np.unique(out.final.labels[live])
    assert not np.isin(out.final.labels[~live], decision).any()

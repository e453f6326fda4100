"""The inconsistency test on an action the block already offers (``split_offered``).

A block's point model picks one column for all its states. Where its states need different
columns, the block's policy fails some of them although the action they need is offered, so the
test as 4.3.3 writes it (``a*`` not yet in ``A_B``) never fires there. The oracle domain: a
deterministic corridor of 7 cells, -1 a step, the terminal goal in the middle, and one block of
all six other cells offering both moves (accepted with delta = 1). The block's point model sends
every cell the same way, so the cells on the other side walk into the wall for ever.
"""

from __future__ import annotations

import numpy as np
import pytest

from adpart.errors import TaskError
from adpart.learning.hierarchical import (
    flat_lower_bound,
    refine_block,
    refinement_model,
)
from adpart.mdp.evaluation import policy_evaluation
from adpart.mdp.model import FiniteMDP
from adpart.mdp.solvers import q_from_v, solve
from adpart.partition import Partition
from adpart.partition.bpsmdp import point_policy

from .hierarchical_run import hierarchical_run
from .test_hierarchical import DELTA, setup  # noqa: F401

CELLS, GOAL, HORIZON = 7, 3, 50
RUN = {"delta": 1.0, "partition_epsilon": None, "runs": 3, "episodes": 60, "seed": 0,
       "eval_every": 10,
       "explore": "r-max", "reference": "policy", "refine": "block", "layer_values": "planned",
       "max_steps_per_episode": HORIZON}


def corridor(gamma: float = 0.95) -> FiniteMDP:
    P = np.zeros((CELLS, 2, CELLS))
    for s in range(CELLS):
        P[s, 0, max(s - 1, 0)] = P[s, 1, min(s + 1, CELLS - 1)] = 1.0
    terminal = np.arange(CELLS) == GOAL
    start = np.where(terminal, 0.0, 1.0)
    return FiniteMDP.from_dense(P, np.full((CELLS, 2), -1.0), gamma, terminal=terminal,
                                initial=start / start.sum(), action_names=("W", "E"),
                                name="corridor")


def one_block() -> Partition:
    """The goal alone, every other cell in one block offering both moves."""
    return Partition((np.arange(CELLS) == GOAL).astype(np.int64), np.ones((2, 2), dtype=bool))


def final_gap(result) -> np.ndarray:
    return result.curve.matrix("value_gap")[:, -1]


def test_the_block_policy_fails_half_the_corridor_and_the_seeds_test_cannot_see_it():
    mdp = corridor()
    smdp = mdp.as_smdp()
    best = point_policy(one_block(), smdp)
    lower = flat_lower_bound(mdp, HORIZON)
    values = policy_evaluation(smdp, best, never=lower)
    assert len(set(best[np.arange(CELLS) != GOAL].tolist())) == 1  # one move for the block
    assert np.isclose(values, lower).sum() == 3  # the three cells on the other side never arrive
    off = hierarchical_run(mdp, [], one_block(), **RUN)
    assert off.refinements == []  # both moves are offered: the seed's test never fires
    assert (final_gap(off) > 0.05 * abs(off.v_star_start)).all()


def test_splitting_where_an_offered_action_beats_the_layer_policy_reaches_the_optimum():
    """Every firing on an offered action is real: replayed on the layer as it stood, the action's
    ``Q*`` beats the value from the state of the layer's best block policy by more than ``L``;
    the final layer's best policy is optimal and every run's greedy policy exact."""
    mdp = corridor()
    smdp = mdp.as_smdp()
    on = hierarchical_run(mdp, [], one_block(), split_offered=True, **RUN)
    assert on.parameters["split_offered"] is True
    np.testing.assert_allclose(final_gap(on), 0.0, atol=1e-9)
    q_star = q_from_v(mdp, solve(mdp, 1e-12).V)
    lower, L = flat_lower_bound(mdp, HORIZON), on.parameters["threshold"]
    refiner = refinement_model(mdp, smdp)
    for k in range(RUN["runs"]):
        layer = one_block()
        events = [e for e in on.refinements if e["run"] == k]
        assert events and all(e["offered"] for e in events)
        for e in events:
            s, a = e["state"], e["action"]
            best = point_policy(layer, smdp)
            assert q_star[s, a] - policy_evaluation(smdp, best, never=lower)[s] > L
            layer = refine_block(layer, e["block"], [a], refiner, delta=1.0, epsilon=None, at=s)
            assert layer.sizes[layer.labels[s]] == 1
        assert layer.n_blocks == on.partitions[k].n_blocks
        np.testing.assert_array_equal(layer.labels, on.partitions[k].labels)


def test_the_kernels_agree_when_splitting_offered_actions():
    mdp = corridor()
    kw = dict(RUN, split_offered=True, runs=2, episodes=30)
    a = hierarchical_run(mdp, [], one_block(), kernel="numba", **kw)
    b = hierarchical_run(mdp, [], one_block(), kernel="python", **kw)
    assert a.refinements == b.refinements and a.refinements
    np.testing.assert_array_equal(a.Q, b.Q)
    np.testing.assert_array_equal(a.blocks, b.blocks)


def test_refine_block_at_a_state_with_an_offered_column_splits_it_off_with_the_blocks_set(setup):  # noqa: F811
    """``s`` becomes a block of its own offering its block's set; the rest keeps that set and is
    delta-stable against the refined layer (the independent checker, eq. 4.6); the other blocks
    are unchanged."""
    from adpart.partition.checker import check_stability

    _, _, part, smdp = setup
    b = int(np.argmax(part.sizes))
    offered = int(np.flatnonzero(part.admissible[b])[0])
    s = int(part.members(b)[0])
    new = refine_block(part, b, [offered], smdp, delta=DELTA, epsilon=0.0, at=s)
    parent = new.parent_map(part)
    assert new.sizes[new.labels[s]] == 1
    kids = np.flatnonzero(parent == b)
    for kid in kids:
        np.testing.assert_array_equal(new.admissible[kid], part.admissible[b])
    for child in np.flatnonzero(parent != b):
        assert np.array_equal(new.members(child), part.members(parent[child]))
    report = check_stability(new, smdp, delta=DELTA)
    assert not [v for v in report.violations if v.block in set(kids.tolist())]


def test_split_offered_needs_the_policy_reference():
    with pytest.raises(TaskError, match="give reference = policy"):
        hierarchical_run(corridor(), [], one_block(), **dict(RUN, reference="offered"),
                              split_offered=True)

"""Intra-option learning (Sutton, Precup & Singh 1999): hand-computed values and reductions."""

from __future__ import annotations

import numpy as np
import pytest

from adpart.envs.registry import get_domain
from adpart.learning import q_learning
from adpart.learning.settings import Run
from adpart.mdp.model import FiniteMDP
from adpart.options import Option, hallway_options, primitive_options
from tests.learning.conftest import corridor, slippery_grid
from tests.learning.hierarchical_run import smdp_q_run

GAMMA = 0.9


def right_chain() -> FiniteMDP:
    """States 0..6 on a line, actions left/right, -1 a step, 6 terminal, episodes start at 0."""
    S, A = 7, 2
    P = np.zeros((S, A, S))
    for s in range(S):
        P[s, 0, max(s - 1, 0)] = 1.0
        P[s, 1, min(s + 1, S - 1)] = 1.0
    terminal = np.zeros(S, dtype=bool)
    terminal[6] = True
    initial = np.zeros(S)
    initial[0] = 1.0
    return FiniteMDP.from_dense(P, -np.ones((S, A)), GAMMA, terminal=terminal, initial=initial)


def go_right(mdp: FiniteMDP, name: str, states: list[int]) -> Option:
    init = np.zeros(mdp.n_states, dtype=bool)
    init[states] = True
    return Option(name, init, np.ones(mdp.n_states, dtype=np.int64), (~init).astype(float))


def truncated_cost(steps: int) -> float:
    """-(1 + gamma + ... + gamma^(steps-1))."""
    return -float(sum(GAMMA**i for i in range(steps)))


@pytest.mark.parametrize("episodes", [1, 2, 3, 6])
def test_hand_computed_values_after_each_episode(episodes):
    """One option runs 0 -> 6; a second one, never chosen, is consistent on 3..5.

    With alpha = 1 each step sets Q(s, o) = -1 + gamma U(s + 1, o) from the values the previous
    episode left, so after n episodes Q(s, o) = -(1 + ... + gamma^(min(n, 6 - s) - 1)): the value
    travels one state back per episode, for the option being run and for the one that is not.
    """
    mdp = right_chain()
    run_it = go_right(mdp, "whole", [0, 1, 2, 3, 4, 5])
    bystander = go_right(mdp, "tail", [3, 4, 5])
    res = smdp_q_run(mdp, [run_it, bystander], runs=1, episodes=episodes, seed=0,
                          alpha=1.0, epsilon=0.0, eval_every=episodes, intra_option=True)
    Q = res.Q[0]
    for s in range(6):
        assert Q[s, 0] == pytest.approx(truncated_cost(min(episodes, 6 - s)))
    for s in (3, 4, 5):
        assert Q[s, 1] == pytest.approx(truncated_cost(min(episodes, 6 - s)))
    assert res.visits[0, :6, 0].tolist() == [episodes] * 6
    assert res.visits[0, :, 1].tolist() == [0, 0, 0, episodes, episodes, episodes, 0]
    assert res.curve["decisions"].tolist() == [1] * episodes  # one decision an episode


def test_without_intra_only_the_start_pair_learns():
    mdp = right_chain()
    res = smdp_q_run(mdp, [go_right(mdp, "whole", [0, 1, 2, 3, 4, 5]),
                                go_right(mdp, "tail", [3, 4, 5])],
                          runs=1, episodes=3, seed=0, alpha=1.0, epsilon=0.0, eval_every=3)
    Q = res.Q[0]
    assert Q[0, 0] == pytest.approx(truncated_cost(6))  # the SMDP return of the whole run
    assert (Q[1:6, 0] == 0.0).all() and (Q[3:6, 1] == 0.0).all()


@pytest.mark.parametrize("make", [corridor, slippery_grid])
def test_primitive_options_with_intra_are_still_flat_q_learning(make):
    """A primitive action's one-step option is the only option consistent with its step."""
    mdp = make()
    flat = q_learning(mdp, Run(runs=3, episodes=25, seed=11, eval_every=5))
    intra = smdp_q_run(mdp, primitive_options(mdp), runs=3, episodes=25, seed=11,
                            eval_every=5, intra_option=True)
    np.testing.assert_array_equal(intra.Q, flat.Q)
    np.testing.assert_array_equal(intra.curve["steps"], flat.curve["steps"])


def test_kernels_agree_with_intra_option_updates():
    mdp = get_domain("four-rooms").mdp("G1")
    opts = hallway_options(mdp)
    kw = {"include_primitives": True, "runs": 2, "episodes": 15, "seed": 4, "eval_every": 5,
          "intra_option": True}
    a = smdp_q_run(mdp, opts, kernel="python", **kw)
    b = smdp_q_run(mdp, opts, kernel="numba", **kw)
    np.testing.assert_array_equal(a.Q, b.Q)
    np.testing.assert_array_equal(a.visits, b.visits)
    plain = smdp_q_run(mdp, opts, kernel="numba", **{**kw, "intra_option": False})
    assert a.visits.sum() > plain.visits.sum()  # options learn from steps they did not take


def test_block_layer_virtual_executions_by_hand():
    """Mode 2 (decision layers): an option the agent's steps follow gets its SMDP update.

    Singleton blocks on the chain, no test, greedy: the agent runs "whole" from 0 to the goal.
    "tail" (offered on 3..5) is never chosen, but the steps from 3 follow its policy, so it is
    executed virtually from 3 and gets the SMDP return of its three steps, -(1 + g + g^2).
    """
    from adpart.partition import Partition
    from tests.learning.hierarchical_run import hierarchical_run

    mdp = right_chain()
    whole = go_right(mdp, "whole", [0, 1, 2, 3, 4, 5])
    tail = go_right(mdp, "tail", [3, 4, 5])
    admissible = np.stack([whole.initiation, tail.initiation], axis=1)
    admissible[6] = True
    layer = Partition(np.arange(7), admissible)
    kw = {"runs": 1, "episodes": 1, "seed": 0, "alpha": 1.0, "epsilon": 0.0,
          "eval_every": 1, "threshold": np.inf, "explore": "columns"}
    res = hierarchical_run(mdp, [whole, tail], layer, intra_option=True, **kw)
    Q = res.block_Q[0]
    A = mdp.n_actions
    assert Q[0, A] == pytest.approx(truncated_cost(6))  # the option run
    assert Q[3, A + 1] == pytest.approx(truncated_cost(3))  # its virtual execution from 3
    assert Q[4, A + 1] == 0.0 and Q[5, A + 1] == 0.0  # one virtual run at a time
    plain = hierarchical_run(mdp, [whole, tail], layer, intra_option=False, **kw)
    assert plain.block_Q[0][3, A + 1] == 0.0

"""Option validation, bad input, primitive options, and basins on a hand-checkable chain."""

from __future__ import annotations

import numpy as np
import pytest

from adpart.errors import ModelError
from adpart.mdp.model import FiniteMDP
from adpart.options import (
    Option,
    basin,
    option_model,
    primitive_options,
    reachable_set,
    sample_option_model,
    subgoal_option,
    subgoal_options,
)


def chain_mdp() -> FiniteMDP:
    """States 0..6 on a line (actions left=0, right=1, deterministic), plus a trap 7.

    Action 2 ("jump") moves 0 -> 7 and is a self-loop elsewhere; 7 only loops on itself.
    State 6 is terminal.
    """
    S, A = 8, 3
    P = np.zeros((S, A, S))
    for s in range(7):
        P[s, 0, max(s - 1, 0)] = 1.0
        P[s, 1, min(s + 1, 6)] = 1.0
        P[s, 2, 7 if s == 0 else s] = 1.0
    P[7, :, 7] = 1.0
    R = -np.ones((S, A))
    terminal = np.zeros(S, dtype=bool)
    terminal[6] = True
    return FiniteMDP.from_dense(P, R, 0.9, terminal=terminal, action_names=("L", "R", "J"))


def test_basin_by_hand():
    mdp = chain_mdp()
    # Subgoals 2 and 5: 2's basin is 0, 1 (left of it), 3, 4 (between), and 5 as a start only.
    b2 = basin(mdp, 2, [2, 5])
    assert np.flatnonzero(b2).tolist() == [0, 1, 3, 4, 5]
    # 5's basin: 3, 4 and the other subgoal 2 as a start; 6 is terminal, 7 cannot reach it,
    # and 0, 1 would have to pass through subgoal 2.
    b5 = basin(mdp, 5, [2, 5])
    assert np.flatnonzero(b5).tolist() == [2, 3, 4]
    assert np.flatnonzero(reachable_set(mdp, 5)).tolist() == [0, 1, 2, 3, 4]


def test_subgoal_option_by_hand():
    mdp = chain_mdp()
    opts = subgoal_options(mdp, [2, 5])
    o5 = opts[1]
    assert o5.name == "to-5" and o5.subgoal == 5
    # It continues only inside the basin: beta = 1 at the subgoal, at the other subgoal (2, a
    # start state of I) and outside I.
    assert np.flatnonzero(o5.beta == 0).tolist() == [3, 4]
    assert o5.policy[[2, 3, 4]].tolist() == [1, 1, 1]  # go right
    m = option_model(mdp, o5)
    # From 2: three steps right, reward -1 each, F = gamma^3 at 5.
    assert m.R[2] == pytest.approx(-(1 + 0.9 + 0.81))
    assert m.F[2, 5] == pytest.approx(0.9**3)
    assert m.duration[[2, 3, 4]].tolist() == pytest.approx([3, 2, 1])
    assert not m.admissible[[0, 1, 5, 6, 7]].any()
    assert m.R[0] == 0.0 and m.F[[0]].nnz == 0


def test_beta_one_start_takes_one_step():
    """Started where beta = 1, an option still acts once; beta counts only on arrival."""
    mdp = chain_mdp()
    o = Option("right-once", np.ones(8, bool), np.ones(8, dtype=np.int64), np.ones(8))
    m = option_model(mdp, o)
    assert m.F[3, 4] == pytest.approx(0.9) and m.duration[3] == 1.0
    assert m.R[6] == 0.0 and not m.admissible[6]  # terminal: not admissible, zero row


def test_primitive_options_match_one_step_model():
    mdp = chain_mdp()
    for a, o in enumerate(primitive_options(mdp)):
        m = option_model(mdp, o)
        prim = mdp.as_smdp()
        rows = prim.F[a * 8:(a + 1) * 8]
        assert abs(m.F - rows).max() < 1e-15
        keep = ~mdp.terminal
        assert np.array_equal(m.R[keep], prim.R[keep, a])
        assert np.all(m.duration[keep] == 1.0)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"initiation": np.ones((8, 1), bool)}, "initiation mask has shape"),
        ({"initiation": np.ones(8, int)}, "must be boolean"),
        ({"initiation": np.zeros(8, bool)}, "empty initiation set"),
        ({"beta": np.full(8, 1.5)}, r"beta\[0\] = 1.5 is not a probability"),
        ({"beta": np.full(7, 1.0)}, "beta has shape"),
        ({"beta": np.full(8, np.nan)}, "not a probability"),
        ({"policy": np.ones(8)}, "deterministic policy must be 8 integers"),
        ({"policy": np.full(8, -1)}, "policy is undefined in state 0"),
        ({"policy": np.full((8, 3), 0.5)}, "sums to 1.5"),
        ({"policy": -np.ones((8, 3))}, "not a non-negative number"),
        ({"policy": np.full(8, -3)}, "is not an action"),
    ],
)
def test_bad_option_input(kwargs, match):
    base = {"initiation": np.ones(8, bool), "policy": np.ones(8, dtype=np.int64),
            "beta": np.ones(8)}
    base.update(kwargs)
    with pytest.raises(ModelError, match=match) as info:
        Option("bad", **base)
    assert "'bad'" in str(info.value)


def test_option_against_wrong_mdp_and_inadmissible_actions():
    S, A = 3, 2
    P = np.zeros((S, A, S))
    P[:, :, 0] = 1.0
    adm = np.ones((S, A), bool)
    adm[1, 1] = False
    mdp = FiniteMDP.from_dense(P, np.zeros((S, A)), 0.9, admissible=adm, action_names=("a", "b"))
    o = Option("uses-b", np.ones(S, bool), np.ones(S, dtype=np.int64), np.ones(S))
    with pytest.raises(ModelError, match=r"'uses-b'.*inadmissible action 'b' \(1\) in state 1"):
        option_model(mdp, o)
    o = Option("big", np.ones(S, bool), np.full(S, 5), np.ones(S))
    with pytest.raises(ModelError, match=r"'big'.*action 5 in state 0.*0..1"):
        option_model(mdp, o)
    stoch = np.zeros((S, A))
    stoch[:, 1] = 1.0
    o = Option("stoch", np.ones(S, bool), stoch, np.ones(S))
    with pytest.raises(ModelError, match=r"'stoch'.*inadmissible action 'b' \(1\) in state 1"):
        option_model(mdp, o)
    o = Option("small", np.ones(4, bool), np.zeros(4, dtype=np.int64), np.ones(4))
    with pytest.raises(ModelError, match="'small' is defined over 4 states"):
        option_model(mdp, o)


def test_never_terminating_option_names_option_and_state():
    mdp = chain_mdp()
    # "left" with beta = 0 everywhere: from 1 it reaches 0, where left is a self-loop forever.
    o = Option("left-forever", np.arange(8) == 2, np.zeros(8, dtype=np.int64), np.zeros(8))
    with pytest.raises(ModelError, match=r"'left-forever' never terminates when started in state "
                                         r"2.*state 0"):
        option_model(mdp, o)


def test_sampler_refuses_starts_outside_initiation():
    mdp = chain_mdp()
    o = subgoal_options(mdp, [2, 5])[1]
    with pytest.raises(ModelError, match="'to-5' is not admissible in state 0"):
        sample_option_model(mdp, o, np.random.default_rng(0), starts=np.array([0]))


def test_subgoal_option_bad_inputs():
    mdp = chain_mdp()
    with pytest.raises(ModelError, match="initiation = 'everywhere'"):
        subgoal_option(mdp, 5, initiation="everywhere")
    with pytest.raises(ModelError, match="initiation mask has shape"):
        subgoal_option(mdp, 5, initiation=np.ones(3, bool))
    with pytest.raises(ModelError, match="subgoal 99 is not a state"):
        subgoal_option(mdp, 99)
    mask = np.zeros(8, bool)
    mask[[1, 4]] = True  # 1 cannot reach 5 without leaving the mask
    with pytest.raises(ModelError, match="cannot be reached from initiation state 1"):
        subgoal_option(mdp, 5, initiation=mask)
    S, A = 3, 1
    P = np.zeros((S, A, S))
    P[:, :, 0] = 1.0  # nothing ever reaches state 1
    sink = FiniteMDP.from_dense(P, np.zeros((S, A)), 0.9)
    with pytest.raises(ModelError, match="initiation set of subgoal 1 is empty"):
        subgoal_option(sink, 1)

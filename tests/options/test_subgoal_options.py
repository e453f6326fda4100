"""Options to subgoals: a subgoal no option can serve is dropped and reported."""

from __future__ import annotations

import numpy as np
import pytest

from adpart.errors import ModelError
from adpart.mdp.model import FiniteMDP
from adpart.options.subgoal_options import subgoal_options


def test_a_subgoal_no_state_can_reach_is_dropped_and_reported_when_asked():
    """A chain 0 -> 1 -> 2 -> 3 (3 absorbing): nothing reaches state 0, so its option would have
    an empty initiation set. By default that raises; with ``dropped`` it is left out and named,
    and the other subgoals keep their options (both initiation rules, with and without cover)."""
    S = 4
    P = np.zeros((S, S))
    for s in range(S - 1):
        P[s, s + 1] = 1.0
    P[S - 1, S - 1] = 1.0
    R = np.full((S, 1), -1.0)
    terminal = np.zeros(S, dtype=bool)
    terminal[S - 1] = True
    mdp = FiniteMDP([P], R, 0.9, terminal=terminal)
    for initiation, cover in (("basin", False), ("local", True), ("local", False)):
        with pytest.raises(ModelError):
            subgoal_options(mdp, [0, 2], initiation=initiation, cover=cover, radius=2)
        dropped: list[tuple[int, str]] = []
        options = subgoal_options(mdp, [0, 2], initiation=initiation, cover=cover, radius=2,
                                  dropped=dropped)
        assert [o.subgoal for o in options] == [2]
        assert [d for d, _ in dropped] == [0] and "no state" in dropped[0][1]

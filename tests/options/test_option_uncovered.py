"""Primitive actions as the fallback where no option can start (include_primitives="uncovered")."""

from __future__ import annotations

import numpy as np
import pytest

from adpart.envs.registry import get_domain
from adpart.errors import ModelError
from adpart.mdp.evaluation import policy_evaluation
from adpart.mdp.solvers import solve
from adpart.options.models import option_models
from adpart.options.smdp import stack_models
from adpart.options.subgoal_options import subgoal_options

DOORWAY = 23


def test_primitives_are_offered_only_where_no_option_starts():
    mdp = get_domain("two-rooms").mdp("reach-goal")
    models = option_models(mdp, subgoal_options(mdp, np.array([DOORWAY])), duration=False)
    with pytest.raises(ModelError, match="state 23"):
        stack_models(mdp, models, include_primitives=False)
    smdp = stack_models(mdp, models, include_primitives="uncovered")
    A = mdp.n_actions
    prim_states = np.flatnonzero(smdp.admissible[:, :A].any(axis=1) & ~mdp.terminal)
    assert prim_states.tolist() == [DOORWAY]
    others = np.setdiff1d(np.arange(mdp.n_states), [DOORWAY])
    assert smdp.row_discounts[:A][:, others].max() == 0.0  # primitive rows empty elsewhere
    # every state now has an action, so the SMDP solves; the goal itself is no subgoal, so this
    # layer cannot reach it (values stay below V*) - what the hierarchical learner's
    # inconsistency refinement repairs (section 4.3.3)
    V = policy_evaluation(smdp, solve(smdp, 1e-10).policy)
    assert np.all(np.isfinite(V))
    assert np.all(V <= solve(mdp, 1e-10).V + 1e-9)


def test_bad_include_primitives_value():
    mdp = get_domain("two-rooms").mdp("reach-goal")
    with pytest.raises(ModelError, match="include_primitives must be"):
        stack_models(mdp, [], include_primitives="sometimes")

"""The detectors as plugins, and reward variation (4.3.1)."""

from __future__ import annotations

import json

import numpy as np

from adpart.envs.registry import get_domain
from adpart.mdp.solvers import solve
from adpart.plugins.builtin import detectors as builtin
from adpart.plugins.builtin.detectors import RewardVariation
from adpart.plugins.registry import Registrar, Registry
from adpart.subgoals import reward_variation_states


def test_subgoal_registration_and_json():
    reg = Registry()
    builtin.register_subgoal_detectors(Registrar(reg, "subgoal-detector", "adpart", "0"))
    names = reg.names("subgoal-detector")
    assert names == ["count-exhaustive", "count-mc", "reward-variation", "betweenness",
                     "visit-frequency"]
    mdp = get_domain("two-rooms").mdp("reach-goal")
    policy = solve(mdp).policy
    for name in names:
        res = reg.get("subgoal-detector", name).create().detect(mdp, policy,
                                                                np.random.default_rng(0))
        assert res.detector == name and res.scores.shape == (mdp.n_states,)
        json.dumps(res.to_json())


def test_subgoal_reward_variation_adds_goal():
    mdp = get_domain("two-rooms").mdp("reach-goal")
    goal = int(np.flatnonzero(mdp.terminal)[0])
    rv0 = reward_variation_states(mdp, level=0.0)
    assert goal in rv0.tolist()
    assert not mdp.terminal[rv0[rv0 != goal]].any()
    res = RewardVariation(level="0").detect(mdp, solve(mdp).policy, np.random.default_rng(0))
    assert set(res.stats["base_subgoals"]) | set(rv0.tolist()) == set(res.subgoals.tolist())

"""The detectors as plugins, and reward variation (4.3.1)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np

from adpart.envs.registry import get_domain
from adpart.mdp.solvers import solve
from adpart.plugins.builtin import detectors as builtin
from adpart.plugins.builtin.detectors import RewardVariation
from adpart.plugins.registry import Registrar, Registry
from adpart.subgoals import RewardVariationSettings, reward_variation_states


def test_subgoal_registration_and_json():
    reg = Registry()
    builtin.register_subgoal_detectors(Registrar(reg, "subgoal-detector", "adpart", "0"))
    names = reg.names("subgoal-detector")
    assert names == ["count-exhaustive", "count-mc", "reward-variation", "betweenness",
                     "visit-frequency", "eigenoptions", "covering"]
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
    rv0 = reward_variation_states(mdp, RewardVariationSettings(reward_level=0.0))
    assert goal in rv0.tolist()
    assert not mdp.terminal[rv0[rv0 != goal]].any()
    res = RewardVariation(reward_level=0.0).detect(mdp, solve(mdp).policy,
                                                   np.random.default_rng(0))
    assert set(res.stats["base_subgoals"]) | set(rv0.tolist()) == set(res.subgoals.tolist())


def test_detector_parameters_are_their_settings():
    """Each built-in detector's parameters are derived from its settings dataclass (one default
    and check each), and a result stores those settings."""
    from adpart.params import settings_params
    from adpart.subgoals import settings as s

    pairs = {builtin.CountExhaustive: s.CountSettings, builtin.CountMonteCarlo:
             s.MonteCarloSettings, builtin.RewardVariation: s.RewardVariationSettings,
             builtin.Betweenness: s.BetweennessSettings,
             builtin.VisitFrequency: s.VisitFrequencySettings}
    def declared(params):  # all but the help text, which a plugin may word for itself
        return [dataclasses.replace(p, help="") for p in params]

    for plugin, cls in pairs.items():
        assert declared(plugin.params) == declared(settings_params(cls))
    assert tuple(builtin._BASES) == s.REWARD_BASES
    mdp = get_domain("two-rooms").mdp("reach-goal")
    res = builtin.VisitFrequency(walks=50).detect(mdp, None, np.random.default_rng(0))
    assert res.params == {"top": 4, "walks": 50, "horizon": 0}

"""What each learner knows, as data, and the guard that holds it to it.

Each learner is run on a guarded copy of its task (:func:`adpart.learning.knowledge.guard`) that
raises when the learner reads the dynamics or the task's rewards outside the environment's own
use of them (sampling and scoring): with the learner's declared knowledge it runs, and with less
than it declares it raises - so the declaration is what the learner reads, no less and no more in
either category.
"""

from __future__ import annotations

import numpy as np
import pytest

from adpart.learning import q_learning
from adpart.learning.hierarchical import decision_layer, hierarchical_knowledge
from adpart.learning.hierarchical_settings import HierarchicalSettings
from adpart.learning.knowledge import (
    FLAT,
    Knowledge,
    KnowledgeError,
    combine,
    guard,
    world,
)
from adpart.learning.settings import Run
from adpart.learning.smdp_q import SMDPQSettings, smdp_q_learning
from adpart.options import subgoal_option

from .hierarchical_run import hierarchical_run
from .test_hierarchical import SETTINGS, goal_grid

RUN = Run(runs=2, episodes=30, seed=1, eval_every=10)


def test_the_guard_raises_outside_the_world_and_not_inside():
    mdp = goal_grid()
    blind = guard(mdp, FLAT)
    for name in ("P", "R", "terminal", "sampler_arrays"):
        with pytest.raises(KnowledgeError, match=f"read {name} .* dynamics none, rewards observed"):
            getattr(blind, name)
    with world():
        assert np.array_equal(blind.R, mdp.R) and blind.P.nnz == mdp.P.nnz
    assert blind.n_states == mdp.n_states and blind.content_hash == mdp.content_hash
    assert np.array_equal(guard(mdp, Knowledge("none", "known")).R, mdp.R)
    with pytest.raises(KnowledgeError, match="read P"):
        guard(mdp, Knowledge("none", "known")).P  # noqa: B018


def test_flat_q_learning_only_samples_and_declares_so():
    mdp = goal_grid()
    guarded = q_learning(guard(mdp, FLAT), RUN)
    plain = q_learning(mdp, RUN)
    assert np.array_equal(guarded.Q, plain.Q)  # the guard changes nothing it allows
    assert Knowledge.from_dict(guarded.parameters["knowledge"]) == FLAT


def test_smdp_q_over_given_options_only_samples_and_knows_through_its_options():
    from adpart.learning.knowledge import OPTION_POLICIES

    mdp = goal_grid()
    opts = [subgoal_option(mdp, 0, initiation="reachable")]
    res = smdp_q_learning(guard(mdp, FLAT), opts, SMDPQSettings(include_primitives=True), RUN)
    assert Knowledge.from_dict(res.parameters["knowledge"]) == OPTION_POLICIES
    alone = smdp_q_learning(guard(mdp, FLAT), [], SMDPQSettings(include_primitives=True), RUN)
    assert Knowledge.from_dict(alone.parameters["knowledge"]) == FLAT


@pytest.mark.parametrize("mode", ["inconsistency", "reward-variation"])
def test_the_hierarchical_learner_reads_what_it_declares_and_raises_below_it(mode):
    mdp = goal_grid()
    opts = [subgoal_option(mdp, c, initiation="reachable") for c in (0, 4, 20, 24)]
    part, _full, _smdp = decision_layer(mdp, opts, delta=0.2, epsilon=0.0)
    keywords = {**SETTINGS, "episodes": 20, "runs": 2, "mode": mode}
    layer = part if mode == "inconsistency" else None
    declared = hierarchical_knowledge(HierarchicalSettings(mode=mode))
    res = hierarchical_run(guard(mdp, declared), opts, layer, **keywords)
    assert Knowledge.from_dict(res.parameters["knowledge"]) == declared
    assert declared.dynamics == "true-model" and declared.rewards == "known"
    if mode == "reward-variation":
        assert any("reward states" in u for u in declared.uses)
    for less in (Knowledge("true-model", "observed"), Knowledge("none", "known")):
        with pytest.raises(KnowledgeError):
            hierarchical_run(guard(mdp, less), opts, layer, **keywords)


def test_a_runs_knowledge_is_the_most_of_its_parts():
    both = combine([FLAT, Knowledge("true-model", "observed", ("option policies",)),
                    Knowledge("none", "known", ("phase-3 reward split",))])
    assert (both.dynamics, both.rewards) == ("true-model", "known")
    assert both.uses == ("option policies", "phase-3 reward split")
    assert combine([]) == FLAT and "rewards observed" in FLAT.label


def test_the_value_iteration_reference_reads_the_whole_model_and_says_so():
    from adpart.learning.knowledge import PLANNER
    from adpart.learning.reference import value_iteration_curve

    mdp = goal_grid()
    res = value_iteration_curve(guard(mdp, PLANNER), sweeps=5, seed=0)
    assert Knowledge.from_dict(res.parameters["knowledge"]) == PLANNER
    with pytest.raises(KnowledgeError):
        value_iteration_curve(guard(mdp, Knowledge("true-model", "observed")), sweeps=5, seed=0)


def test_maxq_samples_only_and_declares_its_hand_designed_graph():
    from adpart.envs.domains.taxi import Taxi
    from adpart.learning.maxq import maxq_q, taxi_graph
    from adpart.learning.maxq.maxq_q import MAXQ_KNOWLEDGE

    mdp = Taxi().mdp()
    graph = taxi_graph().compile(mdp)
    res = maxq_q(guard(mdp, FLAT), graph, Run(runs=1, episodes=3, seed=0, eval_every=3))
    assert Knowledge.from_dict(res.parameters["knowledge"]) == MAXQ_KNOWLEDGE
    assert MAXQ_KNOWLEDGE.rewards == "known"  # the graph is the designer's knowledge of the task

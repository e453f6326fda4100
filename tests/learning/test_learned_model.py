"""The learned-model regime's learners read only what experience gave them (issue 37).

Independent checks: the knowledge guard (a learner that declared estimated dynamics cannot read
the task's true ``P``, ``R`` or terminal set without raising), and the counts learner against
the true-model learner where the two must coincide (a deterministic environment whose every
pair the prior tried).
"""

from __future__ import annotations

import numpy as np
import pytest

from adpart.errors import ModelError, TaskError
from adpart.learning import q_learning
from adpart.learning.curves import LearningCurve
from adpart.learning.hierarchical import hierarchical_knowledge, hierarchical_learning
from adpart.learning.hierarchical_settings import HierarchicalSettings
from adpart.learning.knowledge import Knowledge, KnowledgeError, guard
from adpart.learning.model_based import estimated_dynamics_learning, known_dynamics_learning
from adpart.learning.settings import Run
from adpart.mdp.experience import Experience
from adpart.options.subgoal_options import subgoal_options
from adpart.params import build_settings
from adpart.partition import Partition
from adpart.workflows.experience import EstimatedDomain, belief_model
from adpart.workflows.regime import agent_verdict
from adpart.workflows.resolve import resolve_domain

ESTIMATED = Knowledge("estimated", "observed")


@pytest.fixture(scope="module")
def two_rooms():
    """two-rooms' first task learned flat (its experience), the estimate, and the new task."""
    domain = resolve_domain("two-rooms")
    first = domain.mdp("reach-goal")
    learned = q_learning(first, Run(runs=3, episodes=200, seed=3, alpha=1, epsilon=0.5))
    estimated = EstimatedDomain(domain, learned.experience, "two-rooms@experience:test")
    return domain, estimated, domain.mdp("goal:x=9,y=5")


def _layer(estimated: EstimatedDomain):
    """The option to the doorway (23), solved on the estimated model, and a two-block layer over
    the primitives then it: the option where it may start, the primitives elsewhere."""
    model = estimated.mdp("reach-goal")
    options = subgoal_options(model, [23], initiation="reachable")
    starts = options[0].initiation
    A = model.n_actions
    offers = np.zeros((2, A + 1), dtype=bool)
    offers[0, A] = True
    offers[1, :A] = True
    return options, Partition(np.where(starts, 0, 1), offers)


def test_the_belief_model_knows_the_step_reward_and_no_terminal(two_rooms):
    _, estimated, new = two_rooms
    belief = belief_model(estimated, new, "reach-goal")
    assert not belief.terminal.any()
    assert np.unique(belief.R).size == 1  # one step reward, no goal reward
    assert np.array_equal(belief.admissible, new.admissible)
    tried = estimated.experience.tried
    P = belief.P.toarray()
    S = belief.n_states
    for s, a in np.argwhere(~tried)[:20]:  # unknown: a self-loop
        assert P[a * S + s, s] == 1.0
    truth = new.P.toarray()  # tried (deterministic two-rooms): exactly the true row
    for s, a in np.argwhere(tried)[:50]:
        assert np.array_equal(P[a * S + s], truth[a * S + s])


def test_on_a_belief_the_layer_learner_reads_nothing_of_the_new_task(two_rooms):
    _, estimated, new = two_rooms
    options, partition = _layer(estimated)
    belief = belief_model(estimated, new, "reach-goal")
    settings = build_settings(HierarchicalSettings, {"threshold": 1.0})
    run = Run(runs=2, episodes=40, seed=1, alpha=1, epsilon=0.3)
    guarded = guard(new, ESTIMATED)  # P, R and terminal raise outside the environment's use
    result = hierarchical_learning(guarded, options, partition, settings, run, belief=belief)
    assert result.curve.metadata["knowledge"]["dynamics"] == "estimated"
    assert result.curve.metadata["knowledge"]["rewards"] == "observed"
    with pytest.raises(KnowledgeError, match="outside the declared regime"):
        hierarchical_learning(guard(new, ESTIMATED), options, partition, settings, run)


def test_a_belief_needs_a_threshold_and_the_inconsistency_mode(two_rooms):
    _, estimated, new = two_rooms
    options, partition = _layer(estimated)
    belief = belief_model(estimated, new, "reach-goal")
    run = Run(runs=1, episodes=2, seed=0)
    with pytest.raises(TaskError, match="--threshold"):
        hierarchical_learning(new, options, partition, HierarchicalSettings(), run,
                              belief=belief)
    rmax = build_settings(HierarchicalSettings, {"threshold": 1.0, "explore": "r-max"})
    with pytest.raises(TaskError, match="--value-ceiling V"):  # the task's ceiling is unknown
        hierarchical_learning(new, options, partition, rmax, run, belief=belief)
    planned = build_settings(HierarchicalSettings, {"threshold": 1.0, "explore": "r-max",
                                                    "value-ceiling": 20.0,
                                                    "layer-values": "planned"})
    with pytest.raises(TaskError, match="--layer-values learned"):
        hierarchical_learning(new, options, partition, planned, run, belief=belief)
    planned = build_settings(HierarchicalSettings, {"threshold": 1.0, "reference": "offered"})
    with pytest.raises(TaskError, match="--reference learned"):
        hierarchical_learning(new, options, partition, planned, run, belief=belief)


def test_the_counts_learner_is_the_true_model_learner_once_every_pair_is_known():
    """Deterministic two-rooms, every pair tried once in the prior: the counts model is the true
    model, so the two certainty-equivalent agents make the same plans and the same steps."""
    new = resolve_domain("two-rooms").mdp("goal:x=9,y=5")
    S, A = new.n_states, new.n_actions
    live = np.argwhere(new.admissible & ~new.terminal[:, None])
    rows = live[:, 1] * S + live[:, 0]
    succ = new.P.tocsr()[rows].indices  # one successor per row (deterministic)
    assert succ.size == rows.size
    prior = Experience.from_table({"state": live[:, 0], "action": live[:, 1],
                                   "next_state": succ, "count": np.ones(rows.size)}, S, A,
                                  sources=("run:0",))
    run = Run(runs=2, episodes=15, seed=4, eval_every=5)
    known = known_dynamics_learning(new, run)
    counted = estimated_dynamics_learning(new, run, prior)
    for column in ("steps", "return", "eval_value"):
        assert np.array_equal(known.curve[column], counted.curve[column], equal_nan=True)
    assert counted.curve.metadata["knowledge"]["dynamics"] == "estimated"
    assert "run:0 and its own steps" in counted.curve.metadata["knowledge"]["uses"][0]


def test_the_counts_learner_learns_without_a_prior_and_refuses_a_foreign_one():
    new = resolve_domain("two-rooms").mdp("goal:x=9,y=5")
    res = estimated_dynamics_learning(new, Run(runs=2, episodes=60, seed=2, eval_every=20))
    assert np.all(res.curve.matrix("value_gap")[:, -1] < 1e-6)
    S, A = new.n_states, new.n_actions
    s = int(np.flatnonzero(~new.terminal)[0])
    reachable = set(new.P.tocsr()[np.arange(A) * S + s].indices)
    far = next(t for t in range(S) if t not in reachable)  # a jump no action makes
    foreign = Experience.from_table({"state": [s], "action": [0], "next_state": [far],
                                     "count": [3]}, S, A)
    with pytest.raises(ModelError, match="another environment"):
        estimated_dynamics_learning(new, Run(runs=1, episodes=1), foreign)


def test_the_fallback_is_decided_from_what_the_agent_saw():
    meta = {"max_steps_per_episode": 50}

    def curve(steps):
        return LearningCurve.from_matrices(
            steps=np.array([steps]), decisions=np.array([steps]),
            returns=np.zeros((1, 3)), discounted_returns=np.zeros((1, 3)),
            eval_value=np.zeros((1, 3)), value_gap=np.zeros((1, 3)), metadata=meta)

    never = curve([50, 50, 50])
    verdict = agent_verdict(never, "reach-goal", "goal:x=9,y=5")
    assert verdict["fallback"] and "no episode of reach-goal" in verdict["reason"]
    found = curve([50, 12, 50])
    verdict = agent_verdict(found, "reach-goal", "goal:x=9,y=5")
    assert not verdict["fallback"] and verdict["episodes_ending_in_a_terminal"] == 1


def test_a_firing_is_real_when_the_added_action_beats_what_the_block_offered():
    """On a corridor (right is optimal everywhere but the goal), adding right where the block
    offered only left is a real inconsistency; adding left where it offered right is not."""
    from adpart.learning.firing_audit import firing_audit

    from .conftest import corridor

    mdp = corridor(6)  # actions: 0 left, 1 right; the goal at the right end
    smdp = mdp.as_smdp()
    events = [{"run": 0, "state": 2, "action": 1, "offers": [0]},   # real
              {"run": 0, "state": 3, "action": 0, "offers": [1]},   # not: left is worse
              {"run": 1, "state": 1, "action": 1, "offers": [0, 1]},  # not: already offered
              {"run": 1, "state": 4, "action": 1, "offers": []}]    # real: nothing offered
    audit = firing_audit(events, smdp, mdp, 2)
    assert audit.real.tolist() == [1, 1] and audit.ties.tolist() == [0, 1]  # offered: a tie
    empty = firing_audit([], smdp, mdp, 2)
    assert [x.tolist() for x in (empty.real, empty.ties, empty.own_step)] == [[0, 0]] * 3


def test_a_tie_is_an_own_step_when_an_offered_option_moves_first_as_the_added_action():
    """An option "go right" offered at state 1: adding right there ties (the option does it
    first, then continues optimally) and is its own step; a primitive offered beside it is not
    counted unless it is the added action itself."""
    from adpart.learning.firing_audit import firing_audit, first_actions
    from adpart.options import Option

    from .conftest import corridor

    mdp = corridor(6)  # actions: 0 left, 1 right; the goal at the right end
    S = mdp.n_states
    right = Option("right", np.ones(S, dtype=bool) & ~mdp.terminal, np.ones(S, dtype=np.int64),
                   mdp.terminal.astype(np.float64))
    from adpart.learning.hierarchical import option_set

    columns, smdp = option_set(mdp, [right], include_primitives=True)
    first = first_actions(columns[mdp.n_actions:], S, mdp.n_actions)
    assert first[2].tolist() == [1] * S  # column 2, the option, moves right everywhere
    events = [{"run": 0, "state": 1, "action": 1, "offers": [2]},     # tie, own step
              {"run": 0, "state": 2, "action": 1, "offers": [0, 2]},  # tie, own step
              {"run": 0, "state": 3, "action": 1, "offers": [0]}]     # real
    audit = firing_audit(events, smdp, mdp, 1, first)
    assert (audit.real.tolist(), audit.ties.tolist(), audit.own_step.tolist()) == (
        [1], [2], [2])
    assert firing_audit(events, smdp, mdp, 1).own_step.tolist() == [0]  # not asked: none


def test_r_max_on_a_belief_values_unknown_pairs_at_the_ceiling_it_is_given(two_rooms):
    """With a value ceiling R-max runs on a belief model, and the ceiling is what it plans an
    unknown pair at: given a ceiling below every value it has no optimism left, and the runs
    differ from those given a high one (the agent explores by it)."""
    _, estimated, new = two_rooms
    options, partition = _layer(estimated)
    belief = belief_model(estimated, new, "reach-goal")
    run = Run(runs=3, episodes=30, seed=5)

    def learn(ceiling: float):
        settings = build_settings(HierarchicalSettings, {
            "threshold": 0.05, "explore": "r-max", "value-ceiling": ceiling})
        return hierarchical_learning(new, options, partition, settings, run, belief=belief)

    high, low = learn(20.0), learn(-1e6)
    assert high.curve.metadata["exploration"] == "r-max"
    assert high.curve.metadata["known_after"] == 1
    assert not np.array_equal(np.asarray(high.curve["steps"]), np.asarray(low.curve["steps"]))
    knowledge = hierarchical_knowledge(build_settings(HierarchicalSettings, {
        "threshold": 0.05, "explore": "r-max", "value-ceiling": 20.0}), belief=True)
    assert knowledge.dynamics == "estimated" and knowledge.rewards == "observed"
    assert any("value ceiling" in use for use in knowledge.uses)


def test_the_learned_value_ceiling_is_the_first_tasks_goal_reward_once(two_rooms):
    """``learned_value_ceiling``: where every positive reward the first task paid came with a
    chance of ending the episode, the largest reward per unit of that chance (a goal's reward,
    collected once); two-rooms' moves are sure, so it is the largest reward a tried pair paid,
    computed here from the first task's reward table and the experience's tried pairs."""
    from adpart.workflows.regime import learned_value_ceiling
    from adpart.workflows.resolve import register_domain

    domain, estimated, _ = two_rooms
    register_domain(estimated.name, estimated)
    first = domain.mdp("reach-goal")
    tried = estimated.experience.tried & first.admissible & ~first.terminal[:, None]
    expected = max(first.R[tried].max(), 0.0)
    assert expected > 0  # the goal's reward was paid
    assert learned_value_ceiling(estimated.name, "reach-goal", "goal:x=9,y=5", 500) == expected


def test_the_first_task_is_judged_on_the_agents_model_as_v_star_judges_it_where_both_agree(
        tmp_path):
    """``first_task_judgement`` evaluates each run's greedy policy on the model the runs
    estimated, with the rewards they were paid. On a deterministic lake whose every pair was
    tried that model is the true one, so its verdicts must be V*'s: each run's gap computed here
    by policy evaluation on the true task, independently of the estimate."""
    from adpart.mdp.evaluation import policy_evaluation
    from adpart.mdp.solvers import solve
    from adpart.store import KnowledgeBase
    from adpart.workflows.pipeline import PipelineConfig, run_pipeline

    env = "gym:FrozenLake-v1[map_name=4x4,is_slippery=false]"
    with KnowledgeBase.open(tmp_path / "kb") as kb:
        report = run_pipeline(kb, PipelineConfig(env=env, tasks=("reward", "goal:row=0,col=3"),
                                                 runs=4, episodes=30, first_episodes=300,
                                                 eval_every=5, baseline=False,
                                                 model_baseline=False))
        judged = next(s.detail for s in report.stages if s.stage == "judge")
        estimated = resolve_domain(next(s.result for s in report.stages
                                        if s.stage == "estimate"))
        true = resolve_domain(env).mdp("reward")
        live = true.admissible & ~true.terminal[:, None]
        assert np.all(estimated.experience.tried[live]), "every pair tried: the model is exact"
        v_star = float(true.initial @ policy_evaluation(true, solve(true, 1e-12).policy))
        task = next(t for t in kb.records("task") if t.name == "reward")
        gaps = []
        for policy in (p for p in kb.records("policy") if p.task_id == task.id):
            q = np.asarray(kb.load(policy, "q"))
            greedy = np.argmax(np.where(np.isnan(q), -np.inf, q), axis=1)
            gaps.append((v_star - float(true.initial @ policy_evaluation(true, greedy)))
                        / abs(v_star))
    assert judged["runs"] == len(gaps) == 4
    np.testing.assert_allclose(judged["gap_fraction"], np.maximum(gaps, 0.0), atol=1e-9)
    assert judged["learned_runs"] == sum(g <= 0.05 for g in gaps)
    assert judged["value_hat"] == pytest.approx(v_star, abs=1e-9)

"""The learned-model regime's rehearsal (adpart/workflows/rehearsal.py): hypothetical goals on
the agent's own model, the verdict rule, and the pipeline's fallback it decides."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from adpart.cli import cli
from adpart.learning.qlearning import q_learning
from adpart.learning.settings import Run
from adpart.workflows.experience import EstimatedDomain
from adpart.workflows.rehearsal import (
    REHEARSAL_GOALS,
    rehearsal_goals,
    rehearsal_task,
    rehearsal_verdict,
    trap_states,
)
from adpart.workflows.resolve import resolve_domain


@pytest.fixture(scope="module")
def estimated():
    """two-rooms' first task learned flat by three short runs, and its estimate."""
    domain = resolve_domain("two-rooms")
    learned = q_learning(domain.mdp("reach-goal"),
                         Run(runs=3, episodes=60, seed=3, alpha=1, epsilon=0.5))
    return EstimatedDomain(domain, learned.experience, "two-rooms@experience:rehearsal")


def test_goals_are_states_the_first_tasks_runs_acted_in(estimated):
    first = estimated.base.mdp("reach-goal")
    goals = rehearsal_goals(estimated, "reach-goal", 6, seed=0)
    assert goals.size == 6 == np.unique(goals).size
    assert estimated.experience.tried[goals].any(axis=1).all()
    assert not first.terminal[goals].any()
    np.testing.assert_array_equal(goals, rehearsal_goals(estimated, "reach-goal", 6, seed=0))


def test_a_hypothetical_task_pays_the_first_tasks_rewards_on_the_estimate(estimated):
    """Built by hand from the dense estimate: every pair pays the first task's step reward, a
    move into the goal its top paid reward instead (in expectation), and only the goal ends an
    episode (two-rooms has no trap); the discount is the first task's."""
    first = estimated.base.mdp("reach-goal")
    goal = int(rehearsal_goals(estimated, "reach-goal", 1, seed=1)[0])
    task = rehearsal_task(estimated, "reach-goal", goal)
    P = estimated.experience.estimate().toarray()
    S, A = first.n_states, first.n_actions
    tried = estimated.experience.tried & first.admissible
    values, counts = np.unique(first.R[tried & ~first.terminal[:, None]], return_counts=True)
    step, top = values[np.argmax(counts)], values.max()
    assert top > step
    for s in range(S):
        for a in range(A):
            into = P[a * S + s, goal]
            assert task.R[s, a] == pytest.approx((1 - into) * step + into * top)
    assert task.terminal.sum() == 1 and task.terminal[goal]
    assert task.gamma == first.gamma and task.initial[goal] == 0
    np.testing.assert_allclose(task.P.toarray(), P)


@pytest.mark.parametrize(("ratios", "verdict"), [
    ([None, None], (False, None, None)),
    ([0.5, 2.0, 3.0], (True, 2.0, None)),
    ([0.0, float("inf"), 0.5], (False, 0.5, None)),
    ([1.0, 1.0, None], (False, 1.0, None)),
])
def test_the_layer_is_kept_unless_the_median_ratio_exceeds_one(ratios, verdict):
    assert rehearsal_verdict(ratios) == verdict


@pytest.mark.parametrize(("ratios", "steps", "verdict"), [
    ([1.0, 1.0, 0.5, 2.0], [1.2, 1.1, 0.9, 3.0], (True, 1.0, 1.15)),  # a tie, slower in steps
    ([1.0, 1.0, 0.5, 2.0], [0.8, 1.0, 0.5, 1.5], (False, 1.0, 0.9)),  # a tie, faster in steps
    ([1.0, 1.0, None], [None, None, None], (False, 1.0, None)),  # no finer evidence: kept
    ([0.5, 0.9, 1.0], [2.0, 2.0, 2.0], (False, 0.9, None)),  # no tie: the steps do not vote
])
def test_a_tie_in_episodes_is_broken_by_the_primitive_steps(ratios, steps, verdict):
    falls, median, steps_median = rehearsal_verdict(ratios, steps)
    assert (falls, median) == verdict[:2]
    assert steps_median == (None if verdict[2] is None else pytest.approx(verdict[2]))


FROZEN = "gym:FrozenLake-v1[map_name=4x4]"


@pytest.mark.parametrize(("env", "tasks", "branch"), [
    (FROZEN, "reward,move-goal:row=0,col=3", "flat"),
    ("two-rooms", "reach-goal,goal:x=9,y=5", "layer"),
])
@pytest.mark.extended
def test_the_rehearsal_decides_the_fallback_from_the_agents_model(tmp_path, env, tasks, branch):
    """The slippery 4x4 lake with its goal moved is learned flat by the rehearsal's verdict
    (results/benchmark.md: the rehearsal predicts the layer slower there); on two-rooms the
    layer is kept. The stage names the hypothetical goals and the ratio; with --no-fallback no
    rehearsal runs."""
    args = ["pipeline", env, "--tasks", tasks, "--runs", "3", "--episodes", "150",
            "--kb", str(tmp_path / "kb"), "--json"]
    res = CliRunner().invoke(cli, [*args, "--out", str(tmp_path / "a")])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.output)
    [stage] = [s for s in summary["stages"] if s["stage"] == "rehearse"]
    assert stage["result"] == branch
    # every goal the rehearsal may draw, up to REHEARSAL_GOALS: the 4x4 lake's runs acted in 11
    # states off its 4 holes and its goal
    assert len(stage["detail"]["goals"]) == (11 if env == FROZEN else REHEARSAL_GOALS)
    assert "hypothetical goals" in stage["detail"]["reason"]
    learners = {r["learner"] for r in summary["tasks"] if r["task"] == tasks.split(",", 1)[1]}
    assert ("flat-fallback" in learners) == (branch == "flat")
    assert ("hierarchical" in learners) == (branch == "layer")
    off = json.loads(CliRunner().invoke(cli, [*args, "--no-fallback", "--out",
                                              str(tmp_path / "b")]).output)
    assert not any(s["stage"] == "rehearse" for s in off["stages"])


def test_holes_the_first_tasks_runs_fell_into_stay_terminal_and_its_goal_does_not():
    """On the 4x4 lake the first task ends in a hole (reward 0) or at the goal (+1): the map's
    holes that the runs entered are the traps, the goal is not, and a hypothetical task keeps
    the traps terminal beside its own goal."""
    env = "gym:FrozenLake-v1[map_name=4x4,is_slippery=false]"
    domain = resolve_domain(env)
    first = domain.mdp("reward")
    learned = q_learning(first, Run(runs=3, episodes=200, seed=1, alpha=1, epsilon=0.5))
    estimated = EstimatedDomain(domain, learned.experience, f"{env}@experience:rehearsal")
    rows = ["SFFF", "FHFH", "FFFH", "HFFG"]  # Gymnasium's 4x4 map
    holes = np.array([c == "H" for row in rows for c in row])
    entered = np.zeros(first.n_states, bool)
    entered[learned.experience.counts.indices] = True
    traps = trap_states(estimated, "reward")
    np.testing.assert_array_equal(traps, holes & entered)
    assert traps.any() and not traps[15]  # the goal paid +1: not a trap
    goal = int(rehearsal_goals(estimated, "reward", 1, seed=0)[0])
    task = rehearsal_task(estimated, "reward", goal)
    np.testing.assert_array_equal(np.flatnonzero(task.terminal),
                                  np.flatnonzero(traps | (np.arange(first.n_states) == goal)))

"""adpart.testing: every built-in passes its kind's checks; deliberately broken plugins do not.

Each broken class below breaks exactly one rule of its contract, and the check must say which.
The last tests go through the CLI: a learner plugin whose result lacks a field, or a learner
given options it does not accept, ends in one line naming the fix (exit 2), never a traceback.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pytest
from click.testing import CliRunner

from adpart.cli import cli
from adpart.execution import Executor
from adpart.mdp.model import FiniteMDP
from adpart.params import Param
from adpart.partition.partition import Partition
from adpart.plugins import get_registry
from adpart.plugins.builtin.detectors import Betweenness
from adpart.plugins.builtin.estimators import AllSubgoals, ExpectedLearningTime
from adpart.plugins.builtin.learners import QLearner
from adpart.plugins.contracts import HierarchyEstimator
from adpart.subgoals.result import SubgoalResult
from adpart.testing import (
    ConformanceError,
    _start_value_by_iteration,
    check_criterion,
    check_detector,
    check_estimator,
    check_executor,
    check_learner,
    check_plugin,
    check_plugin_class,
)
from tests.plugins.conftest import install_fake_distribution


@pytest.fixture
def small_chain() -> FiniteMDP:
    """States 0 -> 1 -> 2 (terminal) by "right" (-1 a step), "stay" in place (-1); gamma 0.9."""
    P = np.zeros((3, 2, 3))
    P[0, 0, 1] = P[1, 0, 2] = P[2, 0, 2] = 1.0
    P[0, 1, 0] = P[1, 1, 1] = P[2, 1, 2] = 1.0
    R = np.array([[-1.0, -1.0], [-1.0, -1.0], [0.0, 0.0]])
    return FiniteMDP.from_dense(P, R, 0.9, terminal=[False, False, True],
                                initial=[0.5, 0.5, 0.0])


def _builtin_specs():
    """Every built-in but ``ray``, whose check runs on the shared cluster (tests/ray)."""
    reg = get_registry()
    return [pytest.param(s, id=f"{s.kind}:{s.name}")
            for s in reg.all() if s.package == "adpart" and s.name != "ray"]


@pytest.mark.parametrize("spec", _builtin_specs())
def test_every_builtin_passes_its_conformance_check(spec):
    check_plugin(spec)


def test_the_reference_start_value_is_plain_value_iteration(small_chain):
    # a 3-state chain, -1 a step, gamma = 0.9: from state 0 the goal is 2 steps away
    assert _start_value_by_iteration(small_chain) == pytest.approx(-1.45, abs=1e-12)


# --------------------------------------------------------------------------- broken plugins


class NoName:
    description = "x"
    params = ()


class BadDefault:
    name = "bad-default"
    description = "a default its own declaration refuses"
    params = (Param("rate", "float", -1.0, "a rate", min=0.0),)

    def __init__(self, rate=-1.0):
        self.rate = rate


class UndeclaredKeyword:
    name = "undeclared"
    description = "declares a parameter the constructor does not take"
    params = (Param("rate", "float", 0.5, "a rate"),)


@pytest.mark.parametrize(("cls", "rule"), [
    (NoName, "`name` must be a non-empty string"),
    (BadDefault, "the default of --rate is refused"),
    (UndeclaredKeyword, "--rate is not a constructor keyword"),
])
def test_declarations_are_checked(cls, rule):
    with pytest.raises(ConformanceError, match=rule):
        check_plugin_class(cls)


@dataclass
class NotAResult:
    Q: np.ndarray
    curve: object


class ResultWithoutVStar(QLearner):
    name = "no-v-star"

    def learn(self, mdp, **kwargs):
        out = super().learn(mdp, **kwargs)
        return NotAResult(out.Q, out.curve)


class WrongVStar(QLearner):
    name = "wrong-v-star"

    def learn(self, mdp, **kwargs):
        out = super().learn(mdp, **kwargs)
        return type(out)(Q=out.Q, visits=out.visits, curve=out.curve, seed=out.seed,
                         v_star_start=out.v_star_start + 1.0)


class Unseeded(QLearner):
    name = "unseeded"
    calls = 0

    def learn(self, mdp, *, seed, **kwargs):
        Unseeded.calls += 1
        return super().learn(mdp, seed=seed + Unseeded.calls, **kwargs)


@pytest.mark.parametrize(("cls", "rule"), [
    (ResultWithoutVStar, "not an adpart.learning.LearnResult"),
    (WrongVStar, "value iteration gives"),
    (Unseeded, "the same seed gave a different learning curve"),
])
def test_a_broken_learner_is_caught(cls, rule, small_chain):
    with pytest.raises(ConformanceError, match=rule):
        check_learner(cls, small_chain, episodes=2)


class OutOfRange(Betweenness):
    name = "out-of-range"

    def detect(self, mdp, policy, rng):
        out = super().detect(mdp, policy, rng)
        goals = np.array([0, mdp.n_states], dtype=np.int64)
        return SubgoalResult(goals, out.scores, out.threshold, out.stats, out.params, self.name)


class ScoresPerSubgoal(Betweenness):
    name = "scores-per-subgoal"

    def detect(self, mdp, policy, rng):
        out = super().detect(mdp, policy, rng)
        return SubgoalResult(out.subgoals, out.scores[out.subgoals], out.threshold, out.stats,
                             out.params, self.name)


@pytest.mark.parametrize(("cls", "rule"), [
    (OutOfRange, r"state ids in \[0, "),
    (ScoresPerSubgoal, "scores must have shape"),
])
def test_a_broken_detector_is_caught(cls, rule):
    with pytest.raises(ConformanceError, match=rule):
        check_detector(cls)


class MergingCriterion:
    name = "merging"
    description = "puts every state in one block (does not refine)"
    params = ()

    def refine(self, partition, model, **context):
        return Partition.from_labels(np.zeros(model.n_states, dtype=np.int64), model.admissible)


def test_a_criterion_that_merges_blocks_is_caught():
    with pytest.raises(ConformanceError, match="mixes states of two input blocks"):
        check_criterion(MergingCriterion)


class Shuffling(Executor):
    name = "shuffling"
    description = "returns results in reverse order"

    def map(self, fn, items):
        return [fn(i) for i in items][::-1]


def test_an_executor_out_of_order_is_caught():
    with pytest.raises(ConformanceError, match="results come back in item order"):
        check_executor(Shuffling)


class StoresItsLayer(ExpectedLearningTime):
    name = "stores-its-layer"

    def build(self, inputs):
        return replace(super().build(inputs), partition_id=7)


class EditsItsInputs(ExpectedLearningTime):
    name = "edits-its-inputs"

    def build(self, inputs):
        inputs.admissible[:, inputs.mdp.n_actions:] = False  # in place: no option anywhere
        return super().build(inputs)


class PositionsForIds(AllSubgoals):
    name = "positions-for-ids"

    def build(self, inputs):
        out = super().build(inputs)
        return replace(out, option_ids=list(range(len(out.option_ids))))


class EmptyBlock(ExpectedLearningTime):
    name = "empty-block"

    def build(self, inputs):
        out = super().build(inputs)
        adm = out.partition.admissible.copy()
        adm[0] = False
        return replace(out, partition=out.partition.with_admissible(adm))


class ReadsTheStore:
    name = "reads-the-store"
    description = "the former contract: reads and stores the knowledge base itself"
    params = ()

    def build(self, knowledge_base, environment, *, tasks=None, store=True):
        raise AssertionError("never called")


@pytest.mark.parametrize(("cls", "rule"), [
    (StoresItsLayer, "partition_id must be None"),
    (EditsItsInputs, r"build\(\) changed its inputs"),
    (PositionsForIds, "must be ids of inputs.option_ids"),
    (EmptyBlock, "a block offers no column"),
    (ReadsTheStore, r"cannot be called as build\(inputs\)"),
])
def test_a_broken_estimator_is_caught(cls, rule):
    with pytest.raises(ConformanceError, match=rule):
        check_estimator(cls)


def test_the_estimators_keep_the_protocol_and_leave_their_inputs_alone():
    from adpart.testing import estimator_inputs

    inputs = estimator_inputs()
    for cls in (ExpectedLearningTime, AllSubgoals):
        assert isinstance(cls(), HierarchyEstimator)
        check_estimator(cls, inputs)  # the same inputs object twice: neither changed it
    # ids are the inputs' (not positions); all-subgoals offers every doorway option somewhere
    assert AllSubgoals().build(inputs).option_ids == [201, 202, 203, 204]


# --------------------------------------------------------------------------- through the CLI

BROKEN_LEARNER = '''
from adpart.plugins import hookimpl
from adpart.plugins.builtin.learners import QLearner


class Bare:
    def __init__(self, Q, curve):
        self.Q, self.curve = Q, curve


class Forgetful(QLearner):
    name = "forgetful"
    description = "returns Q and the curve but no v_star_start (test plugin)"

    def learn(self, mdp, **kwargs):
        out = super().learn(mdp, **kwargs)
        return Bare(out.Q, out.curve)


@hookimpl
def register_learners(register):
    register(Forgetful)
'''


def test_a_result_without_its_fields_is_one_line_through_the_cli(plugin_site, tmp_path):
    install_fake_distribution(plugin_site, "fake-adpart-forgetful", "fake_adpart_forgetful",
                              BROKEN_LEARNER)
    out = CliRunner().invoke(cli, ["learn", "two-rooms", "--learner", "forgetful", "--runs", "1",
                                   "--episodes", "2", "--kb", str(tmp_path / "kb"), "-q"])
    assert out.exit_code == 2, out.output
    assert "learner 'forgetful' returned a Bare without v_star_start" in out.output
    assert "Traceback" not in out.output


def test_options_for_a_learner_that_does_not_take_them_is_refused(tmp_path):
    out = CliRunner().invoke(cli, ["learn", "two-rooms", "--options", "subgoal-set:2",
                                   "--kb", str(tmp_path / "kb")])
    assert out.exit_code == 2, out.output
    assert "learner 'q-learning' does not learn over options" in out.output
    assert "--learner hierarchical or smdp-q" in out.output

"""A third-party plugin's own exception is one line naming the plugin and its package (exit 2),
its traceback behind ``adpart --debug``; a plugin's option shows that plugin's help."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from click.testing import CliRunner

from adpart.cli import cli
from adpart.errors import PluginFailure, TaskError
from adpart.plugins import get_registry
from tests.plugins.conftest import install_fake_distribution

CRASHING = '''
from adpart.errors import TaskError
from adpart.params import Param
from adpart.plugins import hookimpl


class CrashingLearner:
    name = "crashing"
    description = "raises inside learn (test plugin)"
    params = (Param("trajectories", "int", 7, "how many trajectories the crashing learner "
                    "pretends to sample", min=1),
              Param("refuse", "bool", False, "raise adpart's own TaskError instead"))

    def __init__(self, trajectories=7, refuse=False):
        self.trajectories, self.refuse = trajectories, refuse

    def learn(self, mdp, *, runs, episodes, seed, eval_every, progress=None):
        if self.refuse:
            raise TaskError("this task does not fit the crashing learner")
        return helper(mdp)


def helper(mdp):
    return {}["no such key in the crashing learner"]


class CrashingDetector:
    name = "crashing-detector"
    description = "divides by zero inside detect (test plugin)"
    params = (Param("trajectories", "int", 3, "trajectories of the crashing detector", min=1),)

    def __init__(self, trajectories=3):
        self.trajectories = trajectories

    def detect(self, mdp, policy, rng):
        return 1 / 0


class BrokenConstructor:
    name = "broken-constructor"
    description = "raises in __init__ (test plugin)"
    params = ()

    def __init__(self):
        raise RuntimeError("constructor bug")

    def learn(self, mdp, **kwargs):
        raise AssertionError("never reached")


from adpart.envs.grid import GridDomain


class CrashingRooms(GridDomain):
    name = "crashing-rooms"
    description = "a grid whose tasks() has a bug (test plugin)"
    MAP = """
    S..
    ..G
    """

    def tasks(self):
        return {"reach": self.undefined_goal_spec}


@hookimpl
def register_environments(register):
    register(CrashingRooms)


@hookimpl
def register_learners(register):
    register(CrashingLearner)
    register(BrokenConstructor)


@hookimpl
def register_subgoal_detectors(register):
    register(CrashingDetector)
'''


@pytest.fixture
def crashing(plugin_site):
    install_fake_distribution(plugin_site, "fake-adpart-crash", "fake_adpart_crash", CRASHING)
    return plugin_site


def _learn(*args: str):
    return CliRunner().invoke(cli, [*args, "learn", "two-rooms", "--runs", "1", "--episodes",
                                    "2", "--no-store", "-q"])


def test_an_exception_inside_learn_is_one_line_naming_plugin_and_package(crashing, tmp_path):
    out = CliRunner().invoke(cli, ["learn", "two-rooms", "--learner", "crashing", "--runs", "1",
                                   "--episodes", "2", "--no-store", "-q",
                                   "--out", str(tmp_path / "o")])
    assert out.exit_code == 2, out.output
    lines = out.output.strip().splitlines()
    assert len(lines) == 1, out.output
    assert lines[0].startswith("Error: learner 'crashing' (package fake-adpart-crash 0.1) "
                               "failed in learn(): KeyError: ")
    assert "Traceback" not in out.output and "adpart --debug" in lines[0]


def test_debug_prints_the_plugins_own_traceback_then_the_same_line(crashing, tmp_path):
    out = CliRunner().invoke(cli, ["--debug", "learn", "two-rooms", "--learner", "crashing",
                                   "--runs", "1", "--episodes", "2", "--no-store", "-q",
                                   "--out", str(tmp_path / "o")])
    assert out.exit_code == 2
    assert "Traceback (most recent call last)" in out.output
    assert "fake_adpart_crash.py" in out.output and "in helper" in out.output  # its frames
    assert out.output.strip().splitlines()[-1].startswith("Error: learner 'crashing'")


def test_a_plugins_adpart_error_stays_its_own_message(crashing, tmp_path):
    out = CliRunner().invoke(cli, ["learn", "two-rooms", "--learner", "crashing", "--refuse",
                                   "true", "--runs", "1", "--episodes", "2", "--no-store",
                                   "-q", "--out", str(tmp_path / "o")])
    assert out.exit_code == 2
    assert out.output.strip() == "Error: this task does not fit the crashing learner"


def test_a_failing_constructor_is_named_too(crashing, tmp_path):
    out = CliRunner().invoke(cli, ["learn", "two-rooms", "--learner", "broken-constructor",
                                   "--runs", "1", "--episodes", "2", "--no-store", "-q",
                                   "--out", str(tmp_path / "o")])
    assert out.exit_code == 2
    assert ("learner 'broken-constructor' (package fake-adpart-crash 0.1) failed in building "
            "it: RuntimeError: constructor bug") in out.output


def test_an_environments_own_bug_is_named_too(crashing, tmp_path):
    out = CliRunner().invoke(cli, ["learn", "crashing-rooms", "--runs", "1", "--episodes", "2",
                                   "--no-store", "-q", "--out", str(tmp_path / "o")])
    assert out.exit_code == 2, out.output
    assert out.output.startswith("Error: environment 'crashing-rooms' (package "
                                 "fake-adpart-crash 0.1) failed in tasks(): AttributeError")


def test_the_guard_wraps_detect_keeps_its_signature_and_pickles(crashing):
    import inspect

    from adpart.envs.registry import get_domain

    spec = get_registry().get("subgoal-detector", "crashing-detector")
    detector = spec.create({"trajectories": 5})
    assert list(inspect.signature(detector.detect).parameters) == ["mdp", "policy", "rng"]
    mdp = get_domain("two-rooms").mdp()
    with pytest.raises(PluginFailure, match=r"subgoal-detector 'crashing-detector' \(package "
                       r"fake-adpart-crash 0.1\) failed in detect\(\): ZeroDivisionError") as e:
        detector.detect(mdp, np.zeros(mdp.n_states, np.int64), np.random.default_rng(0))
    assert isinstance(e.value.__cause__, ZeroDivisionError)
    again = pickle.loads(pickle.dumps(detector))  # a process pool may carry it to a worker
    assert again.trajectories == 5
    with pytest.raises(PluginFailure):
        again.detect(mdp, np.zeros(mdp.n_states, np.int64), np.random.default_rng(0))
    failure = pickle.loads(pickle.dumps(e.value))  # and carry the failure back
    assert str(failure) == str(e.value)


def test_builtin_plugins_are_not_wrapped():
    learner = get_registry().get("learner", "q-learning").create()
    assert inspect_is_plain(learner.learn)
    with pytest.raises(TaskError):  # adpart's own errors are unchanged
        get_registry().get("learner", "hierarchical").create().learn(
            None, runs=1, episodes=1, seed=0, eval_every=1)


def inspect_is_plain(method) -> bool:
    return not hasattr(method, "spec") and hasattr(method, "__self__")


def test_each_plugin_option_shows_its_own_plugins_help(crashing):
    """Two plugins of one kind declare ``--trajectories``: each --help shows its own text and
    default, and the default learner's help shows neither (it declares no such option)."""
    runner = CliRunner()
    learner = runner.invoke(cli, ["learn", "--learner", "crashing", "--help"])
    assert learner.exit_code == 0
    text = " ".join(learner.output.split())
    assert "--trajectories INTEGER how many trajectories the crashing learner pretends to " \
           "sample [default: 7]" in text
    detector = runner.invoke(cli, ["discover", "--detector", "crashing-detector", "--help"])
    text = " ".join(detector.output.split())
    assert "--trajectories INTEGER trajectories of the crashing detector [default: 3]" in text
    assert "crashing learner" not in text
    default = runner.invoke(cli, ["learn", "--help"])
    assert "--trajectories" not in default.output and "--alpha" in default.output


def test_builtin_detectors_sharing_a_field_each_say_what_it_means_for_them():
    """count-exhaustive and count-mc share CountSettings' --trajectories; count-mc's own help
    says it is also the first batch, the exhaustive detector's does not."""
    runner = CliRunner()
    exhaustive = " ".join(runner.invoke(cli, ["discover", "--help"]).output.split())
    mc = " ".join(runner.invoke(cli, ["discover", "--detector", "count-mc", "--help"])
                  .output.split())
    assert "--trajectories INTEGER sampled paths along which ratios are taken" in exhaustive
    assert "first batch" not in exhaustive.split("--trajectories")[1].split("[default")[0]
    assert "--trajectories INTEGER trajectories of the first batch" in mc


def test_with_help_replaces_only_the_help():
    from adpart.params import settings_params, with_help
    from adpart.subgoals.settings import CountSettings

    params = settings_params(CountSettings)
    changed = with_help(params, trajectories="other text")
    assert [p.help for p in changed if p.name == "trajectories"] == ["other text"]
    assert [(p.name, p.default, p.min) for p in changed] == [(p.name, p.default, p.min)
                                                            for p in params]
    with pytest.raises(TypeError, match="no parameter 'nope'"):
        with_help(params, nope="x")

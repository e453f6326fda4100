"""Every tabular learner validates its run settings through adpart.learning.settings."""

from __future__ import annotations

import numpy as np
import pytest

from adpart.errors import ModelError, TaskError
from adpart.learning import q_learning
from adpart.learning.settings import run_settings

from .conftest import corridor
from .hierarchical_run import smdp_q_run


@pytest.mark.parametrize(
    ("kwargs", "needle"),
    [({"runs": 0}, "runs = 0 must be an integer >= 1"),
     ({"episodes": 2.5}, "episodes = 2.5 must be an integer >= 1"),
     ({"eval_every": True}, "eval_every = True"),
     ({"max_steps_per_episode": -1}, "max_steps_per_episode = -1"),
     ({"seed": -3}, "seed = -3 must be a non-negative integer"),
     ({"alpha": 1.5}, "alpha"),
     ({"epsilon": "2"}, "epsilon"),
     ({"q_init": float("nan")}, "q_init = nan must be a finite number")],
)
@pytest.mark.parametrize("learner", [q_learning, smdp_q_run])
def test_learners_reject_the_same_bad_settings(learner, kwargs, needle):
    mdp = corridor()
    with pytest.raises(TaskError) as err:
        learner(mdp, **kwargs)
    assert needle in str(err.value)


def test_run_settings_names_the_learner_and_converts():
    with pytest.raises(ModelError, match="my_learner needs a FiniteMDP, got list"):
        run_settings("my_learner", [], runs=1, episodes=1, eval_every=1,
                     max_steps_per_episode=1, seed=0, alpha=0.5, epsilon=0.1)
    cfg = run_settings("q", corridor(), runs=np.int64(3), episodes=4, eval_every=2,
                       max_steps_per_episode=9, seed=7, alpha="1/n^0.8", epsilon=0.2, q_init=1)
    assert (cfg.runs, cfg.episodes, cfg.eval_every, cfg.horizon, cfg.seed) == (3, 4, 2, 9, 7)
    assert isinstance(cfg.runs, int) and cfg.q_init == 1.0 and cfg.alpha.omega == 0.8

"""Every tabular learner takes one Run, checked once where it is built."""

from __future__ import annotations

import numpy as np
import pytest

from adpart.errors import ModelError, TaskError
from adpart.learning import q_learning
from adpart.learning.settings import MAX_SEED, Run, fresh_seed
from adpart.learning.smdp_q import SMDPQSettings, smdp_q_learning

from .conftest import corridor


@pytest.mark.parametrize(
    ("kwargs", "needle"),
    [({"runs": 0}, "runs = 0 must be >= 1 (--runs)"),
     ({"episodes": 2.5}, "episodes = 2.5 must be an integer (--episodes)"),
     ({"eval_every": True}, "eval_every = True must be an integer (--eval-every)"),
     ({"max_steps_per_episode": -1}, "max_steps_per_episode = -1 must be >= 1 (--max-steps)"),
     ({"seed": -3}, "seed = -3 must be >= 0 (--seed)"),
     ({"seed": MAX_SEED + 1}, "(--seed)"),
     ({"alpha": 1.5}, "alpha = 1.5: alpha schedule reaches 1.5"),
     ({"epsilon": "2"}, "epsilon = '2': epsilon schedule reaches 2"),
     ({"epsilon": "sometimes"}, "epsilon = 'sometimes'"),
     ({"q_init": float("nan")}, "q_init = nan must be a finite number (--q-init)")],
)
def test_a_bad_run_setting_is_refused_where_the_run_is_built(kwargs, needle):
    with pytest.raises(TaskError) as err:
        Run(**kwargs)
    assert needle in str(err.value)


def test_run_converts_and_parses_once():
    run = Run(runs=np.int64(3), episodes=4, eval_every=2, max_steps_per_episode=9, seed=7,
              alpha="1/n^0.8", epsilon=0.2, q_init=1)
    assert (run.runs, run.episodes, run.eval_every, run.max_steps_per_episode, run.seed) == (
        3, 4, 2, 9, 7)
    assert isinstance(run.runs, int) and run.q_init == 1.0 and run.alpha.omega == 0.8
    assert run.epsilon.scale == 0.2 and Run(alpha=run.alpha).alpha == run.alpha


def test_a_fresh_seed_is_drawn_once_and_fits_the_store():
    assert fresh_seed(5) == 5
    drawn = {fresh_seed(None) for _ in range(5)}
    assert len(drawn) == 5 and all(0 <= s <= MAX_SEED for s in drawn)


@pytest.mark.parametrize("learner", [q_learning, lambda m, run: smdp_q_learning(m, [], None, run)])
def test_learners_refuse_what_is_not_a_finite_mdp(learner):
    with pytest.raises(ModelError, match="needs a FiniteMDP, got list"):
        learner([], Run(runs=1, episodes=1))


def test_learners_take_the_same_run():
    run = Run(runs=2, episodes=4, seed=3, eval_every=2)
    flat = q_learning(corridor(), run)
    smdp = smdp_q_learning(corridor(), [], SMDPQSettings(include_primitives=True), run)
    assert flat.parameters["runs"] == smdp.parameters["runs"] == 2
    assert flat.seed == smdp.seed == 3

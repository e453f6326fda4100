"""The value-iteration reference learner: what an agent that knows the model would do.

Its "learning curve" has one row per Bellman sweep instead of per episode: ``steps`` counts the
``S*A`` backups of a sweep, and the greedy policy of every sweep is scored exactly, like a learner's
(Sutton, Precup & Singh 1999 compare options by exactly this curve on four-rooms).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from adpart.errors import TaskError
from adpart.learning.curves import (
    LearningCurve,
    optimal_start_value,
    start_distribution,
    start_values,
)
from adpart.learning.knowledge import PLANNER
from adpart.learning.result import LearnResult
from adpart.mdp.evaluation import greedy_policy
from adpart.mdp.model import FiniteMDP
from adpart.mdp.solvers import q_from_v


@dataclass(frozen=True, eq=False)
class ReferenceResult(LearnResult):
    """The result of :func:`value_iteration_curve`: a learner's result with one run."""


def value_iteration_curve(mdp: FiniteMDP, *, sweeps: int, seed: int) -> ReferenceResult:
    """Run ``sweeps`` Jacobi value-iteration sweeps from V = 0, scoring each greedy policy.

    Args:
        mdp: the task.
        sweeps: number of sweeps (the curve's "episodes").
        seed: recorded only; value iteration uses no randomness.
    """
    if sweeps < 1:
        raise TaskError(f"sweeps = {sweeps} must be >= 1")
    mu = start_distribution(mdp)
    v_star = optimal_start_value(mdp, mu)
    V = np.zeros(mdp.n_states)
    policies = np.empty((sweeps, mdp.n_states), dtype=np.int64)
    Q = np.empty((mdp.n_states, mdp.n_actions))
    for k in range(sweeps):
        Q = q_from_v(mdp, V)
        policies[k] = greedy_policy(Q)
        V = Q.max(axis=1)
    eval_value = start_values(mdp, policies, mu)[None, :]
    backups = np.full((1, sweeps), int(mdp.admissible.sum()), dtype=np.int64)
    nan = np.full((1, sweeps), np.nan)
    parameters = {"sweeps": sweeps, "seed": seed, "knowledge": PLANNER.to_dict()}
    curve = LearningCurve.from_matrices(
        steps=backups,
        decisions=backups,
        returns=nan,
        discounted_returns=nan,
        eval_value=eval_value,
        value_gap=v_star - eval_value,
        metadata={
            "learner": "value-iteration",
            "mdp": mdp.name,
            "mdp_hash": mdp.content_hash,
            "gamma": mdp.gamma,
            "v_star_start": v_star,
            **parameters,
        },
    )
    return ReferenceResult(
        Q=Q[None], curve=curve, seed=seed, v_star_start=v_star, parameters=parameters
    )

"""Finite MDP / SMDP models and their exact solvers."""

from typing import TYPE_CHECKING

from adpart.lazy import lazy_exports

if TYPE_CHECKING:
    from adpart.mdp.evaluation import greedy_policy, policy_evaluation
    from adpart.mdp.model import FiniteMDP, SMDPModel
    from adpart.mdp.solvers import (
        Solution,
        gauss_seidel_value_iteration,
        modified_policy_iteration,
        q_from_v,
        solve,
        value_iteration,
    )

lazy_exports(__name__, {
    "adpart.mdp.evaluation": ("greedy_policy", "policy_evaluation"),
    "adpart.mdp.model": ("FiniteMDP", "SMDPModel"),
    "adpart.mdp.solvers": (
        "Solution", "gauss_seidel_value_iteration", "modified_policy_iteration", "q_from_v",
        "solve", "value_iteration",
    ),
})

__all__ = [
    "FiniteMDP",
    "SMDPModel",
    "Solution",
    "gauss_seidel_value_iteration",
    "greedy_policy",
    "modified_policy_iteration",
    "policy_evaluation",
    "q_from_v",
    "solve",
    "value_iteration",
]

"""Environments: the grid map language, built-in domains, and the Gymnasium bridge."""

from adpart.envs.base import Domain, Dynamics, GoalSpec, Task
from adpart.envs.registry import domain_names, get_domain

__all__ = ["Domain", "Dynamics", "GoalSpec", "Task", "domain_names", "get_domain"]

"""Environments: the grid map language, built-in domains, and the Gymnasium bridge."""

from adpart.envs.base import Domain, Dynamics, GoalSpec, Task
from adpart.envs.gym_env import register_envs
from adpart.envs.registry import domain_names, get_domain

register_envs()  # gymnasium.make("adpart/<name>-v0") works after `import adpart.envs`

__all__ = ["Domain", "Dynamics", "GoalSpec", "Task", "domain_names", "get_domain", "register_envs"]

"""The settings every tabular learner validates the same way (runs, episodes, seed, schedules).

Flat Q-learning, SMDP Q-learning and the hierarchical learner take the same experiment settings;
:func:`run_settings` checks them once, with errors that name the setting and the fix.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from adpart.errors import ModelError, TaskError
from adpart.learning.schedules import Schedule, constant, parse_schedule, visit_count
from adpart.mdp.model import FiniteMDP


@dataclass(frozen=True)
class RunSettings:
    """Validated settings: K runs of N episodes, evaluated every M, at most H steps each."""

    runs: int
    episodes: int
    eval_every: int
    horizon: int
    seed: int
    alpha: Schedule
    epsilon: Schedule
    q_init: float


def count(value: object, what: str) -> int:
    """``value`` as an int >= 1, else TaskError naming ``what``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise TaskError(f"{what} = {value!r} must be an integer >= 1")
    return int(value)


def root_seed(seed: object) -> int:
    """``seed`` as a non-negative int; None draws one from OS entropy (recorded by callers)."""
    if seed is None:
        return int(np.random.SeedSequence().entropy)  # type: ignore[arg-type]
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise TaskError(f"seed = {seed!r} must be a non-negative integer (or None for a fresh one)")
    return int(seed)


def schedule(value: object, what: str) -> Schedule:
    """A schedule from its spelling, checked to stay within [0, 1]."""
    return parse_schedule(value).check_probability(what)  # type: ignore[arg-type]


def run_settings(
    learner: str, mdp: object, *, runs: object, episodes: object, eval_every: object,
    max_steps_per_episode: object, seed: object, alpha: object, epsilon: object,
    q_init: object = 0.0, epsilon_name: str = "epsilon",
) -> RunSettings:
    """Check ``mdp`` is a FiniteMDP and the settings are in range; ``learner`` names the caller."""
    if not isinstance(mdp, FiniteMDP):
        raise ModelError(
            f"{learner} needs a FiniteMDP, got {type(mdp).__name__}; build one with "
            "adpart.envs.registry.get_domain(name).mdp()"
        )
    K = count(runs, "runs")
    N = count(episodes, "episodes")
    M = count(eval_every, "eval_every")
    H = count(max_steps_per_episode, "max_steps_per_episode")
    seed_value = root_seed(seed)
    alpha_s = schedule(alpha, "alpha")
    eps_s = schedule(epsilon, epsilon_name)
    if not isinstance(q_init, (int, float, np.number)) or not np.isfinite(q_init):
        raise TaskError(f"q_init = {q_init!r} must be a finite number")
    return RunSettings(K, N, M, H, seed_value, alpha_s, eps_s, float(q_init))


@dataclass(frozen=True)
class Run:
    """How a learner's K runs go: what :func:`run_settings` checks, and the scoring hooks.

    Attributes:
        runs, episodes: K independent runs of N episodes each.
        seed: the root seed (None: a fresh one from OS entropy, recorded in the result).
        alpha, epsilon: the step-size and exploration schedules
            (:func:`adpart.learning.schedules.parse_schedule` spellings or objects).
        max_steps_per_episode: the primitive-step limit of one episode.
        eval_every: exact scoring of the greedy policies every this many episodes.
        q_init: the starting Q-values (None: the learner's rule).
        kernel: ``"numba"`` or ``"python"`` (None: the default kernel).
        reference_values: ``V*`` to score against (None: solved).
        progress: called as ``progress(done, episodes)`` after every evaluation.
    """

    runs: int = 10
    episodes: int = 500
    seed: int | None = None
    alpha: Schedule | str | float = field(default_factory=lambda: visit_count(0.8))
    epsilon: Schedule | str | float = field(default_factory=lambda: constant(0.1))
    max_steps_per_episode: int = 1000
    eval_every: int = 10
    q_init: float | None = None
    kernel: str | None = None
    reference_values: np.ndarray | None = field(default=None, compare=False, repr=False)
    progress: Callable[[int, int], object] | None = field(default=None, compare=False,
                                                         repr=False)

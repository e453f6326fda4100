"""Every adpart domain as a :class:`gymnasium.Env`, registered as ``adpart/<name>-v0``.

:class:`DomainEnv` runs a domain's :class:`~adpart.mdp.model.FiniteMDP` (one task) one sampled
transition at a time, so agents written for Gymnasium can learn on the same dynamics adpart
partitions and solves exactly:

* observations and actions are ``Discrete(S)`` and ``Discrete(A)``: the MDP's state and action
  indices;
* :meth:`DomainEnv.reset` draws the start state from the task's initial distribution with
  ``self.np_random``; :meth:`DomainEnv.step` draws the successor with
  :meth:`FiniteMDP.sample_next` and the same generator, so one seed fixes the whole episode;
* the reward of a step is the model's **expected** immediate reward ``R(s, a)``: adpart's models
  keep expected rewards only (dissertation sec. 3.1, eq. 3.1), so a sampled return has the same
  expectation as in the model, and ``V*`` of the environment equals ``V*`` of the model;
* ``terminated`` is True on *arrival* in a terminal state (the model's convention: its value is 0);
* ``info["action_mask"]`` (``(A,)`` int8, Gymnasium's Taxi convention) lists the admissible actions
  of the new state when the domain has inadmissible actions. An inadmissible action is a no-op with
  reward :attr:`DomainEnv.inadmissible_reward` ``= min(0, min R) - 1``: stalling then never beats
  the optimal value (``r <= (1 - gamma) V*(s)`` for every ``s``), so the environment's optimal
  policy stays the model's.

:func:`register_envs` registers every name of :data:`adpart.envs.registry.BUILTIN_DOMAINS` with a
:class:`gymnasium.wrappers.TimeLimit` of :data:`DEFAULT_MAX_EPISODE_STEPS` steps; it runs when this
module is imported, so ``gymnasium.make("adpart.envs.gym_env:adpart/two-rooms-v0")`` works in a
fresh interpreter. Gymnasium >= 1.0 has no entry-point plugin discovery (it was removed in 1.0.0),
so an id is known only after its registering module has been imported.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any, ClassVar

import gymnasium
import numpy as np
from gymnasium import spaces

from adpart.envs.base import Domain, GoalSpec, Task
from adpart.envs.registry import BUILTIN_DOMAINS, get_domain
from adpart.errors import TaskError
from adpart.mdp.model import FiniteMDP

#: Gymnasium namespace of adpart's environments: ``adpart/<name>-v0``.
NAMESPACE = "adpart"

#: Episode length limit (TimeLimit truncation) of the registered environments; override it with
#: ``gymnasium.make(id, max_episode_steps=N)``.
DEFAULT_MAX_EPISODE_STEPS = 1000

ENTRY_POINT = "adpart.envs.gym_env:DomainEnv"


def env_id(name: str) -> str:
    """The Gymnasium id of a built-in domain: ``adpart/<name>-v0``."""
    return f"{NAMESPACE}/{name}-v0"


@lru_cache(maxsize=16)
def _cached_model(name: str, task: str | None) -> tuple[Domain, FiniteMDP]:
    """Domain and MDP of a named domain and task, built once per process.

    ``gymnasium.make`` (and ``check_env``, which makes one environment per render mode) creates
    environments repeatedly; the models are immutable (read-only arrays), so sharing them is safe.
    """
    domain = get_domain(name)
    return domain, domain.mdp(task)


def _resolve(
    domain_or_name: Domain | str, task: str | GoalSpec | Task | None
) -> tuple[Domain, FiniteMDP]:
    if isinstance(domain_or_name, str):
        if task is None or isinstance(task, str):
            return _cached_model(domain_or_name, task)
        domain = get_domain(domain_or_name)
        return domain, domain.mdp(task)
    if not isinstance(domain_or_name, Domain):
        raise TaskError(
            f"DomainEnv needs a Domain or a domain name, got {type(domain_or_name).__name__}; "
            f"names: {', '.join(BUILTIN_DOMAINS)} or gym:<id>"
        )
    return domain_or_name, domain_or_name.mdp(task)


class DomainEnv(gymnasium.Env[int, int]):
    """A Gymnasium environment that samples one adpart domain under one task.

    Args:
        domain_or_name: a :class:`Domain`, or a name :func:`adpart.envs.get_domain` knows.
        task: a task name, ``"goal:x=3,y=4"``, a :class:`GoalSpec` or a :class:`Task`
            (None: the domain's default task).
        render_mode: None, ``"ansi"`` (one text line) or ``"rgb_array"`` (the domain's picture
            with the current state marked, ``(H, W, 3)`` uint8).
        max_episode_steps: truncate episodes after this many steps (None: never). The registered
            ids get a :class:`~gymnasium.wrappers.TimeLimit` instead; use this when constructing
            the class directly.

    Attributes:
        domain: the domain.
        mdp: the :class:`FiniteMDP` being sampled.
        state: the current state index (None before the first reset).
        inadmissible_reward: reward of an inadmissible action (a no-op), ``min(0, min R) - 1``.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["ansi", "rgb_array"], "render_fps": 4}

    def __init__(
        self,
        domain_or_name: Domain | str,
        task: str | GoalSpec | Task | None = None,
        render_mode: str | None = None,
        max_episode_steps: int | None = None,
    ) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise TaskError(
                f"render_mode {render_mode!r} is not supported; use one of "
                f"{', '.join(self.metadata['render_modes'])} or None"
            )
        if max_episode_steps is not None and max_episode_steps <= 0:
            raise TaskError(f"max_episode_steps = {max_episode_steps} must be positive (or None)")
        self.domain, self.mdp = _resolve(domain_or_name, task)
        self.render_mode = render_mode
        self.max_episode_steps = max_episode_steps
        S, A = self.mdp.n_states, self.mdp.n_actions
        self.observation_space = spaces.Discrete(S)
        self.action_space = spaces.Discrete(A)
        adm = self.mdp.admissible
        self._has_mask = not bool(adm.all())
        self._mask = adm.astype(np.int8)
        reward_floor = float(self.mdp.R[adm].min()) if adm.any() else 0.0
        self.inadmissible_reward = min(0.0, reward_floor) - 1.0
        self.state: int | None = None
        self._steps = 0
        self._last_action: int | None = None

    # ---------------------------------------------------------------- core API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[int, dict[str, Any]]:
        """Start an episode in a state drawn from the task's initial distribution.

        ``options={"state": s}`` starts in ``s`` instead (it must not be terminal).
        """
        super().reset(seed=seed)
        start = (options or {}).get("state")
        if start is None:
            s = int(self.np_random.choice(self.mdp.n_states, p=self.mdp.initial))
        else:
            s = self._check_start(start)
        self.state, self._steps, self._last_action = s, 0, None
        return s, self._info(s)

    def step(self, action: int) -> tuple[int, float, bool, bool, dict[str, Any]]:
        """Take ``action``: sample ``s' ~ P(.|s, a)``, reward ``R(s, a)`` (expected reward)."""
        if self.state is None:
            raise gymnasium.error.ResetNeeded("call reset() before step()")
        if not self.action_space.contains(action):
            raise gymnasium.error.InvalidAction(
                f"action {action!r} is not in {self.action_space}; actions are "
                f"0..{self.mdp.n_actions - 1} ({', '.join(self.mdp.action_names)})"
            )
        s, a = self.state, int(action)
        if self.mdp.admissible[s, a]:
            nxt = int(self.mdp.sample_next(np.asarray(s), np.asarray(a), self.np_random))
            reward = float(self.mdp.R[s, a])
        else:
            nxt, reward = s, self.inadmissible_reward
        self.state, self._last_action = nxt, a
        self._steps += 1
        terminated = bool(self.mdp.terminal[nxt])
        truncated = (
            not terminated
            and self.max_episode_steps is not None
            and self._steps >= self.max_episode_steps
        )
        return nxt, reward, terminated, bool(truncated), self._info(nxt)

    def render(self) -> str | np.ndarray | None:
        """Render the current state as :attr:`render_mode` says (None when it is None)."""
        if self.render_mode is None:
            return None
        if self.render_mode == "ansi":
            return self._ansi()
        return self._rgb_array()

    # ---------------------------------------------------------------- helpers
    def _check_start(self, start: object) -> int:
        S = self.mdp.n_states
        if not isinstance(start, (int, np.integer)) or not 0 <= int(start) < S:
            raise TaskError(f"reset option state={start!r} is not a state index in 0..{S - 1}")
        if self.mdp.terminal[int(start)]:
            raise TaskError(
                f"reset option state={int(start)} is terminal; an episode cannot start where it "
                "ends"
            )
        return int(start)

    def _info(self, s: int) -> dict[str, Any]:
        """A fresh info dict (check_env requires new objects on every call)."""
        return {"action_mask": self._mask[s].copy()} if self._has_mask else {}

    def _ansi(self) -> str:
        s = self.state
        if s is None:
            return f"{self.mdp.name}: not started (call reset)"
        parts = [self.mdp.name, f"t={self._steps}", f"s={s}"]
        parts += [f"{k}={self.mdp.features[k][s]}" for k in self.mdp.features]
        last = "-" if self._last_action is None else self.mdp.action_names[self._last_action]
        parts.append(f"last={last}")
        if self.mdp.terminal[s]:
            parts.append("terminal")
        return " ".join(parts)

    def _rgb_array(self) -> np.ndarray:
        from matplotlib.backends.backend_agg import FigureCanvasAgg

        marked = np.zeros(self.mdp.n_states, dtype=bool)
        if self.state is not None:
            marked[self.state] = True
        fig = self.domain.render(marked=marked, title=self._ansi())
        try:
            canvas = FigureCanvasAgg(fig)
            canvas.draw()
            return np.asarray(canvas.buffer_rgba())[..., :3].copy()
        finally:
            fig.clear()


def register_envs() -> list[str]:
    """Register ``adpart/<name>-v0`` for every built-in domain (idempotent).

    Ids that are already registered are left alone, so calling this twice emits no
    "Overriding environment" warning. Domains are built lazily by ``gymnasium.make``.

    Returns:
        the ids now registered by adpart, in :data:`BUILTIN_DOMAINS` order.
    """
    ids = []
    for name in BUILTIN_DOMAINS:
        gid = env_id(name)
        if gid not in gymnasium.registry:
            gymnasium.register(
                id=gid,
                entry_point=ENTRY_POINT,
                max_episode_steps=DEFAULT_MAX_EPISODE_STEPS,
                kwargs={"domain_or_name": name},
            )
        ids.append(gid)
    return ids


register_envs()

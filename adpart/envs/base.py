"""Environments (domains) and tasks: the contract every built-in or plugin environment meets.

A :class:`Domain` owns the *dynamics* of an environment (reward-free): transitions, admissible
actions, state features, per-action costs and a renderer. A *task* puts rewards, terminal states
and a start distribution on top (DESIGN.md, "Task"), and ``domain.mdp(task)`` joins the two into a
validated :class:`~adpart.mdp.model.FiniteMDP`. Keeping them apart is what makes transfer possible:
later tasks reuse the options and partitions built on the same dynamics.

The main API of a domain is:

* :attr:`Domain.name`, :attr:`Domain.description`, :attr:`Domain.source` - for listings and docs.
* :meth:`Domain.dynamics` - the reward-free model (computed once, cached).
* :meth:`Domain.tasks` - the named tasks; :meth:`Domain.task` resolves a name or a goal spec.
* :meth:`Domain.mdp` - dynamics + task as a FiniteMDP.
* :meth:`Domain.render` - a PNG of the domain with optional overlays.
"""

from __future__ import annotations

import difflib
import hashlib
import json
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import cached_property
from types import MappingProxyType
from typing import TYPE_CHECKING, ClassVar

import numpy as np
import scipy.sparse as sp

from adpart.errors import TaskError, UnknownNameError
from adpart.mdp.model import FiniteMDP

if TYPE_CHECKING:
    from matplotlib.figure import Figure


@dataclass(frozen=True, eq=False)
class Dynamics:
    """The reward-free part of an environment.

    Attributes:
        P: ``(A*S, S)`` CSR transition matrix, row ``a*S + s`` (see :class:`FiniteMDP`).
        action_names: one name per action.
        action_costs: ``(A,)`` reward of taking each action (e.g. -1 straight, -1.2 diagonal); the
            default step reward of every task on this domain.
        features: named ``(S,)`` arrays (``x``, ``y``, ``floor``, ``holding`` ...).
        admissible: ``(S, A)`` bool, or None for "every action everywhere".
        start: ``(S,)`` default start distribution, or None for uniform.
    """

    P: sp.csr_array
    action_names: tuple[str, ...]
    action_costs: np.ndarray
    features: Mapping[str, np.ndarray] = field(default_factory=dict)
    admissible: np.ndarray | None = None
    start: np.ndarray | None = None

    @property
    def n_states(self) -> int:
        return self.P.shape[1]

    @property
    def n_actions(self) -> int:
        return len(self.action_names)

    @cached_property
    def content_hash(self) -> str:
        """SHA-256 of the reward-free model (transitions, admissible actions, action names).

        The knowledge base keys environments on it, so every task on the same dynamics shares
        one environment record (and the options and partitions built for it).
        """
        P = sp.csr_array(self.P)
        P.sum_duplicates()
        P.eliminate_zeros()
        h = hashlib.sha256()
        h.update(json.dumps({"shape": list(P.shape), "actions": list(self.action_names)}).encode())
        adm = (
            np.ones((self.n_states, self.n_actions), bool)
            if self.admissible is None
            else self.admissible
        )
        for arr in (
            P.indptr.astype(np.int64),
            P.indices.astype(np.int64),
            P.data.astype(np.float64),
            np.asarray(adm, dtype=bool),
        ):
            h.update(np.ascontiguousarray(arr).tobytes())
        return h.hexdigest()


@dataclass(frozen=True, eq=False)
class Task:
    """A reward function with its terminal states and start distribution, over one domain.

    Attributes:
        name: the task's name (``reach-goal``, ``deliver`` ...).
        reward: ``(S, A)`` expected immediate reward.
        terminal: ``(S,)`` bool, episode ends on arrival.
        initial: ``(S,)`` start distribution.
        gamma: discount factor.
        description: one line for listings.
        spec: a JSON-able description of how the task was built (stored in the knowledge base).
    """

    name: str
    reward: np.ndarray
    terminal: np.ndarray
    initial: np.ndarray
    gamma: float
    description: str = ""
    spec: Mapping[str, object] = field(default_factory=dict)


@dataclass(frozen=True)
class GoalSpec:
    """The generic goal specification: reach any state whose features match ``goal``.

    ``R(s, a) = cost(a) + goal_reward * P(s' in G | s, a)``; goal states are terminal. With
    ``start`` given, episodes start uniformly in the matching states, else with the domain's
    start distribution.

    Attributes:
        goal: feature name -> required value, e.g. ``{"x": 9, "y": 0}`` or
            ``{"object": 12, "holding": 0}``; every listed feature must match.
        goal_reward: reward on arrival in a goal state.
        start: like ``goal``, selecting the start states (None: the domain's default).
        gamma: discount factor.
        step_costs: per-action rewards overriding the domain's ``action_costs``.
        name: the task name to report.
    """

    goal: Mapping[str, int]
    goal_reward: float = 10.0
    start: Mapping[str, int] | None = None
    gamma: float = 0.95
    step_costs: tuple[float, ...] | None = None
    name: str = "goal"

    @classmethod
    def parse(cls, text: str, **kwargs: object) -> GoalSpec:
        """Parse ``"x=3,y=4[;start:x=0,y=0]"`` (the CLI's goal syntax)."""
        goal_part, _, start_part = text.partition(";")
        start_part = start_part.removeprefix("start:")
        return cls(
            goal=_parse_assignments(goal_part, text),
            start=_parse_assignments(start_part, text) if start_part else None,
            name=kwargs.pop("name", "goal:" + text),  # type: ignore[arg-type]
            **kwargs,  # type: ignore[arg-type]
        )

    def build(self, domain: Domain) -> Task:
        dyn = domain.dynamics()
        goal = feature_match(dyn, self.goal, what="goal")
        costs = (
            np.asarray(dyn.action_costs, dtype=np.float64)
            if self.step_costs is None
            else np.asarray(self.step_costs, dtype=np.float64)
        )
        if costs.shape != (dyn.n_actions,):
            raise TaskError(
                f"step_costs has {costs.size} entries; {domain.name} has {dyn.n_actions} actions"
            )
        reward = arrival_reward(dyn, goal, self.goal_reward, costs)
        if self.start is not None:
            starts = feature_match(dyn, self.start, what="start")
            initial = starts / starts.sum()
        else:
            initial = default_start(dyn)
        initial = np.where(goal, 0.0, initial)
        if initial.sum() == 0:
            raise TaskError(f"every start state of task {self.name!r} is a goal state")
        return Task(
            name=self.name,
            reward=reward,
            terminal=goal,
            initial=initial / initial.sum(),
            gamma=self.gamma,
            description=f"reach {dict(self.goal)}",
            spec={
                "kind": "goal",
                "goal": dict(self.goal),
                "goal_reward": self.goal_reward,
                "start": dict(self.start) if self.start else None,
                "gamma": self.gamma,
                "step_costs": list(costs),
            },
        )


def _parse_assignments(part: str, whole: str) -> dict[str, int]:
    out: dict[str, int] = {}
    for item in filter(None, (p.strip() for p in part.split(","))):
        key, eq, value = item.partition("=")
        if not eq:
            raise TaskError(f"goal spec {whole!r}: {item!r} is not FEATURE=VALUE (e.g. x=3,y=4)")
        try:
            out[key.strip()] = int(value)
        except ValueError:
            raise TaskError(
                f"goal spec {whole!r}: value {value!r} of {key!r} is not an integer"
            ) from None
    if not out:
        raise TaskError(f"goal spec {whole!r} names no feature; write e.g. x=3,y=4")
    return out


def feature_match(dyn: Dynamics, wanted: Mapping[str, int], *, what: str) -> np.ndarray:
    """``(S,)`` bool mask of states whose features equal every value in ``wanted``."""
    mask = np.ones(dyn.n_states, dtype=bool)
    for key, value in wanted.items():
        if key not in dyn.features:
            hint = difflib.get_close_matches(key, list(dyn.features), n=1)
            raise TaskError(
                f"{what} names feature {key!r}, which this environment does not have; "
                f"features: {', '.join(sorted(dyn.features))}"
                + (f". Did you mean {hint[0]!r}?" if hint else "")
            )
        mask &= dyn.features[key] == value
    if not mask.any():
        raise TaskError(f"no state matches the {what} {dict(wanted)}")
    return mask


def arrival_reward(
    dyn: Dynamics, goal: np.ndarray, goal_reward: float, costs: np.ndarray
) -> np.ndarray:
    """``(S, A)`` reward ``cost(a) + goal_reward * P(s' in goal | s, a)`` (one sparse mat-vec)."""
    S, A = dyn.n_states, dyn.n_actions
    p_goal = (dyn.P @ goal.astype(np.float64)).reshape(A, S).T
    return costs[None, :] + goal_reward * p_goal


def default_start(dyn: Dynamics) -> np.ndarray:
    if dyn.start is None:
        return np.full(dyn.n_states, 1.0 / dyn.n_states)
    return np.asarray(dyn.start, dtype=np.float64)


TaskFactory = Callable[["Domain"], Task]


class Domain(ABC):
    """A discrete environment: dynamics, named tasks, and a renderer.

    Subclasses set :attr:`name`, :attr:`description` and :attr:`source`, implement
    :meth:`_build_dynamics` and :meth:`tasks`, and may override :meth:`render`.
    """

    name: str = ""
    description: str = ""
    source: str = ""
    default_task: str = ""
    #: What a ``goal:FEATURE=VALUE`` task takes on this domain besides its goal (GoalSpec
    #: fields, e.g. the goal reward and discount of the domain's own named tasks); empty: the
    #: generic GoalSpec defaults (+10 on arrival, gamma 0.95).
    goal_defaults: ClassVar[Mapping[str, object]] = MappingProxyType({})

    @abstractmethod
    def _build_dynamics(self) -> Dynamics:
        """Build the reward-free model (called once; the result is cached)."""

    @abstractmethod
    def tasks(self) -> Mapping[str, TaskFactory | GoalSpec]:
        """The named tasks of this domain: a GoalSpec or a callable ``domain -> Task`` each."""

    @cached_property
    def _dynamics(self) -> Dynamics:
        return self._build_dynamics()

    def dynamics(self) -> Dynamics:
        return self._dynamics

    @property
    def n_states(self) -> int:
        return self.dynamics().n_states

    @property
    def n_actions(self) -> int:
        return self.dynamics().n_actions

    def task(self, task: str | GoalSpec | Task | None = None) -> Task:
        """Resolve a task name, a :class:`GoalSpec`, ``"goal:x=3,y=4"``, a task string of
        :mod:`adpart.envs.task_language` (``"move-goal:x=3,y=4"`` ...) or a Task into a Task."""
        if task is None:
            task = self.default_task or next(iter(self.tasks()))
        if isinstance(task, Task):
            return task
        if isinstance(task, GoalSpec):
            return task.build(self)
        if task.startswith("goal:"):
            return GoalSpec.parse(task.removeprefix("goal:"), **self.goal_defaults).build(self)
        from adpart.envs.task_language import build_task, is_task_spec

        if is_task_spec(task):  # move-goal:, set-reward:, reward-table: (the task's own rewards)
            return build_task(self, task)
        known = self.tasks()
        if task not in known:
            hint = difflib.get_close_matches(task, list(known), n=1)
            raise UnknownNameError(
                f"environment {self.name!r} has no task {task!r}; tasks: {', '.join(known)}"
                + (f". Did you mean {hint[0]!r}?" if hint else "")
                + ". A custom goal is written goal:FEATURE=VALUE,... (e.g. goal:x=3,y=4); "
                "move-goal:, set-reward: and reward-table: keep the environment's rewards"
            )
        factory = known[task]
        return factory.build(self) if isinstance(factory, GoalSpec) else factory(self)

    def mdp(self, task: str | GoalSpec | Task | None = None) -> FiniteMDP:
        """The FiniteMDP of this domain's dynamics under ``task``."""
        dyn = self.dynamics()
        t = self.task(task)
        return FiniteMDP(
            dyn.P,
            t.reward,
            t.gamma,
            terminal=t.terminal,
            admissible=dyn.admissible,
            initial=t.initial,
            features=dyn.features,
            action_names=dyn.action_names,
            name=f"{self.name}/{t.name}",
        )

    def render(
        self,
        path: str | None = None,
        *,
        values: np.ndarray | None = None,
        marked: np.ndarray | None = None,
        labels: np.ndarray | None = None,
        title: str | None = None,
        task: Task | str | None = None,
        value_label: str = "value",
        mark_label: str = "marked states",
    ) -> Figure:
        """Draw the domain, optionally with a value per state, marked states or a label per state.

        Overlays on factored domains are reduced to one value per cell (the max over the other
        features for ``values``; any for ``marked``; the first state's label for ``labels``).
        ``task`` (default: the default task) gives the goal (G) and start (S) letters;
        ``value_label`` names the colour bar, ``mark_label`` the marked cells in the legend.
        Saves a PNG when ``path`` is given and returns the matplotlib Figure.
        """
        from adpart.envs.render import render_domain

        return render_domain(self, path, values=values, marked=marked, labels=labels, title=title,
                             task=task, value_label=value_label, mark_label=mark_label)

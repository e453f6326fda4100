"""Exact finite MDPs from MiniGrid environments: ``get_domain("minigrid:<id>[seed=0]")``.

:class:`MiniGridDomain` turns one seeded layout of a `MiniGrid <https://minigrid.farama.org>`_
environment (FourRooms, DoorKey, MultiRoom, LavaGap, Empty, ...) into an adpart
:class:`~adpart.envs.base.Domain` by enumerating every state the agent can reach from the
environment's start, so its model can be solved, partitioned and stored like a built-in domain's.
The ``minigrid`` package is an optional extra (``pip install 'adpart[minigrid]'``); it is imported
only when a ``minigrid:`` name is resolved.

Layout. MiniGrid draws a new layout (walls, goal, key, agent start ...) at every ``reset``. The
adapter calls ``reset(seed=seed)`` once (default seed 0) and keeps that layout: the MDP is the
dynamics of one fixed layout, as in the options literature's FourRooms.

States. A state is everything that determines the future on that layout: the agent's cell
``(x, y)`` and direction, the object it carries, the open/locked state of every door, and where
every movable object (key, ball, box) lies. Grid contents are kept by object *identity*, so two
indistinguishable keys swapped count as two states (an exact, if not minimal, model). Terminal
states are separate absorbing copies: a transition MiniGrid flags ``terminated`` (stepping on the
goal or on lava, a mission fulfilled or failed) leads to the copy of its successor with feature
``outcome`` = 1 (success: MiniGrid paid a positive reward) or 2 (failure: reward 0, e.g. lava),
whatever the same cell would be without termination. That keeps termination a function of the
state even where MiniGrid ends an episode on an action rather than an arrival (the ``done``
action of GoToDoor). ``truncated`` (MiniGrid's ``max_steps``) is ignored: adpart sets its own
step limits.

Enumeration. Breadth-first search over the environment's own ``step``: restore a state, step one
action, read the successor. MiniGrid's rules are never re-implemented. Restoring is cheap: the
agent's position, direction and step counter, the carried object and the door flags are set
directly, and the grid's cell list is rewritten only when the grid configuration differs from the
one the environment holds. Each step's observation (MiniGrid's partial view, the costliest part of
``step``, which never changes the state) is skipped by stubbing ``gen_obs`` on the instance, and
``grid.set`` is wrapped to notice when a step changed the grid. Environments whose ``step`` draws
random numbers (Dynamic-Obstacles) are refused, as are the BabyAI levels, whose mission verifier
keeps state outside the grid.

Actions. MiniGrid's seven: ``left``, ``right``, ``forward``, ``pickup``, ``drop``, ``toggle``,
``done``. With ``actions="effective"`` (the default) only the actions that change the state of at
least one reachable non-terminal state are kept (Empty, FourRooms, LavaGap: left, right,
forward; DoorKey: also pickup, drop, toggle); ``actions="all"`` keeps all seven in MiniGrid's
order. The domain's ``action_names`` say which were kept.

Reward. MiniGrid pays ``1 - 0.9 * step_count / max_steps`` on success, which depends on the time
in the episode, not on the state. The ``reward`` task is its state-based counterpart: +1 on
arrival in a success state, 0 for every other transition (lava included), gamma 0.99 by default,
so ``V*(s) = gamma^(d-1)`` for a state ``d`` actions from success and shorter paths are preferred
as MiniGrid's decaying reward prefers them. ``goal:x=..,y=..`` tasks take the same scale (+1 on
arrival, gamma 0.99, step cost 0).
"""

from __future__ import annotations

import difflib
import time
from collections.abc import Mapping
from functools import cached_property
from typing import TYPE_CHECKING, Any, ClassVar

import gymnasium
import numpy as np
import scipy.sparse as sp

from adpart.envs.base import Domain, Dynamics, GoalSpec, Task, TaskFactory
from adpart.errors import ModelError, TaskError, UnknownNameError

if TYPE_CHECKING:
    from matplotlib.axes import Axes

#: MiniGrid's actions, in its order (``minigrid.core.actions.Actions``).
ACTION_NAMES: tuple[str, ...] = ("left", "right", "forward", "pickup", "drop", "toggle", "done")
ACTION_CHOICES = ("effective", "all")
#: Most states enumerated before the adapter gives up (``max_states``' default).
MAX_STATES = 2_000_000
#: Object types that can change place (picked up, dropped, revealed from a box).
MOVABLE = ("key", "ball", "box")
#: ``outcome`` feature values.
RUNNING, SUCCESS, FAILURE = 0, 1, 2
#: MiniGrid's door state code (``Door.encode``): 0 open, 1 closed, 2 locked.
DOOR_OPEN, DOOR_CLOSED, DOOR_LOCKED = 0, 1, 2
INSTALL_HINT = "pip install 'adpart[minigrid]'"


def import_minigrid() -> Any:
    """Import ``minigrid`` (registering its Gymnasium ids), or say how to install it."""
    try:
        import minigrid
    except ImportError as exc:
        raise UnknownNameError(
            f"minigrid: environments need the optional package 'minigrid' ({exc}); install the "
            f"extra with {INSTALL_HINT} (or pip install 'minigrid>=3.0')"
        ) from None
    return minigrid


def minigrid_ids() -> list[str]:
    """The registered MiniGrid ids (BabyAI levels excluded), after :func:`import_minigrid`."""
    return sorted(
        k for k, spec in gymnasium.registry.items()
        if isinstance(spec.entry_point, str) and spec.entry_point.startswith("minigrid.envs:")
    )


def make_minigrid(env_id: str, **make_kwargs: Any) -> Any:
    """The unwrapped MiniGrid environment ``env_id`` (adpart errors for unknown ids and args).

    Raises:
        UnknownNameError: ``minigrid`` is not installed, or ``env_id`` is not a MiniGrid id.
        ModelError: a BabyAI level, or keyword arguments the environment rejects.
    """
    import_minigrid()
    spec = gymnasium.registry.get(env_id)
    entry = spec.entry_point if spec is not None else None
    if isinstance(entry, str) and entry.startswith("minigrid.envs.babyai"):
        raise ModelError(
            f"minigrid:{env_id} is a BabyAI level, whose mission verifier keeps state outside the "
            "grid, so its states cannot be enumerated from the grid; use a MiniGrid-* id"
        )
    if not (isinstance(entry, str) and entry.startswith("minigrid.envs:")):
        known = minigrid_ids()
        hint = difflib.get_close_matches(env_id, known, n=1)
        raise UnknownNameError(
            f"MiniGrid has no environment {env_id!r}"
            + (f". Did you mean minigrid:{hint[0]}?" if hint else ".")
            + " Ids are case-sensitive and versioned, e.g. minigrid:MiniGrid-FourRooms-v0, "
            "minigrid:MiniGrid-DoorKey-5x5-v0, minigrid:MiniGrid-Empty-8x8-v0"
        )
    try:
        env = gymnasium.make(env_id, disable_env_checker=True, **make_kwargs)
    except TypeError as exc:
        raise ModelError(
            f"minigrid:{env_id} rejected the arguments {sorted(make_kwargs)}: {exc}. Pass only "
            "keyword arguments its constructor accepts (and seed=, gamma=, actions=, "
            "max_states= for the adapter)"
        ) from None
    return env.unwrapped


class _Interner:
    """Numbers hashable values in order of first sight (``index``) and keeps them (``items``)."""

    __slots__ = ("index", "items")

    def __init__(self) -> None:
        self.index: dict[object, int] = {}
        self.items: list[Any] = []

    def __call__(self, value: object) -> int:
        k = self.index.get(value)
        if k is None:
            k = self.index[value] = len(self.items)
            self.items.append(value)
        return k


class StateSpace:
    """The reachable states of one seeded MiniGrid layout and their transitions.

    Built by :meth:`enumerate` (breadth-first over ``env.step``; see the module docstring). A
    state is an int key ``(((config * H + y) * W + x) * 4 + dir) * 3 + outcome``, where
    ``config`` numbers the distinct (grid contents, door flags, carried object) combinations
    met; :meth:`restore` puts the environment into any enumerated state.

    Attributes (after :meth:`enumerate`):
        keys: ``(S,)`` int64 state keys, in discovery order (state 0 is the start).
        succ: ``(S, 7)`` int64 successor of each state under each MiniGrid action (terminal
            states loop on themselves).
        parent: ``(S,)`` int64 the state each state was first reached from (-1 for the start),
            and ``parent_action`` the action taken: a shortest action path to every state.
        seconds: the enumeration's wall-clock time.
    """

    def __init__(self, env: Any, env_id: str, max_states: int = MAX_STATES) -> None:
        self.env, self.env_id, self.max_states = env, env_id, int(max_states)
        self.W, self.H = int(env.width), int(env.height)
        self.cells: list[Any] = env.grid.grid  # mutated in place by Grid.set and by restore
        self.doors = [c for c in self.cells if c is not None and c.type == "door"]
        self.movable = self._movable_objects()
        self.layouts = _Interner()  # tuple(grid cells) -> layout number
        self.configs = _Interner()  # (layout, door code, carried object number) -> config
        self.carried = _Interner()  # the carried object, by identity (0: nothing)
        self.carried(None)
        self._grid_changed = False  # set by the wrapped grid.set during enumeration
        self.live = -1  # the config the environment holds (-1: unknown)
        self._live_carry: Any = None
        self._live_doors = 0
        self.start_key = self._key(self._config_now(), RUNNING)
        self.keys = np.zeros(0, dtype=np.int64)
        self.succ = np.zeros((0, len(ACTION_NAMES)), dtype=np.int64)
        self.parent = np.zeros(0, dtype=np.int64)
        self.parent_action = np.zeros(0, dtype=np.int64)
        self.seconds = 0.0

    def _movable_objects(self) -> list[Any]:
        """Every key, ball and box of the layout (boxes' contents and the carried object too),
        in row-major order of where they start."""
        found: list[Any] = []
        pending = [c for c in self.cells if c is not None] + [self.env.carrying]
        while pending:
            obj = pending.pop(0)
            if obj is None:
                continue
            if obj.type in MOVABLE and all(obj is not o for o in found):
                found.append(obj)
            if obj.contains is not None:
                pending.append(obj.contains)
        return found

    # ------------------------------------------------------------------ configs
    def _door_code(self) -> int:
        """The doors' MiniGrid state codes as one base-3 number (first door most significant)."""
        code = 0
        for door in self.doors:
            code = code * 3 + (
                DOOR_OPEN if door.is_open else DOOR_LOCKED if door.is_locked else DOOR_CLOSED
            )
        return code

    def _config_now(self) -> int:
        """The config the environment is in, registered if new (the slow path: after a step
        that changed the grid, a door or the carried object). Makes it the live config."""
        if self._grid_changed or self.live < 0:
            layout = self.layouts(tuple(self.cells))
            self._grid_changed = False
        else:
            layout = self.configs.items[self.live][0]
        self._live_doors = self._door_code()
        self._live_carry = self.env.carrying
        self.live = self.configs((layout, self._live_doors, self.carried(self._live_carry)))
        return self.live

    def _apply_config(self, config: int) -> None:
        """Rewrite the grid's cells, the door flags and the carried object to ``config``."""
        layout, door_code, carried = self.configs.items[config]
        self.cells[:] = self.layouts.items[layout]
        self._live_doors = door_code
        for door in reversed(self.doors):
            door_code, state = divmod(door_code, 3)
            door.is_open = state == DOOR_OPEN
            door.is_locked = state == DOOR_LOCKED
        self._live_carry = self.env.carrying = self.carried.items[carried]
        self.live = config
        self._grid_changed = False

    def _key(self, config: int, outcome: int) -> int:
        """The key of the environment's agent in ``config`` with ``outcome``."""
        x, y = self.env.agent_pos
        cell = (config * self.H + int(y)) * self.W + int(x)
        return (cell * 4 + int(self.env.agent_dir)) * 3 + outcome

    def split(self, key: int) -> tuple[int, int, int, int, int]:
        """``(config, x, y, dir, outcome)`` of a state key."""
        rest, outcome = divmod(key, 3)
        rest, d = divmod(rest, 4)
        rest, x = divmod(rest, self.W)
        config, y = divmod(rest, self.H)
        return config, x, y, d, outcome

    def restore(self, key: int) -> None:
        """Put the environment into the state ``key`` (cells rewritten only on a config change)."""
        config, x, y, d, _ = self.split(key)
        if config != self.live:
            self._apply_config(config)
        env = self.env
        env.agent_pos, env.agent_dir, env.step_count = (x, y), d, 0

    # ------------------------------------------------------------------ enumeration
    def enumerate(self) -> StateSpace:
        """Breadth-first search from the start over all seven actions (see the class doc).

        The loop is the hot path: per (state, action) it sets the agent, calls ``env.step``
        (whose observation is stubbed out) and numbers the successor; the config is looked up
        again only when the step changed the grid, a door or the carried object.
        """
        env = self.env
        grid = env.grid
        original_set = grid.set

        def recording_set(i: int, j: int, v: Any) -> None:
            self._grid_changed = True
            original_set(i, j, v)

        rng_before = env.np_random.bit_generator.state

        def check_rng() -> None:
            """Refuse a ``step`` that drew random numbers (checked after the start's actions,
            every 1024 states and at the end, so a random environment fails fast)."""
            if env.np_random.bit_generator.state != rng_before:
                raise ModelError(
                    f"minigrid:{self.env_id}'s step draws random numbers (e.g. moving "
                    "obstacles), so its transitions are not a function of the grid state; only "
                    "deterministic MiniGrid environments can be enumerated into an exact model"
                )

        grid.set = recording_set
        env.gen_obs = lambda: None
        begun = time.perf_counter()
        A = len(ACTION_NAMES)
        H, W = self.H, self.W
        step, door_code, has_doors = env.step, self._door_code, bool(self.doors)
        index = {self.start_key: 0}
        keys = [self.start_key]
        succ: list[int] = []
        parent, parent_action = [-1], [-1]
        limit = self.max_states
        try:
            for i, key in enumerate(keys):  # keys grows while it is walked: breadth first
                if i & 1023 == 1:
                    check_rng()
                config, x, y, d, outcome = self.split(key)
                if outcome != RUNNING:  # terminal: absorbing
                    succ.extend([i] * A)
                    continue
                pos = (x, y)
                for a in range(A):
                    if self.live != config:
                        self._apply_config(config)
                    env.agent_pos, env.agent_dir, env.step_count = pos, d, 0
                    _, reward, terminated, _, _ = step(a)
                    if (self._grid_changed or env.carrying is not self._live_carry
                            or (has_doors and door_code() != self._live_doors)):
                        now = self._config_now()
                    else:
                        now = config
                    if terminated:
                        out = SUCCESS if reward > 0 else FAILURE
                    elif reward != 0:
                        raise ModelError(
                            f"minigrid:{self.env_id} paid reward {reward} on a transition that "
                            "does not end the episode; the adapter's state-based reward covers "
                            "rewards on termination only"
                        )
                    else:
                        out = RUNNING
                    nx, ny = env.agent_pos
                    nxt = (((now * H + int(ny)) * W + int(nx)) * 4 + env.agent_dir) * 3 + out
                    j = index.get(nxt)
                    if j is None:
                        j = index[nxt] = len(keys)
                        keys.append(nxt)
                        parent.append(i)
                        parent_action.append(a)
                        if j >= limit:
                            raise ModelError(
                                f"minigrid:{self.env_id} has more than {limit:,} reachable "
                                "states; choose a smaller layout (e.g. a smaller size= or "
                                "fewer rooms) or raise the bound with [max_states=N]"
                            )
                    succ.append(j)
        finally:
            grid.set = original_set
            del env.gen_obs  # back to the class's method
            self.live = -1
            self.restore(self.start_key)  # the start: cells, doors, carried object, agent
        check_rng()
        self.seconds = time.perf_counter() - begun
        self.keys = np.asarray(keys, dtype=np.int64)
        self.succ = np.asarray(succ, dtype=np.int64).reshape(len(keys), A)
        self.parent = np.asarray(parent, dtype=np.int64)
        self.parent_action = np.asarray(parent_action, dtype=np.int64)
        return self

    # ------------------------------------------------------------------ reading states
    def decode(self) -> dict[str, np.ndarray]:
        """``config``, ``x``, ``y``, ``dir`` and ``outcome`` of every state (vectorised)."""
        rest, outcome = np.divmod(self.keys, 3)
        rest, d = np.divmod(rest, 4)
        rest, x = np.divmod(rest, self.W)
        config, y = np.divmod(rest, self.H)
        return {"config": config, "x": x, "y": y, "dir": d, "outcome": outcome}

    def config_features(self) -> dict[str, np.ndarray]:
        """Per config: the carried object's type and colour codes, each door's state code and
        each movable object's cell (-1, -1 when carried or not on the grid)."""
        from minigrid.core.constants import COLOR_TO_IDX, OBJECT_TO_IDX

        n = len(self.configs.items)
        out: dict[str, np.ndarray] = {
            "carrying": np.zeros(n, dtype=np.int64),
            "carrying_color": np.full(n, -1, dtype=np.int64),
        }
        for k, _ in enumerate(self.doors):
            out[f"door{k}"] = np.zeros(n, dtype=np.int64)
        names = movable_names(self.movable)
        for name in names:
            out[f"{name}_x"] = np.full(n, -1, dtype=np.int64)
            out[f"{name}_y"] = np.full(n, -1, dtype=np.int64)
        where: dict[int, dict[int, int]] = {}  # layout -> id(object) -> cell
        for c, (layout, door_code, carried) in enumerate(self.configs.items):
            obj = self.carried.items[carried]
            if obj is not None:
                out["carrying"][c] = OBJECT_TO_IDX[obj.type]
                out["carrying_color"][c] = COLOR_TO_IDX[obj.color]
            for k in reversed(range(len(self.doors))):
                door_code, out[f"door{k}"][c] = divmod(door_code, 3)
            if layout not in where:
                where[layout] = {
                    id(o): i for i, o in enumerate(self.layouts.items[layout]) if o is not None
                }
            for name, o in zip(names, self.movable, strict=True):
                cell = where[layout].get(id(o))
                if cell is not None:
                    out[f"{name}_y"][c], out[f"{name}_x"][c] = divmod(cell, self.W)
        return out


def movable_names(objects: list[Any]) -> list[str]:
    """``key0``, ``ball0``, ``ball1`` ...: each movable object's type and number within it."""
    seen: dict[str, int] = {}
    names = []
    for obj in objects:
        k = seen.get(obj.type, 0)
        seen[obj.type] = k + 1
        names.append(f"{obj.type}{k}")
    return names


def assemble(succ: np.ndarray) -> sp.csr_array:
    """The ``(A*S, S)`` CSR of deterministic successors ``succ`` (``(S, A)``): row ``a*S + s``
    holds one 1 at column ``succ[s, a]``, built straight from its index arrays."""
    S, A = succ.shape
    return sp.csr_array(
        (np.ones(A * S), np.ascontiguousarray(succ.T).reshape(-1), np.arange(A * S + 1)),
        shape=(A * S, S),
    )


class MiniGridDomain(Domain):
    """One seeded layout of a MiniGrid environment, as an exact adpart domain.

    Args:
        env_id: a registered MiniGrid id (``MiniGrid-FourRooms-v0``, ``MiniGrid-DoorKey-5x5-v0``).
        seed: the seed of the one ``reset`` that generates the layout.
        gamma: discount factor of the ``reward`` task and of ``goal:`` tasks.
        actions: ``"effective"`` (the actions that change some state) or ``"all"`` (MiniGrid's 7).
        max_states: the enumeration stops with :class:`ModelError` past this many states.
        **make_kwargs: passed to ``gymnasium.make`` (e.g. ``size=``, ``max_steps=``).

    Raises:
        UnknownNameError: ``minigrid`` is not installed, or ``env_id`` is no MiniGrid id.
        ModelError: a BabyAI level or a random ``step`` (refused), arguments the environment
            rejects, more than ``max_states`` reachable states.
    """

    default_task = "reward"
    goal_defaults: ClassVar[Mapping[str, object]] = {"goal_reward": 1.0, "gamma": 0.99}

    def __init__(
        self,
        env_id: str,
        *,
        seed: int = 0,
        gamma: float = 0.99,
        actions: str = "effective",
        max_states: int = MAX_STATES,
        **make_kwargs: Any,
    ) -> None:
        if actions not in ACTION_CHOICES:
            raise TaskError(f"actions={actions!r}; use one of {', '.join(ACTION_CHOICES)}")
        if not 0.0 < gamma <= 1.0:
            raise TaskError(f"gamma = {gamma!r} is outside (0, 1]")
        if int(max_states) <= 0:
            raise TaskError("max_states must be positive")
        self.env_id, self.seed, self.gamma = env_id, int(seed), float(gamma)
        self.actions, self.max_states = actions, int(max_states)
        self.make_kwargs = dict(make_kwargs)
        self.goal_defaults = {"goal_reward": 1.0, "gamma": self.gamma}
        minigrid = import_minigrid()
        self.env = make_minigrid(env_id, **make_kwargs)
        self.env.reset(seed=self.seed)
        shown = dict(self.make_kwargs)
        if self.seed != 0:
            shown["seed"] = self.seed
        if actions != "effective":
            shown["actions"] = actions
        suffix = ",".join(f"{k}={v}" for k, v in sorted(shown.items()))
        self.name = f"minigrid:{env_id}" + (f"[{suffix}]" if suffix else "")
        self.source = f"MiniGrid {minigrid.__version__}: {type(self.env).__name__}"
        self.description = (
            f"MiniGrid {env_id}, layout of seed {self.seed}, exact model enumerated by "
            "breadth-first search over its step()"
        )
        self.layout_grid = list(self.env.grid.grid)  # the static picture, for render

    # ------------------------------------------------------------ the model
    @cached_property
    def space(self) -> StateSpace:
        """The enumerated states (built on first use, then cached)."""
        return StateSpace(self.env, self.env_id, self.max_states).enumerate()

    @cached_property
    def kept_actions(self) -> np.ndarray:
        """MiniGrid action numbers the domain exposes, in order (see ``actions``)."""
        if self.actions == "all":
            return np.arange(len(ACTION_NAMES))
        space = self.space
        live = space.keys % 3 == RUNNING
        moved = (space.succ != np.arange(space.succ.shape[0])[:, None]) & live[:, None]
        return np.flatnonzero(moved.any(axis=0))

    def model_facts(self) -> dict[str, object]:
        """JSON-able facts about the enumeration (sizes, time, what each feature counts)."""
        space = self.space
        outcome = space.keys % 3
        return {
            "env_id": self.env_id,
            "seed": self.seed,
            "make_kwargs": {k: repr(v) for k, v in self.make_kwargs.items()},
            "n_states": int(space.keys.size),
            "success_states": int((outcome == SUCCESS).sum()),
            "failure_states": int((outcome == FAILURE).sum()),
            "grid_configs": len(space.configs.items),
            "actions": [ACTION_NAMES[a] for a in self.kept_actions],
            "doors": len(space.doors),
            "movable_objects": movable_names(space.movable),
            "enumeration_seconds": round(space.seconds, 3),
        }

    # ------------------------------------------------------------ Domain API
    def _build_dynamics(self) -> Dynamics:
        space = self.space
        kept = self.kept_actions
        feats = space.decode()
        per_config = space.config_features()
        config = feats.pop("config")
        feats.update({name: values[config] for name, values in per_config.items()})
        S = space.keys.size
        start = np.zeros(S)
        start[0] = 1.0
        return Dynamics(
            P=assemble(space.succ[:, kept]),
            action_names=tuple(ACTION_NAMES[a] for a in kept),
            action_costs=np.zeros(kept.size),
            features=feats,
            admissible=None,
            start=start,
        )

    def tasks(self) -> Mapping[str, TaskFactory | GoalSpec]:
        return {"reward": self._reward_task}

    def _reward_task(self, domain: Domain) -> Task:
        dyn = self.dynamics()
        outcome = dyn.features["outcome"]
        success = outcome == SUCCESS
        S, A = dyn.n_states, dyn.n_actions
        reward = (dyn.P @ success.astype(np.float64)).reshape(A, S).T
        return Task(
            name="reward",
            reward=np.ascontiguousarray(reward),
            terminal=outcome != RUNNING,
            initial=np.asarray(dyn.start, dtype=np.float64),
            gamma=self.gamma,
            description="+1 on reaching success (MiniGrid's goal or mission), 0 otherwise",
            spec={"kind": "minigrid-reward", "env_id": self.env_id, "seed": self.seed,
                  "gamma": self.gamma},
        )

    # ------------------------------------------------------------ drawing
    def layout(self) -> np.ndarray:
        """``(1, H, W)`` bool: the cells that are not walls on the seeded layout."""
        free = np.array([c is None or c.type != "wall" for c in self.layout_grid], dtype=bool)
        return free.reshape(1, int(self.env.height), int(self.env.width))

    def draw_extras(self, ax: Axes, floor: int) -> list[tuple[str, str, str]]:
        """Draw the layout's objects where they start: goal (green frame), lava (orange
        hatching), doors (a frame in the door's colour, ``D``; locked ``L``), keys ``K``,
        balls ``o`` and boxes ``B`` in their colours. Returns the legend entries."""
        from matplotlib import patheffects
        from matplotlib.patches import Rectangle

        W = int(self.env.width)
        small = max(W, int(self.env.height)) <= 40
        entries: dict[str, tuple[str, str, str]] = {}
        for i, obj in enumerate(self.layout_grid):
            if obj is None or obj.type in ("wall", "floor"):
                continue
            y, x = divmod(i, W)
            colour = _mpl_colour(obj.color)
            if obj.type == "goal":
                ax.add_patch(Rectangle((x - 0.45, y - 0.45), 0.9, 0.9, fill=False,
                                       edgecolor="tab:green", linewidth=2.5, zorder=2))
                entries["goal"] = ("□", "tab:green", "MiniGrid goal")
            elif obj.type == "lava":
                ax.add_patch(Rectangle((x - 0.5, y - 0.5), 1, 1, fill=False, hatch="xxx",
                                       edgecolor="tab:orange", linewidth=0, zorder=2))
                entries["lava"] = ("x", "tab:orange", "lava (ends the episode)")
            else:
                letter = {"door": "L" if obj.type == "door" and obj.is_locked else "D",
                          "key": "K", "ball": "o", "box": "B"}.get(obj.type, obj.type[0].upper())
                if obj.type == "door":
                    ax.add_patch(Rectangle((x - 0.45, y - 0.45), 0.9, 0.9, fill=False,
                                           edgecolor=colour, linewidth=2, zorder=2))
                ax.text(x, y, letter, ha="center", va="center", color=colour, zorder=5,
                        fontsize=10 if small else 5, fontweight="bold", gid="minigrid-object",
                        path_effects=[patheffects.withStroke(linewidth=2, foreground="black")])
                meaning = {"D": "door", "L": "locked door", "K": "key (start)",
                           "o": "ball (start)", "B": "box (start)"}.get(letter, obj.type)
                entries[letter] = (letter, colour, meaning)
        return list(entries.values())


def _mpl_colour(name: str) -> str:
    """MiniGrid's colour names as matplotlib colours (its ``grey`` and ``yellow`` darkened so
    they read on the light free cells)."""
    return {"yellow": "goldenrod", "grey": "dimgrey"}.get(name, f"tab:{name}")

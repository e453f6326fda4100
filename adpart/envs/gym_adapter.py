"""Finite MDPs from Gymnasium environments: ``get_domain("gym:<id>")``.

:class:`GymDomain` turns a Gymnasium environment with ``Discrete`` observation and action spaces
into an adpart :class:`~adpart.envs.base.Domain`, so its model can be solved, partitioned and
stored like a built-in domain's. Two ways to get the model:

* **exact** - toy-text environments (Taxi-v4, FrozenLake-v1, CliffWalking-v1 ...) publish their
  model as ``env.unwrapped.P[s][a] = [(prob, next_state, reward, terminated), ...]``. It is
  flattened in one pass into arrays and assembled into the ``(A*S, S)`` CSR of
  :class:`~adpart.mdp.model.FiniteMDP` with duplicate successors merged; the expected reward is
  ``R(s, a) = sum_k p_k r_k`` (our models keep expected one-step rewards, dissertation eq. 3.1).
* **estimated** - any other discrete environment: ``samples`` transitions from random-policy
  episodes (uniform actions, seeded), giving the maximum-likelihood model
  ``P(s'|s,a) = n(s,a,s') / n(s,a)`` and ``R(s, a) = mean reward``. Pairs never tried get a
  self-loop with reward 0 and are flagged in :attr:`GymDomain.unvisited`.

Termination. Gymnasium flags *transitions* as terminating; adpart's models end an episode on
*arrival* in a terminal *state* (value 0). The terminal states are therefore the successors of
``terminated=True`` transitions. That is faithful only if no state is reached both with and
without termination. A conflict whose non-terminating arrivals all start in states no episode can
occupy (not reachable from the start distribution without terminating first) cannot change any
episode: such states are recorded in :attr:`GymDomain.done_conflicts` and made terminal. Taxi has
four of them: after a delivery the passenger stands at the destination, and Taxi's ``P`` also
lists moves among those post-delivery states, which arrive there without terminating. Any other
conflict raises :class:`ModelError`, because the environment's termination then depends on the
path, which no state-based terminal mask can represent.

The single task is ``reward``: the environment's own rewards, terminal states and start
distribution, with discount ``gamma`` (default 0.99).
"""

from __future__ import annotations

import difflib
import importlib
import json
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import gymnasium
import numpy as np
import scipy.sparse as sp
from gymnasium import spaces

from adpart.envs.base import Domain, Dynamics, GoalSpec, Task, TaskFactory
from adpart.errors import ModelError, TaskError, UnknownNameError

#: Feature names for the tuple ``env.unwrapped.decode(s)`` returns, by environment class.
DECODE_NAMES: dict[str, tuple[str, ...]] = {
    "TaxiEnv": ("row", "col", "passenger", "destination"),
}

#: Action names of the toy-text environments, by environment class.
ACTION_NAMES: dict[str, tuple[str, ...]] = {
    "TaxiEnv": ("south", "north", "east", "west", "pickup", "dropoff"),
    "FrozenLakeEnv": ("left", "down", "right", "up"),
    "CliffWalkingEnv": ("up", "right", "down", "left"),
}

MODEL_KINDS = ("auto", "exact", "sampled")


@dataclass(frozen=True, eq=False)
class GymModel:
    """The model read from (or estimated on) a Gymnasium environment.

    Attributes:
        P: ``(A*S, S)`` CSR transition matrix, row ``a*S + s``.
        R: ``(S, A)`` expected immediate reward.
        terminal: ``(S,)`` bool, successors of terminating transitions.
        initial: ``(S,)`` start distribution.
        reachable: ``(S,)`` bool, states an episode can occupy before it terminates.
        done_conflicts: states reached both with and without termination, where every
            non-terminating arrival starts in an unreachable state (harmless; made terminal).
        visits: ``(S, A)`` int64 sample count per pair (estimated models; None when exact).
        unvisited: ``(S, A)`` bool, pairs given a placeholder self-loop (never sampled).
        n_samples: transitions sampled (0 when exact).
        initial_source: where the start distribution came from.
    """

    P: sp.csr_array
    R: np.ndarray
    terminal: np.ndarray
    initial: np.ndarray
    reachable: np.ndarray
    done_conflicts: np.ndarray
    visits: np.ndarray | None
    unvisited: np.ndarray
    n_samples: int
    initial_source: str


def make_env(env_id: str, **make_kwargs: Any) -> gymnasium.Env:
    """``gymnasium.make(env_id, **make_kwargs)`` with adpart errors for unknown ids and bad args.

    ``module:Id-v0`` imports ``module`` first (which registers the id), as ``gymnasium.make``
    does; ``gymnasium.spec`` alone does not, so the lookup is made with the bare id.
    """
    lookup = env_id
    if ":" in env_id:
        module, _, lookup = env_id.partition(":")
        try:
            importlib.import_module(module)
        except ImportError as exc:
            raise UnknownNameError(
                f"Gymnasium has no environment {env_id!r}: cannot import module {module!r} "
                f"({exc}); install the package that provides it, or write gym:Id-v0 for a "
                "registered id"
            ) from None
    try:
        gymnasium.spec(lookup)
    except (gymnasium.error.Error, ModuleNotFoundError) as exc:
        known = [k for k in gymnasium.registry if "/" not in k or k.startswith("adpart/")]
        hint = difflib.get_close_matches(env_id, known, n=1)
        raise UnknownNameError(
            f"Gymnasium has no environment {env_id!r} ({exc})"
            + (f". Did you mean gym:{hint[0]}?" if hint else "")
            + ". Ids are case-sensitive and versioned, e.g. gym:Taxi-v4, gym:FrozenLake-v1, "
            "gym:CliffWalking-v1; a third-party id needs its package imported or written as "
            "gym:module:Id-v0"
        ) from None
    try:
        return gymnasium.make(env_id, **make_kwargs)
    except TypeError as exc:
        raise ModelError(
            f"gym:{env_id} rejected the arguments {sorted(make_kwargs)}: {exc}. Pass only "
            "keyword arguments its constructor accepts"
        ) from None
    except ImportError as exc:  # e.g. tabular/CliffWalking-v0 needs jax
        raise ModelError(
            f"gym:{env_id} needs a package that is not installed ({exc}); install it, or use "
            "the environment's plain id (gym:CliffWalking-v1 for the NumPy version)"
        ) from None
    except (ValueError, AssertionError, gymnasium.error.Error) as exc:
        raise ModelError(f"gym:{env_id} could not be made with {make_kwargs}: {exc}") from None


#: Keyword arguments adpart reads itself to give FrozenLake a seeded random map (Gymnasium's own
#: map_name=None draws an unseeded one on every construction, which names no single MDP).
RANDOM_MAP = ("random_map", "map_seed")


def seeded_map(env_id: str, make_kwargs: dict[str, Any]) -> dict[str, Any]:
    """``make_kwargs`` with ``random_map=SIZE`` (and ``map_seed=N``, default 0) replaced by the
    ``desc`` of Gymnasium's ``generate_random_map(SIZE, seed=N)`` (FrozenLake only)."""
    if "random_map" not in make_kwargs:
        if "map_seed" in make_kwargs:
            raise TaskError(f"gym:{env_id}: map_seed seeds random_map=SIZE; give both")
        return make_kwargs
    kwargs = dict(make_kwargs)
    size, seed = kwargs.pop("random_map"), kwargs.pop("map_seed", 0)
    if not env_id.startswith("FrozenLake"):
        raise TaskError(f"gym:{env_id}: random_map=SIZE draws a FrozenLake map; "
                        f"{env_id} takes its layout from its own arguments")
    if not isinstance(size, int) or isinstance(size, bool) or not 2 <= size <= 64:
        raise TaskError(f"gym:{env_id}: random_map = {size!r} must be a map size in [2, 64]")
    if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
        raise TaskError(f"gym:{env_id}: map_seed = {seed!r} must be an integer >= 0")
    from gymnasium.envs.toy_text.frozen_lake import generate_random_map

    kwargs["desc"] = generate_random_map(size=size, seed=seed)
    return kwargs


def _same_model(p: Any, q: Any) -> bool:
    """Whether two ``env.unwrapped.P`` tables are the same model (entry for entry)."""
    try:
        return bool(p == q)
    except ValueError:  # array entries: compare as text
        return repr(p) == repr(q)


def _name_value(value: object) -> str:
    """A keyword value as the domain's name writes it, read back alike by the name parser:
    lists and mappings as compact JSON, anything else as text."""
    if isinstance(value, list | tuple | dict):
        return json.dumps(value, separators=(",", ":"))
    return str(value)


def discrete_size(space: object, what: str, env_id: str) -> tuple[int, int]:
    """``(n, start)`` of a ``Discrete`` space, else a :class:`ModelError` naming the space."""
    if not isinstance(space, spaces.Discrete):
        raise ModelError(
            f"gym:{env_id} has {what} space {space!r}; a finite MDP needs Discrete observation and "
            "action spaces. Discretise the environment first (e.g. a wrapper mapping observations "
            "to integers 0..n-1) or use a built-in domain"
        )
    return int(space.n), int(space.start)


def _closure(adjacency: sp.csr_array, seeds: np.ndarray) -> np.ndarray:
    """``(S,)`` bool: states reachable from ``seeds`` along ``adjacency`` (BFS by levels)."""
    seen = seeds.copy()
    frontier = seeds.copy()
    forward = sp.csr_array(adjacency.T)
    while frontier.any():
        step = (forward @ frontier.astype(np.float64)) > 0
        frontier = step & ~seen
        seen |= frontier
    return seen


def terminal_states(
    rows: np.ndarray,
    cols: np.ndarray,
    done: np.ndarray,
    initial: np.ndarray,
    n_states: int,
    env_id: str,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Terminal mask, reachable mask and harmless conflicts from flat transition arrays.

    Args:
        rows: ``(K,)`` row ``a*S + s`` of each transition with positive probability.
        cols: ``(K,)`` successor of each transition.
        done: ``(K,)`` bool, whether the transition terminates the episode.
        initial: ``(S,)`` start distribution.

    Raises:
        ModelError: a state an episode can occupy is also reached by a terminating transition.
    """
    S = n_states
    src = rows % S
    terminal = np.zeros(S, dtype=bool)
    terminal[cols[done]] = True
    going = ~done
    adjacency = sp.csr_array((np.ones(int(going.sum())), (src[going], cols[going])), shape=(S, S))
    reachable = _closure(adjacency, initial > 0)
    real = terminal & reachable
    if real.any():
        x = int(np.flatnonzero(real)[0])
        k_done = int(np.flatnonzero(done & (cols == x))[0])
        k_going = np.flatnonzero(going & (cols == x) & reachable[src])
        source = (
            f"state {int(src[k_going[0]])} action {int(rows[k_going[0]] // S)}"
            if k_going.size
            else "the start distribution"
        )
        raise ModelError(
            f"gym:{env_id}: state {x} is reached with terminated=True (from state "
            f"{int(src[k_done])} action {int(rows[k_done] // S)}) and also without termination "
            f"(from {source}), and episodes can occupy it. adpart ends episodes on arrival in a "
            "terminal state, so termination must depend on the next state only; wrap the "
            "environment so that it does (e.g. add an absorbing 'done' state)"
        )
    conflicts = np.flatnonzero(terminal & np.isin(np.arange(S), cols[going]))
    return terminal, reachable, conflicts


def model_from_p(
    P_dict: Mapping[int, Mapping[int, list]],
    n_states: int,
    n_actions: int,
    initial: np.ndarray,
    env_id: str,
    state_offset: int = 0,
) -> GymModel:
    """Build the exact model from a toy-text ``P`` dict (see the module docstring).

    The dict is flattened in one pass into ``(row, prob, next, reward, done)`` arrays; everything
    after that is vectorised (duplicates merged by the CSR conversion).
    """
    S, A = n_states, n_actions
    try:
        flat = [
            (a * S + s - state_offset, float(p), int(s2) - state_offset, float(r), bool(d))
            for s, by_action in P_dict.items()
            for a, outcomes in by_action.items()
            for p, s2, r, d in outcomes
        ]
    except (TypeError, ValueError) as exc:
        raise ModelError(
            f"gym:{env_id}: env.unwrapped.P is not of the form P[s][a] = [(prob, next_state, "
            f"reward, terminated), ...] ({exc})"
        ) from None
    if not flat:
        raise ModelError(f"gym:{env_id}: env.unwrapped.P is empty")
    table = np.array(flat, dtype=np.float64)
    rows = table[:, 0].astype(np.int64)
    probs, cols = table[:, 1], table[:, 2].astype(np.int64)
    rewards, done = table[:, 3], table[:, 4].astype(bool)
    bad = (rows < 0) | (rows >= A * S) | (cols < 0) | (cols >= S)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise ModelError(
            f"gym:{env_id}: P lists a transition ({int(rows[k]) % S}, action "
            f"{int(rows[k]) // S}) -> {int(cols[k])} outside the {S} states / {A} actions of its "
            "spaces"
        )
    present = np.bincount(rows, minlength=A * S) > 0
    if not present.all():
        r = int(np.flatnonzero(~present)[0])
        raise ModelError(
            f"gym:{env_id}: P lists no outcome for state {r % S} action {r // S}; every pair "
            "needs at least one (prob, next_state, reward, terminated) entry"
        )
    P = sp.csr_array(sp.coo_array((probs, (rows, cols)), shape=(A * S, S)))
    P.sum_duplicates()
    P.eliminate_zeros()
    R = np.bincount(rows, weights=probs * rewards, minlength=A * S).reshape(A, S).T
    live = probs > 0
    terminal, reachable, conflicts = terminal_states(
        rows[live], cols[live], done[live], initial, S, env_id
    )
    return GymModel(
        P=P,
        R=np.ascontiguousarray(R),
        terminal=terminal,
        initial=initial,
        reachable=reachable,
        done_conflicts=conflicts,
        visits=None,
        unvisited=np.zeros((S, A), dtype=bool),
        n_samples=0,
        initial_source="env.unwrapped.initial_state_distrib",
    )


def sample_transitions(
    env: gymnasium.Env,
    n_samples: int,
    seed: int,
    n_states: int,
    n_actions: int,
    offset: int = 0,
) -> tuple[np.ndarray, ...]:
    """``n_samples`` transitions of uniformly random actions, resetting whenever an episode ends.

    Returns:
        ``(states, actions, next_states, rewards, terminated, starts)`` arrays; ``starts`` holds
        the start state of every episode begun.
    """
    rng = np.random.default_rng(seed)
    actions = rng.integers(n_actions, size=n_samples)
    states = np.empty(n_samples, dtype=np.int64)
    nexts = np.empty(n_samples, dtype=np.int64)
    rewards = np.empty(n_samples, dtype=np.float64)
    ended = np.empty(n_samples, dtype=bool)
    obs, _ = env.reset(seed=seed)
    starts = [int(obs)]
    for i in range(n_samples):
        obs2, r, terminated, truncated, _ = env.step(int(actions[i]) + int(env.action_space.start))
        states[i], nexts[i], rewards[i], ended[i] = obs, obs2, r, terminated
        if terminated or truncated:
            obs, _ = env.reset()
            starts.append(int(obs))
        else:
            obs = obs2
    shift = np.int64(offset)
    return (
        states - shift,
        actions.astype(np.int64),
        nexts - shift,
        rewards,
        ended,
        np.asarray(starts, dtype=np.int64) - shift,
    )


def model_from_samples(
    states: np.ndarray,
    actions: np.ndarray,
    nexts: np.ndarray,
    rewards: np.ndarray,
    terminated: np.ndarray,
    starts: np.ndarray,
    n_states: int,
    n_actions: int,
    env_id: str,
) -> GymModel:
    """Maximum-likelihood model of sampled transitions (vectorised counting).

    ``P(s'|s,a) = n(s,a,s') / n(s,a)``, ``R(s,a)`` the mean observed reward; unvisited pairs get a
    self-loop with reward 0 and are flagged. The start distribution is the empirical one of
    ``starts``.
    """
    S, A = n_states, n_actions
    rows = actions * S + states
    visits_flat = np.bincount(rows, minlength=A * S)
    unvisited_flat = visits_flat == 0
    loop_rows = np.flatnonzero(unvisited_flat)
    all_rows = np.concatenate([rows, loop_rows])
    all_cols = np.concatenate([nexts, loop_rows % S])
    weight = 1.0 / np.maximum(visits_flat, 1)
    P = sp.csr_array(sp.coo_array((weight[all_rows], (all_rows, all_cols)), shape=(A * S, S)))
    P.sum_duplicates()
    R = (np.bincount(rows, weights=rewards, minlength=A * S) * weight).reshape(A, S).T
    initial = np.bincount(starts, minlength=S).astype(np.float64)
    initial /= initial.sum()
    terminal, reachable, conflicts = terminal_states(rows, nexts, terminated, initial, S, env_id)
    return GymModel(
        P=P,
        R=np.ascontiguousarray(R),
        terminal=terminal,
        initial=initial,
        reachable=reachable,
        done_conflicts=conflicts,
        visits=visits_flat.reshape(A, S).T.copy(),
        unvisited=unvisited_flat.reshape(A, S).T.copy(),
        n_samples=int(states.size),
        initial_source=f"{starts.size} sampled resets",
    )


class GymDomain(Domain):
    """A Gymnasium environment with discrete spaces, as an adpart domain.

    Args:
        env_id: a registered Gymnasium id (``Taxi-v4``, ``FrozenLake-v1``, ``module:Id-v0``).
        gamma: discount factor of the ``reward`` task.
        model: ``"exact"`` (read ``env.unwrapped.P``), ``"sampled"`` (estimate from random-policy
            transitions) or ``"auto"`` (exact when ``P`` exists, else sampled).
        samples: transitions to sample for an estimated model.
        seed: seeds the sampling (actions, environment resets).
        reset_samples: resets sampled to estimate the start distribution of an exact model whose
            environment has no ``initial_state_distrib``.
        **make_kwargs: passed to ``gymnasium.make`` (e.g. ``is_slippery=False``, ``map_name``).

    Attributes (for the CLI; reading any of them builds the model):
        estimated: True when the model was estimated from samples.
        n_samples: sampled transitions (0 for an exact model).
        visits: ``(S, A)`` sample counts per pair (None for an exact model).
        unvisited: ``(S, A)`` bool, pairs never sampled (placeholder self-loop, reward 0).
        done_conflicts: harmless termination conflicts (see the module docstring).
        reachable: ``(S,)`` bool, states an episode can occupy.
        initial_source: where the start distribution came from.

    Raises:
        UnknownNameError: Gymnasium does not know ``env_id``.
        ModelError: a space is not Discrete, ``model="exact"`` without ``P``, or the environment's
            termination is not a function of the next state.
    """

    default_task = "reward"

    def __init__(
        self,
        env_id: str,
        *,
        gamma: float = 0.99,
        model: str = "auto",
        samples: int = 50_000,
        seed: int = 0,
        reset_samples: int = 1000,
        **make_kwargs: Any,
    ) -> None:
        if model not in MODEL_KINDS:
            raise TaskError(f"model={model!r}; use one of {', '.join(MODEL_KINDS)}")
        if not 0.0 < gamma <= 1.0:
            raise TaskError(f"gamma = {gamma!r} is outside (0, 1]")
        if samples <= 0 or reset_samples <= 0:
            raise TaskError("samples and reset_samples must be positive")
        self.env_id = env_id
        self.make_kwargs = dict(make_kwargs)
        self.gamma = float(gamma)
        self.samples, self.seed, self.reset_samples = int(samples), int(seed), int(reset_samples)
        made = seeded_map(env_id, self.make_kwargs)
        self.env = make_env(env_id, **made)
        self._S, self._obs_start = discrete_size(self.env.observation_space, "observation", env_id)
        self._A, self._act_start = discrete_size(self.env.action_space, "action", env_id)
        base = self.env.unwrapped
        has_p = isinstance(getattr(base, "P", None), Mapping)
        if model == "exact" and not has_p:
            raise ModelError(
                f"gym:{env_id} has no env.unwrapped.P to read an exact model from; use "
                "model='sampled' (or 'auto') to estimate one from sampled transitions"
            )
        self.estimated = model == "sampled" or (model == "auto" and not has_p)
        if not self.estimated and getattr(base, "fickle_passenger", False):
            raise ModelError(
                f"gym:{env_id} with fickle_passenger=True changes the destination inside step(), "
                "but env.unwrapped.P omits that change, so a model read from P would be wrong. "
                "Use the built-in 'taxi-fickle' domain (Taxi(fickle=True)), whose model encodes "
                "it, "
                "or fickle_passenger=False"
            )
        if not self.estimated and not _same_model(base.P, make_env(env_id, **made).unwrapped.P):
            raise ModelError(
                f"gym:{env_id} with {self.make_kwargs or 'no arguments'} gives another model on "
                "every construction (it draws its layout at random when made: FrozenLake without "
                "desc or map_name draws an unseeded map), so the name names no single MDP: fix "
                "the layout (map_name=8x8, desc=[\"SFFF\",...] or desc=@map.txt, or "
                "random_map=8,map_seed=N for a seeded random map)")
        suffix = ",".join(f"{k}={_name_value(v)}" for k, v in sorted(self.make_kwargs.items()))
        self.name = f"gym:{env_id}" + (f"[{suffix}]" if suffix else "")
        spec = self.env.spec
        self.source = f"Gymnasium {gymnasium.__version__}: {spec.entry_point if spec else env_id}"
        how = (
            f"estimated from {self.samples} random-policy transitions"
            if self.estimated
            else "read from env.unwrapped.P"
        )
        self.description = f"Gymnasium environment {env_id}, model {how}"

    # ------------------------------------------------------------ the model
    @cached_property
    def model(self) -> GymModel:
        """The exact or estimated model (built on first use, then cached)."""
        if self.estimated:
            data = sample_transitions(
                self.env, self.samples, self.seed, self._S, self._A, self._obs_start
            )
            return model_from_samples(*data, self._S, self._A, self.env_id)
        return model_from_p(
            self.env.unwrapped.P,
            self._S,
            self._A,
            self._initial_distribution(),
            self.env_id,
            self._obs_start,
        )

    def _initial_distribution(self) -> np.ndarray:
        dist = getattr(self.env.unwrapped, "initial_state_distrib", None)
        if dist is not None:
            arr = np.asarray(dist, dtype=np.float64).reshape(-1)
            if arr.shape == (self._S,) and np.all(arr >= 0) and arr.sum() > 0:
                return arr / arr.sum()
        rng = np.random.default_rng(self.seed)
        seeds = rng.integers(2**31 - 1, size=self.reset_samples)
        starts = np.array([self.env.reset(seed=int(s))[0] for s in seeds], dtype=np.int64)
        counts = np.bincount(starts - self._obs_start, minlength=self._S).astype(np.float64)
        return counts / counts.sum()

    @property
    def n_samples(self) -> int:
        return self.model.n_samples

    @property
    def visits(self) -> np.ndarray | None:
        return self.model.visits

    @property
    def unvisited(self) -> np.ndarray:
        return self.model.unvisited

    @property
    def done_conflicts(self) -> np.ndarray:
        return self.model.done_conflicts

    @property
    def reachable(self) -> np.ndarray:
        return self.model.reachable

    @property
    def initial_source(self) -> str:
        if self.estimated:
            return self.model.initial_source
        has_dist = getattr(self.env.unwrapped, "initial_state_distrib", None) is not None
        return (
            "env.unwrapped.initial_state_distrib"
            if has_dist
            else f"{self.reset_samples} sampled resets"
        )

    def model_facts(self) -> dict[str, object]:
        """JSON-able facts about how the model was obtained (for ``adpart env show``)."""
        m = self.model
        facts: dict[str, object] = {
            "env_id": self.env_id,
            "make_kwargs": {k: repr(v) for k, v in self.make_kwargs.items()},
            "estimated": self.estimated,
            "n_states": self._S,
            "n_actions": self._A,
            "terminal_states": int(m.terminal.sum()),
            "reachable_states": int(m.reachable.sum()),
            "done_conflicts": m.done_conflicts.tolist(),
            "initial_source": self.initial_source,
        }
        if self.estimated and m.visits is not None:
            facts["n_samples"] = m.n_samples
            facts["unvisited_pairs"] = int(m.unvisited.sum())
            facts["unvisited_reachable_pairs"] = int(m.unvisited[m.reachable & ~m.terminal].sum())
            occupied = m.visits[m.reachable & ~m.terminal]
            facts["min_visits_reachable"] = int(occupied.min()) if occupied.size else 0
        return facts

    # ------------------------------------------------------------ Domain API
    def _build_dynamics(self) -> Dynamics:
        m = self.model
        return Dynamics(
            P=m.P,
            action_names=self._action_names(),
            action_costs=np.full(self._A, -1.0),
            features=self._features(),
            admissible=None,
            start=m.initial,
        )

    def tasks(self) -> Mapping[str, TaskFactory | GoalSpec]:
        return {"reward": self._reward_task}

    def _reward_task(self, domain: Domain) -> Task:
        m = self.model
        return Task(
            name="reward",
            reward=m.R,
            terminal=m.terminal,
            initial=m.initial,
            gamma=self.gamma,
            description=f"the environment's own rewards ({self.env_id})",
            spec={
                "kind": "gym-reward",
                "env_id": self.env_id,
                "gamma": self.gamma,
                "estimated": self.estimated,
                "samples": self.n_samples,
            },
        )

    def _action_names(self) -> tuple[str, ...]:
        known = ACTION_NAMES.get(type(self.env.unwrapped).__name__)
        if known is not None and len(known) == self._A:
            return known
        return tuple(f"a{a}" for a in range(self._A))

    def _features(self) -> dict[str, np.ndarray]:
        """``state``; ``decode`` fields and grid ``row``/``col`` (with ``x``, ``y``) where known.

        Decoding calls ``env.unwrapped.decode`` once per state (a one-off, not a hot path).
        """
        S = self._S
        base = self.env.unwrapped
        feats: dict[str, np.ndarray] = {"state": np.arange(S, dtype=np.int64)}
        decode = getattr(base, "decode", None)
        if callable(decode):
            try:
                table = np.array(
                    [tuple(decode(s + self._obs_start)) for s in range(S)], dtype=np.int64
                )
            except (TypeError, ValueError, AssertionError, IndexError):
                table = None
            if table is not None and table.ndim == 2:
                names = DECODE_NAMES.get(type(base).__name__)
                if names is None or len(names) != table.shape[1]:
                    names = tuple(f"decode{i}" for i in range(table.shape[1]))
                feats.update({n: table[:, i] for i, n in enumerate(names)})
        if "row" not in feats:
            ncol = getattr(base, "ncol", None)
            shape = getattr(base, "shape", None)
            if ncol is None and isinstance(shape, tuple) and len(shape) == 2:
                ncol = shape[1] if shape[0] * shape[1] == S else None
            if isinstance(ncol, (int, np.integer)) and ncol > 0 and S % int(ncol) == 0:
                feats["row"], feats["col"] = np.divmod(np.arange(S, dtype=np.int64), int(ncol))
        if "row" in feats and "col" in feats:
            feats["x"], feats["y"] = feats["col"], feats["row"]
        return feats

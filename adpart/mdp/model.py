"""Finite MDPs and stacked SMDP models: the data every algorithm in adpart works on.

Layout (DESIGN.md, "Core data model"): transitions are one CSR matrix of shape ``(A*S, S)`` whose
row ``a*S + s`` holds ``P(. | s, a)``; rows are grouped *by action* because a sparse matrix-vector
product over action-major rows gives the ``(A, S)`` block of Q values contiguously, which measured
about 2x faster than state-major rows in value iteration (see ``benchmarks/``).

A :class:`FiniteMDP` is validated once, in its constructor; kernels downstream trust it.
:class:`SMDPModel` is the form the exact solvers take: rewards ``R(s, o)`` and *discounted*
transition matrices ``F(s' | s, o)`` (eqs. 3.1-3.2 of the dissertation), so that a primitive MDP
(``F = gamma * P``) and a set of options with multi-time models are solved by the same code.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Protocol

import numpy as np
import scipy.sparse as sp

from adpart.errors import ModelError

#: Rows of admissible (state, action) pairs must sum to one within this absolute tolerance.
ROW_SUM_ATOL = 1e-8


def _as_action_major_csr(transitions: object, n_states: int | None) -> sp.csr_array:
    """Convert the accepted transition inputs into one float64 CSR of shape ``(A*S, S)``."""
    if isinstance(transitions, (list, tuple)):
        if not transitions:
            raise ModelError("transitions is an empty sequence; give one (S, S) matrix per action")
        blocks = [sp.csr_array(t, dtype=np.float64) for t in transitions]
        shapes = {b.shape for b in blocks}
        if len(shapes) != 1:
            raise ModelError(
                f"per-action transition matrices have different shapes {sorted(shapes)}; "
                "each must be (n_states, n_states)"
            )
        matrix = sp.vstack(blocks, format="csr")
    elif sp.issparse(transitions):
        matrix = sp.csr_array(transitions, dtype=np.float64)
    else:
        raise ModelError(
            "transitions must be a scipy.sparse matrix of shape (A*S, S) or a sequence of "
            f"(S, S) matrices, one per action; got {type(transitions).__name__}. "
            "For a dense array P[s, a, s'] use FiniteMDP.from_dense."
        )
    rows, cols = matrix.shape
    s = cols if n_states is None else n_states
    if s <= 0 or cols != s or rows % s != 0:
        raise ModelError(
            f"transition matrix has shape {matrix.shape}; it must be (n_actions * n_states, "
            "n_states) with row a*S + s holding P(. | s, a)"
        )
    matrix.sum_duplicates()
    matrix.sort_indices()
    return matrix


@dataclass(frozen=True, eq=False)
class SMDPModel:
    """Stacked (multi-time) models of a set of actions or options, as the solvers consume them.

    Attributes:
        R: ``(S, O)`` float64, expected discounted reward accumulated while option ``o`` runs
            from ``s`` (eq. 3.1); for a primitive action, the expected one-step reward.
        F: ``(O*S, S)`` CSR float64, row ``o*S + s`` = ``sum_k gamma^k P(s', k | s, o)`` (eq. 3.2);
            for a primitive action, ``gamma * P(s' | s, a)``. Rows of terminal states are zero.
        admissible: ``(S, O)`` bool, whether ``o`` may be chosen in ``s`` (its initiation set).
    """

    R: np.ndarray
    F: sp.csr_array
    admissible: np.ndarray

    @property
    def n_states(self) -> int:
        return self.R.shape[0]

    @property
    def n_actions(self) -> int:
        return self.R.shape[1]

    def as_smdp(self) -> SMDPModel:
        return self

    @cached_property
    def row_discounts(self) -> np.ndarray:
        """``(O, S)`` total discounted mass ``sum_s' F(s'|s,o)`` of every row."""
        return np.asarray(self.F.sum(axis=1)).reshape(self.n_actions, self.n_states)

    @cached_property
    def modulus(self) -> float:
        """Contraction modulus of the Bellman operator: the largest admissible row discount."""
        masses = self.row_discounts.T[self.admissible]
        return float(masses.max()) if masses.size else 0.0

    @cached_property
    def uniform_discount(self) -> bool:
        """True when every admissible row has the same discounted mass (no terminal states).

        The span-seminorm stopping rule of value iteration (Puterman, Prop. 6.6.5) is valid
        only then; otherwise the solvers fall back to the sup-norm rule.
        """
        masses = self.row_discounts.T[self.admissible]
        return bool(masses.size) and float(np.ptp(masses)) <= 1e-12


@dataclass(frozen=True, eq=False)
class FiniteMDP:
    """A finite Markov decision process with sparse transitions.

    Construct it with the validating constructor (this class's ``__init__``), or with
    :meth:`from_dense` for small models written as ``P[s, a, s']``. Every violated invariant raises
    :class:`adpart.errors.ModelError` naming the state, the action and the value at fault.

    Attributes:
        P: ``(A*S, S)`` CSR float64, row ``a*S + s`` = ``P(. | s, a)``.
        R: ``(S, A)`` float64 expected immediate reward of taking ``a`` in ``s``.
        gamma: discount factor in (0, 1].
        terminal: ``(S,)`` bool; an episode ends on *arrival* in a terminal state, whose value
            is 0 by definition (its rows are ignored by the solvers).
        admissible: ``(S, A)`` bool; at least one action per state.
        initial: ``(S,)`` float64 start-state distribution of an episode.
        features: named ``(S,)`` arrays describing each state (``x``, ``y``, ``floor`` ...).
        action_names: one name per action, used in messages, plots and the CLI.
        name: a human-readable label (not part of :attr:`content_hash`).
    """

    P: sp.csr_array
    R: np.ndarray
    gamma: float
    terminal: np.ndarray
    admissible: np.ndarray
    initial: np.ndarray
    features: Mapping[str, np.ndarray] = field(default_factory=dict)
    action_names: tuple[str, ...] = ()
    name: str = "mdp"

    def __init__(
        self,
        transitions: object,
        rewards: object,
        gamma: float,
        *,
        terminal: object = None,
        admissible: object = None,
        initial: object = None,
        features: Mapping[str, object] | None = None,
        action_names: Sequence[str] | None = None,
        name: str = "mdp",
    ) -> None:
        P = _as_action_major_csr(transitions, None)
        n_states = P.shape[1]
        n_actions = P.shape[0] // n_states
        names = (
            tuple(action_names)
            if action_names is not None
            else tuple(f"a{a}" for a in range(n_actions))
        )
        if len(names) != n_actions:
            raise ModelError(
                f"action_names has {len(names)} entries but the model has {n_actions} actions"
            )
        R = np.asarray(rewards, dtype=np.float64)
        if R.shape != (n_states, n_actions):
            raise ModelError(
                f"rewards have shape {R.shape} but the transitions describe {n_states} states "
                f"and {n_actions} actions; rewards must be (n_states, n_actions) = "
                f"({n_states}, {n_actions})"
            )
        if not (isinstance(gamma, (int, float, np.floating)) and 0.0 < float(gamma) <= 1.0):
            raise ModelError(f"gamma = {gamma!r} is outside (0, 1]")
        term = self._mask(terminal, (n_states,), "terminal", default=False)
        adm = self._mask(admissible, (n_states, n_actions), "admissible", default=True)
        init = (
            np.full(n_states, 1.0 / n_states)
            if initial is None
            else np.asarray(initial, dtype=np.float64)
        )
        feats = {k: np.asarray(v) for k, v in (features or {}).items()}
        object.__setattr__(self, "P", P)
        object.__setattr__(self, "R", R)
        object.__setattr__(self, "gamma", float(gamma))
        object.__setattr__(self, "terminal", term)
        object.__setattr__(self, "admissible", adm)
        object.__setattr__(self, "initial", init)
        object.__setattr__(self, "features", feats)
        object.__setattr__(self, "action_names", names)
        object.__setattr__(self, "name", name)
        self._validate()
        for arr in (R, term, adm, init, *feats.values()):
            arr.setflags(write=False)

    @classmethod
    def from_dense(cls, P: object, R: object, gamma: float, **kwargs: object) -> FiniteMDP:
        """Build from a dense ``P[s, a, s']`` array (small models and tests)."""
        dense = np.asarray(P, dtype=np.float64)
        if dense.ndim != 3 or dense.shape[0] != dense.shape[2]:
            raise ModelError(
                f"dense transitions have shape {dense.shape}; expected (S, A, S) with P[s, a, s']"
            )
        per_action = [sp.csr_array(dense[:, a, :]) for a in range(dense.shape[1])]
        return cls(per_action, R, gamma, **kwargs)  # type: ignore[arg-type]

    @staticmethod
    def _mask(value: object, shape: tuple[int, ...], what: str, *, default: bool) -> np.ndarray:
        if value is None:
            return np.full(shape, default, dtype=bool)
        arr = np.asarray(value)
        if arr.shape != shape:
            raise ModelError(f"{what} mask has shape {arr.shape}; expected {shape}")
        if arr.dtype != bool:
            raise ModelError(f"{what} mask must be boolean, got dtype {arr.dtype}")
        return arr.copy()

    def _action(self, a: int) -> str:
        return f"{self.action_names[a]!r} ({a})"

    def _validate(self) -> None:
        S, A = self.n_states, self.n_actions
        P = self.P
        row_of_entry = np.repeat(np.arange(P.shape[0]), np.diff(P.indptr))
        bad = np.flatnonzero(~np.isfinite(P.data))
        if bad.size:
            r, k = row_of_entry[bad[0]], bad[0]
            raise ModelError(
                f"P(s'={P.indices[k]} | s={r % S}, a={self._action(r // S)}) = {P.data[k]} is not "
                "a finite number"
            )
        bad = np.flatnonzero(P.data < 0)
        if bad.size:
            r, k = row_of_entry[bad[0]], bad[0]
            raise ModelError(
                f"P(s'={P.indices[k]} | s={r % S}, a={self._action(r // S)}) = {P.data[k]} is "
                "negative; probabilities must be >= 0"
            )
        bad_r = np.argwhere(~np.isfinite(self.R))
        if bad_r.size:
            s, a = bad_r[0]
            raise ModelError(
                f"reward R[s={s}, a={self._action(a)}] = {self.R[s, a]} is not a finite number"
            )
        no_action = np.flatnonzero(~self.admissible.any(axis=1))
        if no_action.size:
            raise ModelError(
                f"state {no_action[0]} has no admissible action; every state needs at least one "
                "(give terminal states a self-loop)"
            )
        sums = np.asarray(P.sum(axis=1)).reshape(A, S).T
        off = np.argwhere(self.admissible & (np.abs(sums - 1.0) > ROW_SUM_ATOL))
        if off.size:
            s, a = off[0]
            raise ModelError(
                f"transition row for state {s}, action {self._action(a)} sums to "
                f"{float(sums[s, a])!r}; "
                f"rows of admissible pairs must sum to 1 within {ROW_SUM_ATOL}"
            )
        init = self.initial
        if init.shape != (S,) or not np.all(np.isfinite(init)) or np.any(init < 0):
            raise ModelError(
                f"initial distribution must be {S} finite non-negative numbers; got shape "
                f"{init.shape}"
            )
        if abs(init.sum() - 1.0) > ROW_SUM_ATOL:
            raise ModelError(
                f"initial distribution sums to {float(init.sum())!r}; it must sum to 1"
            )
        for key, col in self.features.items():
            if col.shape != (S,):
                raise ModelError(f"feature {key!r} has shape {col.shape}; expected ({S},)")

    @property
    def n_states(self) -> int:
        return self.P.shape[1]

    @property
    def n_actions(self) -> int:
        return self.P.shape[0] // self.P.shape[1]

    def transition_row(self, s: int, a: int) -> tuple[np.ndarray, np.ndarray]:
        """Successor states and their probabilities for one ``(s, a)``."""
        r = a * self.n_states + s
        lo, hi = self.P.indptr[r], self.P.indptr[r + 1]
        return self.P.indices[lo:hi], self.P.data[lo:hi]

    def as_smdp(self) -> SMDPModel:
        """The one-step model as stacked SMDP models: ``R`` and ``F = gamma * P``.

        Terminal states get zero rows in both, so their value is 0 (episode over on arrival).
        """
        return self._smdp

    @cached_property
    def _smdp(self) -> SMDPModel:
        keep = np.tile(~self.terminal, self.n_actions).astype(np.float64)
        F = sp.csr_array(sp.diags_array(keep * self.gamma) @ self.P)
        F.eliminate_zeros()
        R = np.where(self.terminal[:, None], 0.0, self.R)
        return SMDPModel(R=R, F=F, admissible=self.admissible)

    @cached_property
    def content_hash(self) -> str:
        """SHA-256 of the model's content: dynamics, rewards, gamma, masks, start distribution.

        Two models with the same hash are the same MDP (labels, names and features excluded), so
        the knowledge base can key environments and tasks on it.
        """
        P = self.P.copy()
        P.eliminate_zeros()
        h = hashlib.sha256()
        header = {"S": self.n_states, "A": self.n_actions, "gamma": self.gamma, "v": 1}
        h.update(json.dumps(header, sort_keys=True).encode())
        for arr in (
            P.indptr.astype(np.int64),
            P.indices.astype(np.int64),
            P.data.astype(np.float64),
            self.R,
            self.terminal,
            self.admissible,
            self.initial,
        ):
            h.update(np.ascontiguousarray(arr).tobytes())
        return h.hexdigest()

    @cached_property
    def sampler_keys(self) -> np.ndarray:
        """Row-offset cumulative probabilities: entry k of row r holds ``r + cumsum_in_row``.

        ``searchsorted(sampler_keys, row + u, side="right")`` (clipped to the row's last entry)
        is the CSR position of a successor drawn with ``u ~ U[0, 1)``; compiled learners use the
        same keys so that their sampling matches :meth:`sample_next` exactly.
        """
        P = self.P
        counts = np.diff(P.indptr)
        rows = np.repeat(np.arange(P.shape[0], dtype=np.float64), counts)
        csum = np.cumsum(P.data)
        row_start_sum = np.concatenate(([0.0], csum))[P.indptr[:-1]]
        within = csum - np.repeat(row_start_sum, counts)
        keys = rows + within
        keys.setflags(write=False)
        return keys

    @cached_property
    def sampler_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(sampler_keys, indptr, indices)`` with int64 indices: what compiled samplers read.

        Compiled kernels (Q-learning, the subgoal walkers) search row ``a*S + s`` of ``keys``
        between ``indptr[row]`` and ``indptr[row + 1]`` for the first key above ``row + u``.
        """
        indptr = self.P.indptr.astype(np.int64)
        indices = self.P.indices.astype(np.int64)
        for arr in (indptr, indices):
            arr.setflags(write=False)
        return self.sampler_keys, indptr, indices

    def sample_next(
        self, states: np.ndarray, actions: np.ndarray, rng: np.random.Generator
    ) -> np.ndarray:
        """Sample successors for many ``(state, action)`` pairs at once (one ``searchsorted``).

        Args:
            states: int array of states, any shape.
            actions: int array of actions, broadcastable to ``states``.
            rng: the only source of randomness.

        Returns:
            int64 array of successor states with the shape of ``states``.
        """
        keys = self.sampler_keys
        rows = np.asarray(actions, dtype=np.int64) * self.n_states + np.asarray(states)
        u = rng.random(rows.shape)
        k = np.searchsorted(keys, rows + u, side="right")
        k = np.minimum(k, self.P.indptr[rows + 1] - 1)
        return self.P.indices[k].astype(np.int64)

    def with_rewards(
        self,
        rewards: object,
        *,
        terminal: object = None,
        initial: object = None,
        name: str | None = None,
    ) -> FiniteMDP:
        """The same dynamics with another task's rewards (and optionally terminal states)."""
        return FiniteMDP(
            self.P,
            rewards,
            self.gamma,
            terminal=self.terminal if terminal is None else terminal,
            admissible=self.admissible,
            initial=self.initial if initial is None else initial,
            features=self.features,
            action_names=self.action_names,
            name=self.name if name is None else name,
        )


class HasSMDP(Protocol):
    """Anything the solvers and evaluation accept: it can present itself as an SMDP model."""

    def as_smdp(self) -> SMDPModel: ...

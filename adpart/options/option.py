"""The option (I, pi, beta) of Sutton, Precup & Singh (1999), dissertation section 3.1.

An option is available in the states of its initiation set ``I``; once started it picks actions
with its policy ``pi`` and, after every step, terminates in the state it arrived in with
probability ``beta`` of that state. The semantics adpart commits to (docs/options.md):

* **An option always takes at least one step.** Started in ``s`` in ``I`` it acts even if
  ``beta(s) = 1``; ``beta`` is consulted only on *arrival*. So the one-step option of a primitive
  action ``a`` is ``I = {s : a admissible in s}``, ``pi = a``, ``beta = 1`` everywhere.
* **Outside ``I`` the option is not admissible**: the stacked SMDP marks it inadmissible there,
  its model rows are zero, and the rollout estimator refuses to start it there.
* **Arrival in a terminal state of the MDP ends the option** (the episode is over), whatever
  ``beta`` says; the arrival counts in ``F`` like any termination, with the terminal value 0.
* The option may continue in a state ``s'`` with ``beta(s') < 1`` even outside ``I``
  (Sutton et al. only *usually* assume ``{beta < 1}`` is inside ``I``); its policy must then be
  defined there. All options built by adpart have ``beta = 1`` outside ``I``.

The policy is either ``(S,)`` int64 (``-1`` where undefined: it must be defined on ``I`` and
wherever ``beta < 1``) or ``(S, A)`` float64 action probabilities (rows of zeros where undefined).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from adpart.errors import ModelError

if TYPE_CHECKING:
    from adpart.mdp.model import FiniteMDP

#: Rows of a stochastic policy must sum to one within this absolute tolerance.
POLICY_ROW_ATOL = 1e-8


def _readonly(arr: np.ndarray) -> np.ndarray:
    arr = np.array(arr, copy=True)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class Option:
    """A Markov option ``(I, pi, beta)`` over the states of one MDP.

    Attributes:
        name: label used in every message about this option (e.g. ``"to-62"``).
        initiation: ``(S,)`` bool, the initiation set ``I``.
        policy: ``(S,)`` int64 actions (``-1`` = undefined) or ``(S, A)`` float64 probabilities.
        beta: ``(S,)`` float64 termination probabilities in ``[0, 1]``, applied on arrival.
        subgoal: the target state of an option to a subgoal, else ``-1``.
        meta: free-form description (how it was built), kept for provenance.
    """

    name: str
    initiation: np.ndarray
    policy: np.ndarray
    beta: np.ndarray
    subgoal: int = -1
    meta: dict[str, object] = field(default_factory=dict)

    def __post_init__(self) -> None:
        init = np.asarray(self.initiation)
        if init.ndim != 1:
            raise ModelError(
                f"option {self.name!r}: initiation mask has shape {init.shape}; it must be one "
                "bool per state, shape (S,)"
            )
        if init.dtype != bool:
            raise ModelError(
                f"option {self.name!r}: initiation mask must be boolean, got dtype {init.dtype}; "
                "pass e.g. np.asarray(mask, dtype=bool)"
            )
        S = init.shape[0]
        beta = np.asarray(self.beta, dtype=np.float64)
        if beta.shape != (S,):
            raise ModelError(
                f"option {self.name!r}: beta has shape {beta.shape}; expected ({S},), one "
                "termination probability per state"
            )
        bad = np.flatnonzero(~np.isfinite(beta) | (beta < 0.0) | (beta > 1.0))
        if bad.size:
            raise ModelError(
                f"option {self.name!r}: beta[{bad[0]}] = {float(beta[bad[0]])!r} is not a "
                "probability; termination probabilities must lie in [0, 1]"
            )
        policy = self._checked_policy(np.asarray(self.policy), S)
        if not init.any():
            raise ModelError(
                f"option {self.name!r} has an empty initiation set; it could never be started"
            )
        if not (-1 <= int(self.subgoal) < S):
            raise ModelError(
                f"option {self.name!r}: subgoal {self.subgoal} is not a state 0..{S - 1}"
            )
        need = init | (beta < 1.0)
        undefined = ~self._defined(policy)
        missing = np.flatnonzero(need & undefined)
        if missing.size:
            raise ModelError(
                f"option {self.name!r}: policy is undefined in state {missing[0]}, where the "
                "option can act (it is in the initiation set or has beta < 1); define an "
                "action there"
            )
        object.__setattr__(self, "initiation", _readonly(init))
        object.__setattr__(self, "beta", _readonly(beta))
        object.__setattr__(self, "policy", _readonly(policy))
        object.__setattr__(self, "subgoal", int(self.subgoal))

    def _checked_policy(self, policy: np.ndarray, S: int) -> np.ndarray:
        if policy.ndim == 1:
            if policy.shape != (S,) or not np.issubdtype(policy.dtype, np.integer):
                raise ModelError(
                    f"option {self.name!r}: a deterministic policy must be {S} integers (-1 where "
                    f"undefined); got shape {policy.shape}, dtype {policy.dtype}"
                )
            if policy.min() < -1:
                s = int(np.argmin(policy))
                raise ModelError(
                    f"option {self.name!r}: policy[{s}] = {policy[s]} is not an action (use -1 "
                    "for 'undefined')"
                )
            return policy.astype(np.int64)
        if policy.ndim != 2 or policy.shape[0] != S:
            raise ModelError(
                f"option {self.name!r}: policy has shape {policy.shape}; expected ({S},) actions "
                f"or ({S}, A) action probabilities"
            )
        probs = policy.astype(np.float64)
        bad = np.argwhere(~np.isfinite(probs) | (probs < 0.0))
        if bad.size:
            s, a = bad[0]
            raise ModelError(
                f"option {self.name!r}: policy probability pi({s}, {a}) = "
                f"{float(probs[s, a])!r} is not a non-negative number"
            )
        sums = probs.sum(axis=1)
        off = np.flatnonzero((sums != 0.0) & (np.abs(sums - 1.0) > POLICY_ROW_ATOL))
        if off.size:
            raise ModelError(
                f"option {self.name!r}: policy row of state {off[0]} sums to "
                f"{float(sums[off[0]])!r}; each row must be a distribution (or all zeros "
                "where undefined)"
            )
        return probs

    @staticmethod
    def _defined(policy: np.ndarray) -> np.ndarray:
        return policy >= 0 if policy.ndim == 1 else policy.sum(axis=1) > 0

    @property
    def n_states(self) -> int:
        return self.initiation.shape[0]

    @property
    def deterministic(self) -> bool:
        return self.policy.ndim == 1

    def acting_states(self, terminal: np.ndarray) -> np.ndarray:
        """``(S,)`` bool: states where the option may act, ``(I | beta < 1) & ~terminal``."""
        return (self.initiation | (self.beta < 1.0)) & ~terminal

    def check(self, mdp: FiniteMDP) -> None:
        """Check the option against ``mdp``: sizes, action range and admissible actions.

        Raises:
            ModelError: naming the option, the state and the action at fault.
        """
        S, A = mdp.n_states, mdp.n_actions
        if self.n_states != S:
            raise ModelError(
                f"option {self.name!r} is defined over {self.n_states} states but the MDP "
                f"{mdp.name!r} has {S}; build the option for this MDP"
            )
        acting = self.acting_states(mdp.terminal)
        if self.deterministic:
            pol = self.policy
            high = np.flatnonzero(acting & (pol >= A))
            if high.size:
                s = int(high[0])
                raise ModelError(
                    f"option {self.name!r}: policy chooses action {pol[s]} in state {s}, but the "
                    f"MDP has actions 0..{A - 1}"
                )
            states = np.flatnonzero(acting)
            ok = mdp.admissible[states, pol[states]]
            if not ok.all():
                s = int(states[np.argmin(ok)])
                raise ModelError(
                    f"option {self.name!r}: policy chooses inadmissible action "
                    f"{mdp.action_names[pol[s]]!r} ({pol[s]}) in state {s}; choose an action "
                    "admissible there"
                )
            return
        if self.policy.shape[1] != A:
            raise ModelError(
                f"option {self.name!r}: stochastic policy has {self.policy.shape[1]} action "
                f"columns but the MDP has {A} actions"
            )
        bad = np.argwhere(acting[:, None] & (self.policy > 0) & ~mdp.admissible)
        if bad.size:
            s, a = bad[0]
            raise ModelError(
                f"option {self.name!r}: policy puts probability {self.policy[s, a]:.3g} on "
                f"inadmissible action {mdp.action_names[a]!r} ({a}) in state {s}"
            )


def primitive_option(mdp: FiniteMDP, action: int) -> Option:
    """The one-step option of ``action``: ``I`` = where it is admissible, ``beta = 1``."""
    if not 0 <= action < mdp.n_actions:
        raise ModelError(f"action {action} is not one of the MDP's actions 0..{mdp.n_actions - 1}")
    S = mdp.n_states
    init = mdp.admissible[:, action].copy()
    return Option(
        name=mdp.action_names[action],
        initiation=init,
        policy=np.where(init, action, -1).astype(np.int64),
        beta=np.ones(S),
        meta={"kind": "primitive", "action": int(action)},
    )


def primitive_options(mdp: FiniteMDP) -> list[Option]:
    """One one-step option per primitive action, in action order (section 3.1)."""
    return [primitive_option(mdp, a) for a in range(mdp.n_actions)]

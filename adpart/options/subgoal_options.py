"""Options to subgoals, learned off-line from the model (DESIGN.md "Options to subgoals", 4.2.1).

For a subgoal ``g`` the option is built in three parts:

* **Initiation set** ``I`` (``initiation=``):

  - ``"basin"`` (default): the states, other than ``g`` and not terminal, from which ``g`` can be
    reached (with positive probability, under some policy) by a path whose intermediate states
    are neither other subgoals nor terminal. Other subgoals belong to ``I`` as *start* states
    only (a path may start in one), so that an agent that has reached one subgoal can take the
    option to the next: the subgoal options alone then connect the subgoals.
  - ``"reachable"``: every non-terminal state other than ``g`` that can reach ``g`` at all.
  - a ``(S,)`` bool mask given by the caller.

  ``g`` itself is never in ``I`` (an option to where the agent already is would be pointless).
* **Termination** ``beta``: 1 at ``g``, outside ``I`` and, for ``"basin"``, at the other subgoals
  (the basin's paths never cross them); 0 elsewhere.
* **Policy**: greedy for the *pseudo-reward task* "reach ``g``": reward +1 on arrival at ``g``,
  0 otherwise, every state where the option terminates is absorbing with value 0, discounted by
  ``pseudo_gamma`` (the MDP's gamma if it is below 1, else 0.99). Its value is
  ``E[pseudo_gamma^tau ; the option ends at g]``, so the policy reaches ``g`` as fast and as
  surely as possible without leaving the region where the option runs. It is task-independent:
  the MDP's own rewards play no part. Solved by modified policy iteration
  (:func:`adpart.mdp.solvers.solve`) to ``epsilon``; ties go to the lowest action index.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from adpart.errors import ModelError
from adpart.mdp.model import FiniteMDP
from adpart.mdp.solvers import solve
from adpart.options.option import Option

if TYPE_CHECKING:
    from collections.abc import Sequence

#: Default discount of the pseudo-reward task when the MDP itself is undiscounted.
UNDISCOUNTED_PSEUDO_GAMMA = 0.99
#: Solver accuracy of the pseudo-reward task (its values lie in [0, 1]).
PSEUDO_EPSILON = 1e-10
INITIATION_CHOICES = ("basin", "reachable")


def transition_graph(mdp: FiniteMDP) -> sp.csr_array:
    """``(S, S)`` CSR with a 1 where some admissible action moves ``s`` to ``s'`` w.p. > 0."""
    S, A = mdp.n_states, mdp.n_actions
    keep = sp.diags_array(mdp.admissible.T.reshape(-1).astype(np.float64))
    gather = sp.hstack([sp.eye_array(S, format="csr")] * A, format="csr")
    G = sp.csr_array(gather @ (keep @ mdp.P))
    G.eliminate_zeros()
    G.data[:] = 1.0
    return G


def _reverse_reach(G: sp.csr_array, target: int, passable: np.ndarray) -> np.ndarray:
    """States that reach ``target`` through ``passable`` intermediate states (``target`` excluded).

    Edges leaving non-passable states are dropped, then a breadth-first search runs from
    ``target`` on the reversed graph; a non-passable state is found (as a start) if it has an
    edge into the found region, but is not expanded.
    """
    S = G.shape[0]
    inner = passable.copy()
    inner[target] = True
    keep = sp.diags_array(inner.astype(np.float64))
    G_in = sp.csr_array(keep @ G @ keep)
    G_in.eliminate_zeros()
    order = csgraph.breadth_first_order(G_in.T.tocsr(), target, directed=True,
                                        return_predecessors=False)
    region = np.zeros(S, dtype=bool)
    region[order] = True
    entering = np.asarray((G @ region.astype(np.float64)) > 0).ravel()
    found = region | entering
    found[target] = False
    return found


def _subgoal_mask(subgoals: object, S: int) -> np.ndarray:
    arr = np.asarray(subgoals)
    if arr.size == 0:
        return np.zeros(S, dtype=bool)
    if arr.dtype == bool:
        if arr.shape != (S,):
            raise ModelError(f"subgoal mask has shape {arr.shape}; expected ({S},)")
        return arr.copy()
    if arr.ndim != 1 or not np.issubdtype(arr.dtype, np.integer):
        raise ModelError("subgoals must be a list of state ids or an (S,) bool mask")
    if arr.size and (arr.min() < 0 or arr.max() >= S):
        raise ModelError(f"subgoal state {int(arr.max())} is not a state 0..{S - 1}")
    mask = np.zeros(S, dtype=bool)
    mask[arr] = True
    return mask


def basin(mdp: FiniteMDP, subgoal: int, subgoals: object = ()) -> np.ndarray:
    """``(S,)`` bool basin of ``subgoal`` among ``subgoals`` (ids or mask), see module docstring."""
    S = mdp.n_states
    others = _subgoal_mask(subgoals, S)
    others[subgoal] = False
    passable = ~others & ~mdp.terminal
    found = _reverse_reach(transition_graph(mdp), subgoal, passable)
    return found & ~mdp.terminal


def reachable_set(mdp: FiniteMDP, subgoal: int) -> np.ndarray:
    """``(S,)`` bool: non-terminal states other than ``subgoal`` that can reach it at all."""
    found = _reverse_reach(transition_graph(mdp), subgoal, ~mdp.terminal)
    return found & ~mdp.terminal


def policy_to(
    mdp: FiniteMDP,
    subgoal: int,
    stop: np.ndarray,
    *,
    pseudo_gamma: float | None = None,
    epsilon: float = PSEUDO_EPSILON,
) -> tuple[np.ndarray, np.ndarray]:
    """Greedy policy of the pseudo-reward task "reach ``subgoal``" (module docstring).

    Args:
        stop: ``(S,)`` bool, states where the option ends (value 0); ``subgoal`` must be one.

    Returns:
        ``(policy (S,) int64, V (S,))``: V is ``E[pseudo_gamma^tau ; end at subgoal]`` of the
        policy when continuing, i.e. 0 on ``stop``; the policy is greedy in every state,
        ``stop`` states included (an option started there takes one step first).
    """
    S, A = mdp.n_states, mdp.n_actions
    g = float(pseudo_gamma if pseudo_gamma is not None else (
        mdp.gamma if mdp.gamma < 1.0 else UNDISCOUNTED_PSEUDO_GAMMA))
    if not 0.0 < g < 1.0:
        raise ModelError(f"pseudo_gamma = {g!r} must lie in (0, 1)")
    arrive = np.asarray(mdp.P[:, [subgoal]].toarray()).reshape(A, S).T
    terminal = stop | mdp.terminal
    pseudo = FiniteMDP(mdp.P, arrive, g, terminal=terminal, admissible=mdp.admissible,
                       name=f"{mdp.name}/reach-{subgoal}")
    V = solve(pseudo, epsilon, method="mpi").V
    V = np.where(terminal, 0.0, V)
    Q = arrive + g * (mdp.P @ V).reshape(A, S).T
    Q = np.where(mdp.admissible, Q, -np.inf)
    return np.argmax(Q, axis=1).astype(np.int64), V


def subgoal_option(
    mdp: FiniteMDP,
    subgoal: int,
    *,
    subgoals: object = (),
    initiation: str | np.ndarray = "basin",
    pseudo_gamma: float | None = None,
    name: str | None = None,
) -> Option:
    """The option to ``subgoal`` (module docstring for ``I``, ``beta`` and the policy).

    Args:
        subgoals: all subgoals (ids or mask); with ``"basin"`` the others bound the basin.
        initiation: ``"basin"``, ``"reachable"`` or an ``(S,)`` bool mask.

    Raises:
        ModelError: unknown ``initiation``, an empty initiation set, or (with a given mask) an
            initiation state from which the subgoal cannot be reached inside the mask.
    """
    S = mdp.n_states
    if not isinstance(subgoal, (int, np.integer)) or not 0 <= subgoal < S:
        raise ModelError(f"subgoal {subgoal!r} is not a state 0..{S - 1}")
    subgoal = int(subgoal)
    label = name or f"to-{subgoal}"
    others = _subgoal_mask(subgoals, S)
    others[subgoal] = False
    if isinstance(initiation, str):
        if initiation == "basin":
            init = basin(mdp, subgoal, others)
            stop = ~init | others
        elif initiation == "reachable":
            init = reachable_set(mdp, subgoal)
            stop = ~init
        else:
            raise ModelError(
                f"initiation = {initiation!r}; use one of {INITIATION_CHOICES} or an (S,) bool mask"
            )
    else:
        init = np.asarray(initiation)
        if init.shape != (S,) or init.dtype != bool:
            raise ModelError(
                f"option {label!r}: initiation mask has shape {init.shape} and dtype {init.dtype}; "
                f"expected an ({S},) bool mask"
            )
        init = init & ~mdp.terminal
        init[subgoal] = False
        stop = ~init
    stop = stop.copy()
    stop[subgoal] = True
    if not init.any():
        raise ModelError(
            f"option {label!r}: the initiation set of subgoal {subgoal} is empty (no state can "
            f"reach it); choose another subgoal or initiation"
        )
    policy, V = policy_to(mdp, subgoal, stop, pseudo_gamma=pseudo_gamma)
    if not isinstance(initiation, str):
        dead = np.flatnonzero(init & ~stop & (V <= 0.0))
        if dead.size:
            raise ModelError(
                f"option {label!r}: subgoal {subgoal} cannot be reached from initiation state "
                f"{int(dead[0])} without leaving the initiation mask; widen the mask or drop "
                "that state"
            )
    beta = stop.astype(np.float64)
    kind = initiation if isinstance(initiation, str) else "mask"
    return Option(label, init, policy, beta, subgoal=subgoal,
                  meta={"kind": "subgoal", "initiation": kind})


def subgoal_options(
    mdp: FiniteMDP,
    subgoals: Sequence[int] | np.ndarray,
    *,
    initiation: str = "basin",
    pseudo_gamma: float | None = None,
) -> list[Option]:
    """One option per subgoal (in increasing state order), each bounded by the others' basins."""
    mask = _subgoal_mask(subgoals, mdp.n_states)
    return [
        subgoal_option(mdp, int(g), subgoals=mask, initiation=initiation,
                       pseudo_gamma=pseudo_gamma)
        for g in np.flatnonzero(mask)
    ]

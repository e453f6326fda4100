"""Options to subgoals, learned off-line from the model (DESIGN.md "Options to subgoals", 4.2.1).

For a subgoal ``g`` the option is built in three parts:

* **Initiation set** ``I`` (``initiation=``):

  - ``"local"`` (default): the states of the basin (below) from which the option's own policy
    reaches ``g`` within about ``radius`` steps, read off the pseudo-reward value:
    ``I = {s in basin : V_g(s) >= pseudo_gamma**(radius - 1)}``, where ``V_g(s) =
    E[pseudo_gamma^(tau - 1) ; the option ends at g]`` is the value the policy is solved for
    (below; the +1 is paid on arrival, at step ``tau``). In a deterministic
    domain this is exactly "shortest path to ``g`` inside the basin has at most ``radius`` steps"
    (tested against a breadth-first search); in a stochastic one it is the certainty-equivalent
    horizon, so a state whose route is long *or* unreliable is left out. This is the seed's
    "options terminate when they reach the subgoal in the same room" (chapter 6) without a
    map: an option is offered only where its subgoal is near. ``radius`` defaults to
    :class:`InitiationSettings`' radius, chosen by measurement (docs/options.md: three-floor,
    Parr's maze, urban). The whole basin was measured to make SMDP Q-learning 11.9x slower than
    flat on three-floor: there an untried option (Q = 0 is optimistic against -1 a step) carries the
    agent 25-67 steps back towards the old task's subgoal.
  - ``"basin"``: the states, other than ``g`` and not terminal, from which ``g`` can be
    reached (with positive probability, under some policy) by a path whose intermediate states
    are neither other subgoals nor terminal. Other subgoals belong to ``I`` as *start* states
    only (a path may start in one), so that an agent that has reached one subgoal can take the
    option to the next: the subgoal options alone then connect the subgoals.
  - ``"reachable"``: every non-terminal state other than ``g`` that can reach ``g`` at all.
  - a ``(S,)`` bool mask given by the caller.

  ``g`` itself is never in ``I`` (an option to where the agent already is would be pointless).
* **Termination** ``beta``: 1 at ``g``, outside ``I`` and, for ``"basin"`` and ``"local"``, at the
  other subgoals (the basin's paths never cross them); 0 elsewhere.
* **Policy**: greedy for the *pseudo-reward task* "reach ``g``": reward +1 on arrival at ``g``,
  0 otherwise, every state where the option terminates is absorbing with value 0, discounted by
  ``pseudo_gamma`` (the MDP's gamma if it is below 1, else 0.99). Its value is
  ``E[pseudo_gamma^(tau - 1) ; the option ends at g]`` (the +1 comes on arrival), so the policy
  reaches ``g`` as fast and as surely as possible without leaving the region where the option
  runs. It is task-independent: the MDP's own rewards play no part. Solved by modified policy
  iteration (:func:`adpart.mdp.solvers.solve`) to ``epsilon``; ties go to the lowest action
  index. For ``"local"`` the policy is the basin's (solved once); the option simply ends where
  it leaves ``I``, which on the policy's own route happens only in a stochastic domain.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from adpart.errors import ModelError, TaskError
from adpart.mdp.model import FiniteMDP
from adpart.mdp.solvers import solve
from adpart.options.option import Option
from adpart.options.settings import INITIATION_CHOICES, InitiationSettings

if TYPE_CHECKING:
    from collections.abc import Sequence

#: Default discount of the pseudo-reward task when the MDP itself is undiscounted.
UNDISCOUNTED_PSEUDO_GAMMA = 0.99
#: Solver accuracy of the pseudo-reward task (its values lie in [0, 1]).
PSEUDO_EPSILON = 1e-10
#: Relative slack of the ``"local"`` test ``V_g >= gamma**radius``, so that a state exactly
#: ``radius`` steps away is kept despite the solver's rounding.
RADIUS_RTOL = 1e-9


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


def pseudo_discount(mdp: FiniteMDP, pseudo_gamma: float | None = None) -> float:
    """The pseudo-reward task's discount: ``pseudo_gamma``, else the MDP's gamma < 1, else 0.99."""
    g = float(pseudo_gamma if pseudo_gamma is not None else (
        mdp.gamma if mdp.gamma < 1.0 else UNDISCOUNTED_PSEUDO_GAMMA))
    if not 0.0 < g < 1.0:
        raise ModelError(f"pseudo_gamma = {g!r} must lie in (0, 1)")
    return g


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
        ``(policy (S,) int64, V (S,))``: V is ``E[pseudo_gamma^(tau-1) ; end at subgoal]`` of the
        policy when continuing, i.e. 0 on ``stop``; the policy is greedy in every state,
        ``stop`` states included (an option started there takes one step first). The value of
        *starting* in a ``stop`` state is :func:`start_value` ``(mdp, subgoal, V, ...)``.
    """
    g = pseudo_discount(mdp, pseudo_gamma)
    terminal = stop | mdp.terminal
    pseudo = FiniteMDP(mdp.P, _arrivals(mdp, subgoal), g, terminal=terminal,
                       admissible=mdp.admissible, name=f"{mdp.name}/reach-{subgoal}")
    V = solve(pseudo, epsilon, method="mpi").V
    V = np.where(terminal, 0.0, V)
    return np.argmax(_reach_q(mdp, subgoal, V, g), axis=1).astype(np.int64), V


def _arrivals(mdp: FiniteMDP, subgoal: int) -> np.ndarray:
    """``(S, A)`` probability that ``(s, a)`` arrives in ``subgoal`` (the pseudo-reward)."""
    S, A = mdp.n_states, mdp.n_actions
    return np.asarray(mdp.P[:, [subgoal]].toarray()).reshape(A, S).T


def _reach_q(mdp: FiniteMDP, subgoal: int, V: np.ndarray, g: float) -> np.ndarray:
    """``(S, A)`` pseudo-reward action values from the continuation values ``V``."""
    S, A = mdp.n_states, mdp.n_actions
    Q = _arrivals(mdp, subgoal) + g * (mdp.P @ V).reshape(A, S).T
    return np.where(mdp.admissible, Q, -np.inf)


def start_value(mdp: FiniteMDP, subgoal: int, V: np.ndarray,
                pseudo_gamma: float | None = None) -> np.ndarray:
    """``(S,)`` ``E[pseudo_gamma^(tau-1) ; end at subgoal]`` of an option *started* in each state.

    Equal to ``V`` where the option continues; in a stop state (another subgoal that is a start
    state of the basin) it is the one-step look-ahead of the greedy action.
    """
    return _reach_q(mdp, subgoal, V, pseudo_discount(mdp, pseudo_gamma)).max(axis=1)


def resolve_initiation(initiation: str | None, radius: float | None) -> tuple[str, float]:
    """``(initiation, radius)`` with None read from :class:`InitiationSettings`, checked there."""
    given = {k: v for k, v in (("initiation", initiation), ("radius", radius)) if v is not None}
    try:
        chosen = InitiationSettings(**given)
    except TaskError as exc:
        raise ModelError(str(exc)) from None
    return chosen.initiation, chosen.radius


def subgoal_option(
    mdp: FiniteMDP,
    subgoal: int,
    *,
    subgoals: object = (),
    initiation: str | np.ndarray | None = None,
    radius: float | None = None,
    pseudo_gamma: float | None = None,
    name: str | None = None,
) -> Option:
    """The option to ``subgoal`` (module docstring for ``I``, ``beta`` and the policy).

    Args:
        subgoals: all subgoals (ids or mask); with ``"basin"`` and ``"local"`` the others bound
            the basin.
        initiation: ``"local"``, ``"basin"``, ``"reachable"`` or an ``(S,)`` bool mask (None:
            :class:`InitiationSettings`' default).
        radius: steps of a ``"local"`` initiation set (None: :class:`InitiationSettings`').

    Raises:
        ModelError: unknown ``initiation``, a bad ``radius``, an empty initiation set, or (with a
            given mask) an initiation state from which the subgoal cannot be reached inside it.
    """
    S = mdp.n_states
    if not isinstance(subgoal, (int, np.integer)) or not 0 <= subgoal < S:
        raise ModelError(f"subgoal {subgoal!r} is not a state 0..{S - 1}")
    subgoal = int(subgoal)
    label = name or f"to-{subgoal}"
    others = _subgoal_mask(subgoals, S)
    others[subgoal] = False
    if initiation is None or isinstance(initiation, str):  # a mask needs no radius
        initiation, radius = resolve_initiation(initiation, radius)
    if isinstance(initiation, str):
        if initiation in ("basin", "local"):
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
    if isinstance(initiation, str) and initiation == "local" and np.isfinite(radius):
        reach = start_value(mdp, subgoal, V, pseudo_gamma)
        within = pseudo_discount(mdp, pseudo_gamma) ** (radius - 1.0) * (1.0 - RADIUS_RTOL)
        init = init & (reach >= within)
        stop = stop | ~init
        stop[subgoal] = True
        if not init.any():
            raise ModelError(
                f"option {label!r}: no state reaches subgoal {subgoal} within radius {radius:g}; "
                "raise the radius (--radius) or use initiation 'basin'"
            )
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
    meta: dict[str, object] = {"kind": "subgoal", "initiation": kind}
    if kind == "local":
        meta["radius"] = radius
    return Option(label, init, policy, beta, subgoal=subgoal, meta=meta)


def subgoal_options(
    mdp: FiniteMDP,
    subgoals: Sequence[int] | np.ndarray,
    *,
    initiation: str | None = None,
    radius: float | None = None,
    cover: bool = False,
    pseudo_gamma: float | None = None,
    dropped: list[tuple[int, str]] | None = None,
) -> list[Option]:
    """One option per subgoal (in increasing state order), each bounded by the others' basins.

    ``dropped``: where given, a subgoal whose option would have an empty initiation set (no
    state can reach it, or every state that can is nearer another subgoal) is left out and
    ``(subgoal, why)`` appended there, instead of raising :class:`ModelError`: a detector's
    subgoal that no option can serve is reported, not fatal to the options of the others.

    With ``initiation="local"`` and ``cover=True`` a state that lies in no option's ball (no
    subgoal within ``radius`` steps) but in some basin is added to the initiation set of the
    option that reaches its subgoal most surely and soonest (the highest ``E[gamma^(tau-1)]``;
    the lowest subgoal on ties): the *nearest* subgoal. Every state that can reach a subgoal
    then has an option - which a decision layer needs, since its blocks must offer one - while
    a state near subgoals is offered only theirs. The option still ends where it leaves its
    initiation set, so from a far state it walks towards its subgoal until it enters another
    subgoal's ball or its own: the basin cut where a neighbouring subgoal's region begins.
    """
    mask = _subgoal_mask(subgoals, mdp.n_states)
    goals = np.flatnonzero(mask)
    initiation, radius = resolve_initiation(initiation, radius)
    if not (cover and initiation == "local"):
        options = []
        for g in goals:
            try:
                options.append(subgoal_option(mdp, int(g), subgoals=mask, initiation=initiation,
                                              radius=radius, pseudo_gamma=pseudo_gamma))
            except ModelError as exc:
                if dropped is None or "no state" not in str(exc):
                    raise
                dropped.append((int(g), str(exc)))
        return options
    parts = [_basin_parts(mdp, int(g), mask, pseudo_gamma) for g in goals]
    if not parts:
        return []
    within = pseudo_discount(mdp, pseudo_gamma) ** (radius - 1.0) * (1.0 - RADIUS_RTOL)
    basins = np.stack([p[0] for p in parts])  # (G, S)
    reach = np.where(basins, np.stack([p[3] for p in parts]), -1.0)
    balls = basins & (reach >= within)
    far = basins.any(axis=0) & ~balls.any(axis=0)
    nearest = np.argmax(reach, axis=0)  # first maximum: the lowest subgoal on ties
    options = []
    for i, (g, (_, stop, policy, _)) in enumerate(zip(goals, parts, strict=True)):
        init = balls[i] | (far & (nearest == i))
        if not init.any() and dropped is not None:
            why = (f"option 'to-{int(g)}': no state can start it (none can reach subgoal "
                   f"{int(g)}, or every one that can is nearer another subgoal)")
            dropped.append((int(g), why))
            continue
        beta = (stop | ~init).astype(np.float64)
        beta[g] = 1.0
        options.append(Option(f"to-{int(g)}", init, policy, beta, subgoal=int(g),
                              meta={"kind": "subgoal", "initiation": "local",
                                    "radius": radius, "cover": True}))
    return options


def _basin_parts(mdp: FiniteMDP, subgoal: int, subgoals: np.ndarray,
                 pseudo_gamma: float | None) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                      np.ndarray]:
    """``(basin, stop, policy, reach)`` of the basin option to ``subgoal`` (module docstring)."""
    others = subgoals.copy()
    others[subgoal] = False
    init = basin(mdp, subgoal, others)
    stop = ~init | others
    stop[subgoal] = True
    policy, V = policy_to(mdp, subgoal, stop, pseudo_gamma=pseudo_gamma)
    return init, stop, policy, start_value(mdp, subgoal, V, pseudo_gamma)

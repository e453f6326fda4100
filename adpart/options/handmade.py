"""Hand-designed options: room-to-hallway options, "repeat an action until a wall", doorways.

* :func:`room_options` / :func:`hallway_options`: the hallway options of Sutton, Precup & Singh
  (1999) as described in ENVIRONMENTS.md: the *rooms* are the connected components of the
  non-hub, non-terminal states; for every room and every hub (hallway) it leads into, one option
  whose initiation set is the room plus the room's other hubs (the hallways into it), with
  ``beta = 0`` inside the room and 1 everywhere else, and the policy of the pseudo-reward task
  "reach that hub without leaving the room" (:func:`adpart.options.subgoal_options.policy_to`).
  On ``four-rooms`` that is eight options, two per room.
* :func:`wall_options`: the options of the dissertation's Fig. 4.3: one per compass move, the
  policy repeats the move, and the option ends as soon as the agent stands in a cell where that
  move would run into a wall (``beta = 1`` there); it is admissible where the move is not
  blocked. On stochastic grids a slip does not end it; only the wall ahead does.
* :func:`doorway_options`: the hand-designed subgoals of ``three-floor`` (Fig. 5.1) - the doorway
  and stair cells (features ``doorway``/``door`` and ``stair``) - as options to subgoals with
  basin initiation sets (:func:`adpart.options.subgoal_options.subgoal_options`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from adpart.errors import ModelError
from adpart.options.option import Option
from adpart.options.subgoal_options import (
    InitiationSettings,
    policy_to,
    subgoal_options,
    transition_graph,
)

if TYPE_CHECKING:
    from adpart.envs.grid import GridDomain
    from adpart.mdp.model import FiniteMDP


def rooms(mdp: FiniteMDP, hubs: np.ndarray) -> np.ndarray:
    """``(S,)`` int room label of every non-hub, non-terminal state (-1 on hubs and terminals).

    Rooms are the connected components of the transition graph (edges taken both ways)
    restricted to those states; labels are numbered in order of each room's smallest state.
    """
    inside = ~hubs & ~mdp.terminal
    G = transition_graph(mdp)
    keep = sp.diags_array(inside.astype(np.float64))
    _, comp = csgraph.connected_components(sp.csr_array(keep @ G @ keep), directed=False)
    labels = np.full(mdp.n_states, -1, dtype=np.int64)
    _, first = np.unique(comp[inside], return_inverse=True)
    labels[inside] = first
    return labels


def room_options(mdp: FiniteMDP, hubs: np.ndarray, *, pseudo_gamma: float | None = None) -> (
    list[Option]
):
    """Options from every room to each hub it leads into (module docstring).

    Args:
        hubs: ``(S,)`` bool mask of the hub (hallway / doorway) states.

    Returns:
        Options named ``room<r>-><hub>``, ordered by room then hub.
    """
    hubs = np.asarray(hubs)
    if hubs.shape != (mdp.n_states,) or hubs.dtype != bool:
        raise ModelError(
            f"hubs must be an ({mdp.n_states},) bool mask; got {hubs.shape}, {hubs.dtype}"
        )
    if not hubs.any():
        raise ModelError("no hub states given; room options need at least one hallway or doorway")
    labels = rooms(mdp, hubs)
    G = transition_graph(mdp)
    options = []
    for r in range(int(labels.max()) + 1):  # one iteration per room, not per state
        room = labels == r
        out_of = np.asarray((room.astype(np.float64) @ G) > 0).ravel() & hubs
        into = np.asarray((G @ room.astype(np.float64)) > 0).ravel() & hubs & ~mdp.terminal
        for h in np.flatnonzero(out_of):
            init = room | (into & (np.arange(mdp.n_states) != h))
            stop = ~room
            policy, _ = policy_to(mdp, int(h), stop, pseudo_gamma=pseudo_gamma)
            options.append(Option(
                f"room{r}->{int(h)}", init, policy, stop.astype(np.float64), subgoal=int(h),
                meta={"kind": "room", "room": r, "hub": int(h)},
            ))
    return options


def hallway_options(mdp: FiniteMDP, *, pseudo_gamma: float | None = None) -> list[Option]:
    """The eight hallway options of four-rooms (Sutton et al. 1999), from feature ``hallway``."""
    if "hallway" not in mdp.features:
        raise ModelError(
            f"MDP {mdp.name!r} has no 'hallway' feature; use room_options(mdp, hubs) with a mask"
        )
    return room_options(mdp, np.asarray(mdp.features["hallway"]) == 1, pseudo_gamma=pseudo_gamma)


def wall_options(domain: GridDomain, mdp: FiniteMDP | None = None) -> list[Option]:
    """"Repeat an action until a wall" (dissertation Fig. 4.3): one option per compass move.

    Args:
        domain: a grid domain (its map says where the walls are).
        mdp: the domain's MDP under some task (default: ``domain.mdp()``).
    """
    from adpart.envs.grid import MOVES_4, MOVES_8

    mdp = domain.mdp() if mdp is None else mdp
    moves = MOVES_4 if domain.CONNECTIVITY == 4 else MOVES_8
    grid = domain.grid
    nb = grid.neighbours(moves)
    cell = np.arange(mdp.n_states) % grid.n_cells
    options = []
    for m, (move_name, _, _) in enumerate(moves):
        blocked = nb[m, cell] == cell
        init = ~blocked & ~mdp.terminal & mdp.admissible[:, m]
        if not init.any():
            continue
        options.append(Option(
            f"{move_name}-until-wall", init, np.full(mdp.n_states, m, dtype=np.int64),
            (~init).astype(np.float64), meta={"kind": "until-wall", "action": m},
        ))
    return options


#: The hand-designed doorway options start anywhere in their doorway's basin (Fig. 5.1: "from
#: anywhere in the room"), not in the discovered options' local ball.
DOORWAY_INITIATION = InitiationSettings(initiation="basin")


def doorway_options(mdp: FiniteMDP, *, initiation: InitiationSettings = DOORWAY_INITIATION,
                    pseudo_gamma: float | None = None) -> list[Option]:
    """Options to every doorway and stair cell (three-floor's hand-designed subgoals, Fig. 5.1)."""
    feats = mdp.features
    door_key = "doorway" if "doorway" in feats else "door"
    if door_key not in feats and "stair" not in feats:
        raise ModelError(f"MDP {mdp.name!r} has neither a 'doorway'/'door' nor a 'stair' feature")
    hubs = np.zeros(mdp.n_states, dtype=bool)
    for key in (door_key, "stair"):
        if key in feats:
            hubs |= np.asarray(feats[key]) == 1
    return subgoal_options(mdp, hubs, initiation=initiation.initiation,
                           radius=initiation.radius, pseudo_gamma=pseudo_gamma)

"""Built-in MAXQ task graphs: ``taxi`` (Dietterich 2000, Fig. 3 / dissertation Fig. 3.7) and
``parr-maze`` (dissertation ch. 6; Dietterich 2000 sec. 7.3).

Graphs are written in the declarative description of :mod:`adpart.learning.maxq.taskgraph`:
predicates are vectorised over the domain's state features. :func:`get_graph` looks a graph up
by name; :func:`graph_for` picks the graph matching an MDP (by its features).
"""

from __future__ import annotations

import difflib
from collections.abc import Mapping

import numpy as np

from adpart.errors import TaskError, UnknownNameError
from adpart.learning.maxq.parr_rooms import DIRECTIONS, OPPOSITE, PERPENDICULAR, RoomMap
from adpart.learning.maxq.taskgraph import Subtask, TaskGraph
from adpart.mdp.model import FiniteMDP

__all__ = ["GRAPHS", "NON_GOAL_PSEUDO_REWARD", "get_graph", "graph_for", "parr_graph",
           "taxi_graph"]

#: Taxi landmarks R, G, Y, B as (row, col) - the domain's LANDMARKS.
_LANDMARKS = ((0, 0), (0, 4), (4, 0), (4, 3))
_CELL = ("taxi_row", "taxi_col")


def _taxi_derived(mdp: FiniteMDP) -> Mapping[str, np.ndarray]:
    """``pending`` (fickle Taxi's just-picked-up flag) for the non-fickle model too (all 0)."""
    if "pending" in mdp.features:
        return {}
    return {"pending": np.zeros(mdp.n_states, dtype=np.int64)}


def _at(f: Mapping[str, np.ndarray], t: int) -> np.ndarray:
    r, c = _LANDMARKS[t]
    return (f["taxi_row"] == r) & (f["taxi_col"] == c)


def taxi_graph() -> TaskGraph:
    """Root -> {Get, Put}; Get -> {Pickup, Navigate(t)}; Put -> {Putdown, Navigate(t)};
    Navigate(t) -> {North, South, East, West}, with Dietterich's state abstractions (sec. 5):

    * Navigate(t): the taxi's cell (the passenger and destination are irrelevant to driving);
    * Get: ``C(Get, s, Navigate(t))`` depends on the passenger's location only (after the
      navigation the taxi is at ``t``); ``C(Get, s, Pickup)`` also on the taxi's cell (an illegal
      pickup leaves the taxi where it was);
    * Put: the same with the destination, plus fickle Taxi's ``pending`` flag (the destination
      may still change while the first Navigate runs);
    * Root: ``C(Root, s, Get)`` depends on passenger location and destination;
      ``C(Root, s, Put) = 0`` (Put ends the episode) - one shared entry;
    * one-step rewards: moves cost -1 everywhere (one entry); Pickup depends on passenger and
      cell; Putdown on passenger-in-taxi, destination and cell.

    All pseudo-rewards are zero (Dietterich's choice for Taxi), so the recursively optimal policy
    is also hierarchically optimal.
    """
    moves = ("North", "South", "East", "West")
    return TaskGraph(
        name="taxi",
        root="Root",
        subtasks=(
            Subtask("Root", ("Get", "Put"),
                    terminal=lambda f: np.zeros(f["passenger"].shape, dtype=bool),
                    abstraction={"Get": ("passenger", "destination"), "Put": ()},
                    description="deliver the passenger (ends with the episode)"),
            Subtask("Get", ("Pickup", "Navigate"),
                    terminal=lambda f: f["in_taxi"] == 1,
                    abstraction={"Navigate": ("passenger",),
                                 "Pickup": ("passenger", *_CELL)},
                    description="go to the passenger and pick them up"),
            Subtask("Put", ("Putdown", "Navigate"),
                    terminal=lambda f: f["in_taxi"] == 0,
                    abstraction={"Navigate": ("destination", "pending"),
                                 "Putdown": ("destination", "pending", *_CELL)},
                    description="drive to the destination and put the passenger down"),
            Subtask("Navigate", moves,
                    terminal=_at,
                    abstraction=_CELL,
                    params={"t": (0, 1, 2, 3)},
                    description="drive to landmark t"),
        ),
        primitive_abstraction={
            **{m: () for m in moves},
            "Pickup": ("passenger", *_CELL),
            "Putdown": ("in_taxi", "destination", *_CELL),
        },
        derived=_taxi_derived,
        description="Dietterich's Taxi hierarchy (Root, Get, Put, Navigate(t))",
    )


#: Pseudo-reward of the Parr subtasks Go / ExitInter / ExitHall when they end anywhere but at
#: their goal (leaving the hallway backwards, exiting a room sideways); 0 at the goal.
NON_GOAL_PSEUDO_REWARD = -100.0

#: Move(d): the maze's primitive action in direction d.
_MOVE = {"N": "GoNorth", "E": "GoEast", "S": "GoSouth", "W": "GoWest"}


def parr_graph() -> TaskGraph:
    """The hand-designed MAXQ graph of chapter 6 for Parr's maze (Dietterich 2000 sec. 7.3).

    Rooms, doors, hallways and intersections come from :class:`RoomMap` (derived from the maze's
    free cells at compile time). ``d``, ``p`` range over N, E, S, W; ``r`` (a room) and ``c``
    (a start coordinate) are **call-time** parameters bound from the state the subtask is
    called in; ``Move(d)`` is the primitive ``Go<d>``. Non-goal termination of Go / ExitInter
    / ExitHall earns the pseudo-reward :data:`NON_GOAL_PSEUDO_REWARD`, everything else 0.

    * Root -> Go(d, r): r = the current room. Ends with the episode (any goal cell).
    * Go(d, r) -> ExitInter(d, r'), ExitHall(d, r') (r' = the room at call time): runs in the
      corridor from r through the hallway rooms in direction d; ends on entering another room,
      goal = the intersection at the corridor's end. Defined where r has a d-door and is an
      intersection or a hallway along d.
    * ExitInter(d, r) -> Sniff(d, r), BackOne(d, c), PerpThree(p, c) (p perpendicular to d):
      r an intersection with a d-door; ends on leaving r; goal = the room through the d-door.
    * ExitHall(d, r) -> the same children: r a hallway along d; ends on leaving r's hall;
      goal = the intersection at the hall's d end.
    * Sniff(d, r) -> ToWall(d), FollowWall(d, p): ends on leaving r, or in a corner of the
      wall ahead (walls in d and in a perpendicular direction), where neither child can move
      on and the caller must back off.
    * ToWall(d) -> Move(d): ends where there is a wall in front (direction d).
    * FollowWall(d, p) -> Move(p): ends where the wall in direction d ends or in a corner
      (walls in d and in p).
    * BackOne(d, c) -> Move(opposite d): c = the coordinate along d at call time; ends when
      the agent has moved one unit back (the coordinate changed) or a wall blocks the way back.
      The dissertation's BackOne(d, x, y) depends on (x, y) only through this coordinate, so
      the instances that differ in the other coordinate have the same termination set and are
      one instance here (an exact reformulation, not an approximation).
    * PerpThree(p, c) -> Move(p): c = the coordinate along p at call time; ends after moving
      three units in direction p or at a wall in direction p (PerpThree(p, x, y) likewise).

    Dietterich groups BackOne and PerpThree under a Back(d, p, x, y) node; the dissertation's
    list (the spec) has no Back, so ExitInter / ExitHall call them directly. No state
    abstraction is declared: every instance already keeps tables only over the cells where it
    runs (ExitInter(d, r) over room r, BackOne(d, c) over one row or column), which is where
    the room parameters' irrelevance pays off; ``abstraction=False`` compiles the same graph.
    """
    held: dict[str, RoomMap] = {}

    def rooms_of(f: Mapping[str, np.ndarray]) -> RoomMap:
        return held["map"]

    def derived(mdp: FiniteMDP) -> Mapping[str, np.ndarray]:
        if not {"x", "y"} <= set(mdp.features):
            raise TaskError(f"the parr-maze task graph needs a grid maze with x / y features; "
                            f"{mdp.name!r} has {sorted(mdp.features)}")
        rm = RoomMap.from_cells(mdp.features["x"], mdp.features["y"])
        held["map"] = rm
        out = {"room": rm.room, **{f"wall_{d}": rm.wall[d].astype(np.int64) for d in DIRECTIONS}}
        for d in DIRECTIONS:
            out[f"axis_{d}"] = rm.axis_coordinate(d)
        return out

    def none(f: Mapping[str, np.ndarray]) -> np.ndarray:
        return np.zeros(f["room"].shape, dtype=bool)

    def wall(f: Mapping[str, np.ndarray], d: str) -> np.ndarray:
        return f[f"wall_{d}"] == 1

    def goal_or(f: Mapping[str, np.ndarray], good: np.ndarray) -> np.ndarray:
        ok = good | (f["goal"] == 1) if "goal" in f else good
        return np.where(ok, 0.0, NON_GOAL_PSEUDO_REWARD)

    # Go(d, r)
    def go_terminal(f, d, r):
        found = rooms_of(f).corridor(d, r)
        if found is None:
            return np.ones(f["room"].shape, dtype=bool)
        return ~np.isin(f["room"], found[0])

    def go_pseudo(f, d, r):
        found = rooms_of(f).corridor(d, r)
        return goal_or(f, f["room"] == (found[1] if found else -1))

    # ExitInter(d, r)
    def inter_active(f, d, r):
        rm = rooms_of(f)
        ok = (not rm.is_hallway(r)) and rm.neighbour(r, d) is not None
        return np.full(f["room"].shape, ok, dtype=bool)

    def inter_pseudo(f, d, r):
        nb = rooms_of(f).neighbour(r, d)
        return goal_or(f, f["room"] == (nb if nb is not None else -1))

    # ExitHall(d, r)
    def hall_active(f, d, r):
        ok = rooms_of(f).hall_exit(r, d) is not None
        return np.full(f["room"].shape, ok, dtype=bool)

    def hall_terminal(f, d, r):
        rm = rooms_of(f)
        run = rm.hall(r) if rm.is_hallway(r) else (r,)
        return ~np.isin(f["room"], run)

    def hall_pseudo(f, d, r):
        target = rooms_of(f).hall_exit(r, d)
        return goal_or(f, f["room"] == (target if target is not None else -1))

    def sniff_terminal(f, d, r):
        p1, p2 = PERPENDICULAR[d]
        return (f["room"] != r) | (wall(f, d) & (wall(f, p1) | wall(f, p2)))

    def back_terminal(f, d, c):
        return (f[f"axis_{d}"] != c) | wall(f, OPPOSITE[d])

    def perp_terminal(f, p, c):
        sign = 1 if p in "SE" else -1
        moved = sign * (f[f"axis_{p}"] - c)
        return (moved >= 3) | (moved < 0) | wall(f, p)

    def exit_children(d: str) -> tuple[str, ...]:
        p1, p2 = PERPENDICULAR[d]
        return (f"Sniff(d={d})", f"BackOne(d={d})", f"PerpThree(p={p1})", f"PerpThree(p={p2})")

    dirs = {"d": DIRECTIONS}
    room_at_call = {"r": "room"}
    return TaskGraph(
        name="parr-maze",
        root="Root",
        subtasks=(
            Subtask("Root", ("Go",), terminal=none,
                    description="reach the goal room (ends with the episode)"),
            Subtask("Go", ("ExitInter(d={d})", "ExitHall(d={d})"), terminal=go_terminal,
                    pseudo_reward=go_pseudo, params=dirs, call_params=room_at_call,
                    description="go from room r in direction d to the next intersection"),
            Subtask("ExitInter", exit_children, terminal=lambda f, d, r: f["room"] != r,
                    active=inter_active, pseudo_reward=inter_pseudo, params=dirs,
                    call_params=room_at_call,
                    description="leave intersection r through its d door"),
            Subtask("ExitHall", exit_children, terminal=hall_terminal, active=hall_active,
                    pseudo_reward=hall_pseudo, params=dirs, call_params=room_at_call,
                    description="leave the hall of r into the intersection in direction d"),
            Subtask("Sniff",
                    lambda d: (f"ToWall(d={d})",
                               *(f"FollowWall(d={d},p={p})" for p in PERPENDICULAR[d])),
                    terminal=sniff_terminal, params=dirs, call_params=room_at_call,
                    description="push on in direction d along walls until r is left or stuck"),
            Subtask("ToWall", lambda d: (_MOVE[d],), terminal=lambda f, d: wall(f, d),
                    params=dirs, description="move in direction d up to a wall"),
            Subtask("FollowWall", lambda d, p: (_MOVE[p],),
                    terminal=lambda f, d, p: ~wall(f, d) | wall(f, p),
                    params={"d": DIRECTIONS, "p": DIRECTIONS},
                    active=lambda f, d, p: np.full(f["room"].shape, p in PERPENDICULAR[d]),
                    description="move in direction p while the wall in direction d lasts"),
            Subtask("BackOne", lambda d: (_MOVE[OPPOSITE[d]],), terminal=back_terminal,
                    params=dirs, call_params={"c": lambda f, d: f[f"axis_{d}"]},
                    description="one step back (against d) from where it was called"),
            Subtask("PerpThree", lambda p: (_MOVE[p],), terminal=perp_terminal,
                    params={"p": DIRECTIONS}, call_params={"c": lambda f, p: f[f"axis_{p}"]},
                    description="three steps in direction p from where it was called"),
        ),
        derived=derived,
        description="chapter 6's hand-designed hierarchy for Parr's maze (Go, ExitInter, "
                    "ExitHall, Sniff, ToWall, FollowWall, BackOne, PerpThree, Move)",
    )


#: name -> factory of every built-in task graph.
GRAPHS = {"taxi": taxi_graph, "parr-maze": parr_graph}


def get_graph(name: str) -> TaskGraph:
    """The built-in task graph called ``name``."""
    if name not in GRAPHS:
        hint = difflib.get_close_matches(name, list(GRAPHS), n=1)
        raise UnknownNameError(
            f"unknown MAXQ task graph {name!r}; built-in graphs: {', '.join(GRAPHS)}"
            + (f". Did you mean {hint[0]!r}?" if hint else "")
        )
    return GRAPHS[name]()


def graph_for(mdp: FiniteMDP) -> str:
    """The built-in graph that fits ``mdp`` (``taxi`` for taxi features, ``parr-maze`` for
    Parr's maze and its mini version); raises
    UnknownNameError otherwise."""
    feats = set(mdp.features)
    if {"taxi_row", "taxi_col", "passenger", "destination"} <= feats:
        return "taxi"
    if mdp.name.startswith("parr-maze") and {"x", "y"} <= feats:
        return "parr-maze"
    raise UnknownNameError(
        f"no built-in MAXQ task graph fits {mdp.name!r}; give --graph "
        f"({', '.join(GRAPHS)}) or build a TaskGraph in Python"
    )



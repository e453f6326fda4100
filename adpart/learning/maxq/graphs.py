"""Built-in MAXQ task graphs: ``taxi`` (Dietterich 2000, Fig. 3 / dissertation Fig. 3.7).

The ``parr-maze`` graph of chapter 6 is not built in yet: its BackOne(d, x, y) and
PerpThree(p, x, y) subtasks terminate relative to the position at which they were *called*,
which needs call-time parameters that the description does not have (docs/maxq.md).

Graphs are written in the declarative description of :mod:`adpart.learning.maxq.taskgraph`:
predicates are vectorised over the domain's state features. :func:`get_graph` looks a graph up
by name; :func:`graph_for` picks the graph matching an MDP (by its features).
"""

from __future__ import annotations

import difflib
from collections.abc import Mapping

import numpy as np

from adpart.errors import UnknownNameError
from adpart.learning.maxq.taskgraph import Subtask, TaskGraph
from adpart.mdp.model import FiniteMDP

__all__ = ["GRAPHS", "get_graph", "graph_for", "taxi_graph"]

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


#: name -> factory of every built-in task graph.
GRAPHS = {"taxi": taxi_graph}


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
    """The built-in graph that fits ``mdp`` (``taxi`` for taxi features); raises
    UnknownNameError otherwise."""
    feats = set(mdp.features)
    if {"taxi_row", "taxi_col", "passenger", "destination"} <= feats:
        return "taxi"
    raise UnknownNameError(
        f"no built-in MAXQ task graph fits {mdp.name!r}; give --graph "
        f"({', '.join(GRAPHS)}) or build a TaskGraph in Python"
    )

"""Task-graph description: validation errors and compilation (masks, instances, abstraction)."""

from __future__ import annotations

import numpy as np
import pytest

from adpart.envs.domains.taxi import Taxi
from adpart.errors import TaskError, UnknownNameError
from adpart.learning.maxq import Subtask, TaskGraph, get_graph, graph_for, taxi_graph


def never(f):
    return np.zeros(f["x"].shape, dtype=bool)


def test_cycle_is_reported_with_its_path():
    with pytest.raises(TaskError, match=r"cycle A -> B -> A"):
        TaskGraph("g", "Root", (
            Subtask("Root", ("A",), terminal=never),
            Subtask("A", ("B", "North"), terminal=never),
            Subtask("B", ("A",), terminal=never),
        ))
    with pytest.raises(TaskError, match="cycle"):
        TaskGraph("g", "Root", (Subtask("Root", ("Root",), terminal=never),))


def test_subtask_without_termination_is_refused():
    with pytest.raises(TaskError, match="'Go' has no termination predicate"):
        TaskGraph("g", "Root", (
            Subtask("Root", ("Go",), terminal=never),
            Subtask("Go", ("North",)),
        ))


def test_unknown_child_names_the_fix():
    graph = TaskGraph("g", "Root", (
        Subtask("Root", ("Get",), terminal=never),
        Subtask("Get", ("Pickup", "Nort"), terminal=never),
    ))
    with pytest.raises(TaskError, match=r"unknown child 'Nort'.*Did you mean 'North'"):
        graph.compile(Taxi().mdp())
    with pytest.raises(TaskError, match="matches no instance"):
        TaskGraph("g", "Root", (
            Subtask("Root", ("Nav(t=9)",), terminal=never),
            Subtask("Nav", ("North",), terminal=never, params={"t": (0, 1)}),
        )).compile(Taxi().mdp())


def test_other_bad_graphs():
    with pytest.raises(TaskError, match="root 'Top' is not one of"):
        TaskGraph("g", "Top", (Subtask("Root", ("North",), terminal=never),))
    with pytest.raises(TaskError, match="used twice"):
        TaskGraph("g", "Root", (Subtask("Root", ("North",), terminal=never),
                                Subtask("Root", ("South",), terminal=never)))
    with pytest.raises(TaskError, match="no children"):
        TaskGraph("g", "Root", (Subtask("Root", (), terminal=never),))
    bad_shape = TaskGraph("g", "Root", (Subtask("Root", ("North",), terminal=lambda f: 0),))
    with pytest.raises(TaskError, match=r"must return an \(500,\) bool mask"):
        bad_shape.compile(Taxi().mdp())
    bad_feature = TaskGraph("g", "Root", (
        Subtask("Root", ("North",), terminal=never, abstraction=("colour",)),))
    with pytest.raises(TaskError, match="features \\['colour'\\]"):
        bad_feature.compile(Taxi().mdp())
    with pytest.raises(UnknownNameError, match="Did you mean 'taxi'"):
        get_graph("taxy")


def test_taxi_graph_compiles_to_dietterichs_hierarchy():
    mdp = Taxi(gamma=1.0).mdp()
    g = taxi_graph().compile(mdp)
    assert graph_for(mdp) == "taxi"
    assert g.names[6:] == ("Navigate(t=0)", "Navigate(t=1)", "Navigate(t=2)",
                           "Navigate(t=3)", "Get", "Put", "Root")
    root = g.root - 6
    assert [g.names[c] for c in g.children[root]] == ["Get", "Put"]
    get = g.names.index("Get") - 6
    assert [g.names[c] for c in g.children[get]] == ["Pickup", *g.names[6:10]]
    # Navigate(t=0) ends exactly on R = (0, 0); Get ends when the passenger is in the taxi
    f = mdp.features
    nav0 = g.names.index("Navigate(t=0)") - 6
    np.testing.assert_array_equal(g.terminal[nav0],
                                  ((f["taxi_row"] == 0) & (f["taxi_col"] == 0)) | mdp.terminal)
    np.testing.assert_array_equal(g.terminal[get], (f["in_taxi"] == 1) | mdp.terminal)
    # abstraction: Navigate's tables have the 24 cells where it still runs; without it, one
    # entry per running state (tables only cover the states where the subtask runs)
    assert g.c_size[nav0] == [24] * 4
    n_running = int((~g.terminal[nav0]).sum())
    assert taxi_graph().compile(mdp, abstraction=False).c_size[nav0] == [n_running] * 4
    np.testing.assert_array_equal(g.rows[nav0], np.flatnonzero(~g.terminal[nav0]))
    assert g.table_size() < taxi_graph().compile(mdp, abstraction=False).table_size() / 5

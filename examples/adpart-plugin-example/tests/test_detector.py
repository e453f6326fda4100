"""doorways: the conformance check, the doors it finds, and cut sizes against brute force."""

from __future__ import annotations

import numpy as np
import pytest
from adpart.envs.registry import get_domain
from adpart.mdp.solvers import solve
from adpart.testing import check_detector
from scipy.sparse import csgraph

from adpart_plugin_example import Doorways, ThreeRoomsLine
from adpart_plugin_example.detector import cut_off_sizes, transition_graph


def removal_cut_off(graph) -> np.ndarray:
    """For every state: delete it, count components again (S graph searches; the reference)."""
    S = graph.shape[0]
    _, comp = csgraph.connected_components(graph, directed=False)
    out = np.zeros(S, dtype=np.int64)
    for v in range(S):
        keep = np.delete(np.arange(S), v)
        _, labels = csgraph.connected_components(graph[keep][:, keep], directed=False)
        sizes = np.bincount(labels[comp[keep] == comp[v]])
        sizes = sizes[sizes > 0]
        if sizes.size > 1:
            out[v] = sizes.sum() - sizes.max()
    return out


def test_passes_adparts_detector_check():
    check_detector(Doorways)  # on adpart's two-rooms
    check_detector(Doorways, ThreeRoomsLine().mdp())


def rng():
    return np.random.default_rng(0)


def test_the_doors_of_three_rooms_line_are_the_subgoals():
    domain = ThreeRoomsLine()
    mdp = domain.mdp()
    res = Doorways().detect(mdp, solve(mdp).policy, rng())
    assert res.detector == "doorways"
    assert res.subgoals.tolist() == np.flatnonzero(mdp.features["door"]).tolist()
    # with 4 moves the cells in front of each door are cut vertices too
    wide = Doorways(narrowest=False).detect(mdp, None, rng())
    cells = [(4, 2), (5, 2), (6, 2), (10, 2), (11, 2), (12, 2)]
    assert wide.subgoals.tolist() == [domain.cell_state(x, y) for x, y in cells]
    # the door at x = 5 cuts off the west room (25 states) from the 51 others
    assert res.scores[domain.cell_state(5, 2)] == 25
    # and the cells beyond each door, (6, 2) and (10, 2), cut off 26 (the door's room + door)
    inner = Doorways(min_size=26).detect(mdp, None, rng()).subgoals.tolist()
    assert inner == [domain.cell_state(6, 2), domain.cell_state(10, 2)]
    assert Doorways(min_size=27).detect(mdp, None, rng()).subgoals.size == 0


def test_two_rooms_door_and_four_rooms_has_none():
    two = get_domain("two-rooms")
    res = Doorways().detect(two.mdp(), None, rng())
    assert res.subgoals.tolist() == [two.cell_state(5, 2)]
    # four rooms in a ring: no single hallway disconnects anything
    assert Doorways().detect(get_domain("four-rooms").mdp(), None, rng()).subgoals.size == 0


@pytest.mark.parametrize("env", ["three-rooms-line", "two-rooms", "four-rooms"])
def test_cut_off_sizes_agree_with_deleting_each_state(env):
    mdp = ThreeRoomsLine().mdp() if env == "three-rooms-line" else get_domain(env).mdp()
    graph = transition_graph(mdp)
    np.testing.assert_array_equal(cut_off_sizes(graph), removal_cut_off(graph))


def test_cut_off_sizes_of_a_small_graph_by_hand():
    # a path 0-1-2-3 with a triangle 3-4-5 and an isolated state 6
    import scipy.sparse as sp

    edges = [(0, 1), (1, 2), (2, 3), (3, 4), (4, 5), (5, 3)]
    r, c = zip(*edges, strict=True)
    g = sp.coo_array((np.ones(12), (r + c, c + r)), shape=(7, 7)).tocsr()
    assert cut_off_sizes(g).tolist() == [0, 1, 2, 2, 0, 0, 0]

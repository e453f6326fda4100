"""The simpleoptions bridge (adpart.subgoals.simpleoptions_bridge): the adapter, the detector, and
a peer's betweenness and eigenoptions against adpart's own on two-rooms, four-rooms, three-floor.

Where the two agree the test asserts equality, of the subgoals and of the numbers behind them
(centralities after undoing networkx's normalisation, eigenvectors up to sign); where they differ
it asserts the difference and its cause (a stochastic MDP planned on its most likely outcome, the
self-loops of a state-transition graph that keeps moves into walls).
"""

from __future__ import annotations

import builtins
import json
import sys

import numpy as np
import pytest
import scipy.sparse as sp
from click.testing import CliRunner
from scipy.sparse import csgraph

pytest.importorskip("simpleoptions", reason="the simpleoptions bridge needs the optional package "
                    "simpleoptions: pip install 'adpart[simpleoptions]'")
pytest.importorskip("tqdm", reason="simpleoptions 0.11.0 imports tqdm (the extra installs it)")

import networkx as nx

from adpart.cli import cli
from adpart.errors import AdpartError, TaskError
from adpart.mdp.model import FiniteMDP
from adpart.params import build_settings
from adpart.plugins import get_registry
from adpart.plugins.builtin.simpleoptions_detector import SimpleOptions
from adpart.subgoals.literature import betweenness, local_maxima, transition_graph
from adpart.subgoals.settings import EigenoptionSettings
from adpart.subgoals.simpleoptions_bridge import (
    INSTALL_HINT,
    SimpleOptionsMissingError,
    SimpleOptionsSettings,
    detect_simpleoptions,
    import_simpleoptions,
    mdp_environment,
    so_betweenness,
    so_diffusion,
    so_eigenoptions,
)
from adpart.subgoals.spectral import (
    eigenoptions,
    laplacian_eigenpairs,
    spectral_components,
)
from adpart.testing import check_detector, check_plugin_class
from adpart.workflows.resolve import resolve_domain

TASKS = {"two-rooms": "reach-goal", "four-rooms": "G1", "three-floor": "reach-goal"}
#: adpart's betweenness local maxima (tests/subgoals: four-rooms' 8 cells beside the hallways).
BETWEENNESS = {"two-rooms": [23], "four-rooms": [24, 26, 42, 54, 58, 70, 87, 89]}
#: adpart's eigenoption subgoals, k = 4 (tests/subgoals/test_spectral.py).
EIGEN = {"two-rooms": [1, 7, 28, 32, 38, 44, 47, 53], "four-rooms": [7, 11, 18, 54, 84, 92],
         "three-floor": [44, 58, 1017, 1976, 2000, 2393]}
SMALL = ["two-rooms", "four-rooms"]
DOMAINS = [*SMALL, pytest.param("three-floor", marks=pytest.mark.extended)]


def mdp_of(name: str) -> FiniteMDP:
    return resolve_domain(name).mdp(TASKS[name])


# --------------------------------------------------------------------------- the environment


@pytest.mark.parametrize("name", SMALL)
def test_the_environment_presents_the_mdp(name):
    """States, actions and dynamics are adpart's; the package's own graph search gives adpart's
    transition graph (plus the stay-in-place moves as self-loops when asked for)."""
    mdp = mdp_of(name)
    S, A = mdp.n_states, mdp.n_actions
    env = mdp_environment(mdp)
    assert env.get_state_space() == set(range(S))
    assert env.get_action_space() == set(range(A))
    assert env.get_initial_states() == np.flatnonzero(mdp.initial > 0).tolist()
    assert not any(env.is_state_terminal(s) for s in range(S))
    P = mdp.P.toarray().reshape(A, S, S)
    for s in (0, 20, S - 1):
        acts = env.get_available_actions(s)
        assert acts == np.flatnonzero(mdp.admissible[s]).tolist()
        got = np.zeros(S)
        for (nxt, reward), p in env.get_successors(s):
            got[nxt] += p
            assert reward in mdp.R[s, acts]
        np.testing.assert_allclose(got, P[acts, s].mean(axis=0), atol=1e-15)
        for a in acts:  # one action: its outcomes, the most likely first
            probs = [p for _, p in env.get_successors(s, [a])]
            assert probs == sorted(probs, reverse=True) and abs(sum(probs) - 1) < 1e-12
    ours = sp.coo_array(transition_graph(mdp))
    stg = env.generate_interaction_graph(directed=True)
    assert set(stg.edges) == set(zip(ours.row.tolist(), ours.col.tolist(), strict=True))
    looped = mdp_environment(mdp, SimpleOptionsSettings(self_loops=True))
    loops = looped.generate_interaction_graph(directed=True)
    stays = np.flatnonzero(np.einsum("ass->s", P * mdp.admissible.T[:, :, None]) > 0)
    assert sorted(s for s, t in loops.edges if s == t) == stays.tolist()
    assert stays.size > 0
    # a task's terminal states presented as terminal: the search stops there (reset and step
    # keep their own random.Random, never the global generator)
    state = __import__("random").getstate()
    term = mdp_environment(mdp, SimpleOptionsSettings(terminals=True))
    goal = int(np.flatnonzero(mdp.terminal)[0])
    assert term.is_state_terminal(goal) and goal in term.get_state_space()
    start = term.reset()
    assert term.step(term.get_available_actions(start)[0])[0] in range(S)
    assert __import__("random").getstate() == state


# --------------------------------------------------------------------------- betweenness


def reach_counts(graph: sp.csr_array) -> np.ndarray:
    """Per state: the states it reaches plus the states reaching it (itself excluded)."""
    D = csgraph.shortest_path(graph, unweighted=True)
    reach = np.isfinite(D) & ~np.eye(D.shape[0], dtype=bool)
    return reach.sum(axis=1) + reach.sum(axis=0)


def check_betweenness(name: str) -> None:
    mdp = mdp_of(name)
    S = mdp.n_states
    graph = transition_graph(mdp)
    ours = betweenness(graph)
    theirs, subgoals, stats = so_betweenness(mdp)
    assert stats["graph_states"] == S
    # the same subgoals: the local maxima of the same centrality on the same graph
    assert sorted(subgoals.tolist()) == local_maxima(graph, ours).tolist()
    assert np.all(np.diff(theirs[subgoals]) <= 0)  # the package's order: most central first
    # the same centrality: networkx (endpoints=True, normalized=True) divides by n (n - 1)
    # and counts each state as an endpoint of the paths from and to it
    np.testing.assert_allclose(theirs * S * (S - 1) - reach_counts(graph), ours, rtol=1e-10,
                               atol=1e-8)
    assert (graph != graph.T).nnz == 0  # every move of these grids can be undone


@pytest.mark.parametrize("name", SMALL)
def test_betweenness_agrees_with_adparts(name):
    check_betweenness(name)
    _, subgoals, _ = so_betweenness(mdp_of(name))
    assert sorted(subgoals.tolist()) == BETWEENNESS[name]
    # the graph is symmetric, so the undirected one gives the same subgoals
    _, undirected, _ = so_betweenness(mdp_of(name), SimpleOptionsSettings(directed_graph=False))
    assert sorted(undirected.tolist()) == BETWEENNESS[name]


@pytest.mark.extended
def test_betweenness_agrees_with_adparts_on_three_floor():
    """79 local maxima (adpart's Brandes about 38 s on one core, networkx's about 14 s)."""
    check_betweenness("three-floor")


def test_the_package_betweenness_generator_fails_on_current_networkx():
    """Why the bridge runs the subgoal part of the method itself: 0.11.0 reads
    single_target_shortest_path_length's dict (networkx >= 3.5) as (node, distance) pairs."""
    impl = import_simpleoptions()
    env = mdp_environment(mdp_of("two-rooms"))
    gen = impl.BetweennessOptionGenerator(4, 5, 1.0, 0.1, 1.0, 0, 1, 0.0)
    major, minor = (int(x) for x in nx.__version__.split(".")[:2])
    if (major, minor) >= (3, 5):
        with pytest.raises(TypeError, match="not subscriptable"):
            gen.generate_options(env, directed=True, return_subgoals=True)
    else:
        _, subgoals = gen.generate_options(env, directed=True, return_subgoals=True)
        assert sorted(subgoals) == BETWEENNESS["two-rooms"]


def test_top_and_goals():
    mdp = mdp_of("four-rooms")
    scores, every, _ = so_betweenness(mdp)
    _, top, _ = so_betweenness(mdp, SimpleOptionsSettings(top=3))
    assert top.tolist() == every[:3].tolist()
    # paths to the goal (62, hallway of the east rooms) only: the cells beside the hallways on
    # the way there
    _, toward, _ = so_betweenness(mdp, SimpleOptionsSettings(goal_paths=True))
    assert sorted(toward.tolist()) == [26, 54, 70, 89]
    res = detect_simpleoptions(mdp, SimpleOptionsSettings(top=3))
    assert res.subgoals.tolist() == sorted(top.tolist())
    np.testing.assert_array_equal(res.scores, scores)


# --------------------------------------------------------------------------- eigenoptions


def signed_pairs(options) -> dict[int, set[frozenset[int]]]:
    """PVF index -> the subgoal sets of its two signs (a PVF's sign is arbitrary)."""
    out: dict[int, set[frozenset[int]]] = {}
    for o in options:
        j = abs(int(o.pvf_id)) if hasattr(o, "pvf_id") else o.index
        out.setdefault(j, set()).add(frozenset(o.subgoals.tolist()))
    return out


def check_eigenoptions(name: str, k: int = 4) -> tuple[list, list]:
    """The same PVFs (to 1e-8, up to sign) and the same subgoals; returns both option lists."""
    mdp = mdp_of(name)
    (comp,) = spectral_components(mdp)
    vals, vecs = laplacian_eigenpairs(comp.W, k + 1)
    assert np.all(np.diff(vals) > 1e-6)  # no degenerate eigenspace: the PVFs are defined
    theirs, stats = so_eigenoptions(mdp, SimpleOptionsSettings(generator="eigenoptions", k=k))
    assert stats["graph_states"] == comp.n
    assert [o.pvf_id for o in theirs] == [f"{s}{j}" for j in range(1, k + 1) for s in ("", "-")]
    for o in theirs:
        j = abs(int(o.pvf_id))
        e = o.pvf[comp.states]
        sign = np.sign(e @ vecs[:, j])
        np.testing.assert_allclose(e, sign * vecs[:, j], atol=1e-8)
    ours, _ = eigenoptions(mdp, EigenoptionSettings(k=k, sinks="all"))
    ours_extreme, _ = eigenoptions(mdp, EigenoptionSettings(k=k))
    assert signed_pairs(theirs) == signed_pairs(ours_extreme)
    for o in theirs:  # the extreme rule keeps some of the sinks
        assert set(o.subgoals.tolist()) <= set(o.sinks.tolist())
    union = sorted({s for o in theirs for s in o.subgoals.tolist()})
    assert union == EIGEN[name]
    return theirs, ours


def paired(mdp: FiniteMDP, theirs, ours, k: int = 4) -> list[tuple[list[int], list[int]]]:
    """(their sinks, our sinks) of each of adpart's options and the package's option of the same
    PVF and sign (the one whose PVF points the same way as adpart's signed eigenvector)."""
    (comp,) = spectral_components(mdp)
    _, vecs = laplacian_eigenpairs(comp.W, k + 1)
    out = []
    for o in ours:
        v = o.sign * vecs[:, o.index]
        (match,) = [t for t in theirs if abs(int(t.pvf_id)) == o.index
                    and t.pvf[comp.states] @ v > 0]
        out.append((match.sinks.tolist(), o.sinks.tolist()))
    return out


def test_eigenoptions_agree_with_adparts_on_two_rooms():
    """Deterministic: the same PVFs, subgoals and every sink of every option."""
    theirs, ours = check_eigenoptions("two-rooms")
    for their_sinks, our_sinks in paired(mdp_of("two-rooms"), theirs, ours):
        assert their_sinks == our_sinks


def determinised(mdp: FiniteMDP) -> FiniteMDP:
    """Each action moves to its most likely outcome (ties to the lower state id)."""
    P = mdp.P.toarray()
    target = np.argmax(P, axis=1)
    D = sp.csr_array((np.ones(P.shape[0]), (np.arange(P.shape[0]), target)), shape=P.shape)
    return FiniteMDP(D, mdp.R, mdp.gamma, terminal=mdp.terminal, admissible=mdp.admissible,
                     initial=mdp.initial)


def test_eigenoptions_on_four_rooms_differ_in_sinks_by_the_determinisation():
    """Slippery four-rooms: the same PVFs and subgoals, but the package plans each action on its
    most likely outcome (2/3), adpart on the expectation. One option's sinks differ: the one
    ending at 7 (9, 1) also stops at 8 (10, 1) and 102 (10, 11) under the expectation only. On
    the determinised MDP adpart's sinks are the package's, option for option."""
    theirs, ours = check_eigenoptions("four-rooms")
    mdp = mdp_of("four-rooms")
    pairs = paired(mdp, theirs, ours)
    differ = [(t, o) for t, o in pairs if t != o]
    assert differ == [([7], [7, 8, 102])]
    det, _ = eigenoptions(determinised(mdp), EigenoptionSettings(sinks="all"))
    for their_sinks, det_sinks in paired(mdp, theirs, det):
        assert their_sinks == det_sinks


@pytest.mark.extended
def test_eigenoptions_agree_with_adparts_on_three_floor():
    """2,900 states: the package's dense eigh and Python policy iteration take about 20 s."""
    check_eigenoptions("three-floor")


@pytest.mark.parametrize("name", SMALL)
def test_self_loops_change_the_degrees_and_so_the_eigenoptions(name):
    """Keeping moves into walls as self-loops adds 1 to those states' degrees in the normalised
    Laplacian: the package's PVFs are then adpart's Laplacian of W + diag(loops), and subgoals
    move. Four-rooms: every extreme moves to a neighbour (7 11 18 54 84 92 -> 1 8 19 53 83 93);
    two-rooms: the fourth PVF's pair moves (28 32 -> 13 37)."""
    mdp = mdp_of(name)
    (comp,) = spectral_components(mdp)
    env = mdp_environment(mdp, SimpleOptionsSettings(self_loops=True))
    stg = env.generate_interaction_graph(directed=True)
    loops = np.zeros(mdp.n_states)
    loops[[s for s, t in stg.edges if s == t]] = 1.0
    W = sp.csr_array(comp.W + sp.diags_array(loops[comp.states]))
    _, vecs = laplacian_eigenpairs(W, 5)
    theirs, _ = so_eigenoptions(mdp, SimpleOptionsSettings(generator="eigenoptions",
                                                           self_loops=True))
    for o in theirs:
        e, v = o.pvf[comp.states], vecs[:, abs(int(o.pvf_id))]
        np.testing.assert_allclose(e, np.sign(e @ v) * v, atol=1e-8)
    res = detect_simpleoptions(mdp, SimpleOptionsSettings(generator="eigenoptions",
                                                          self_loops=True))
    expected = {"two-rooms": [1, 7, 13, 37, 38, 44, 47, 53],
                "four-rooms": [1, 8, 19, 53, 83, 93]}[name]
    assert res.subgoals.tolist() == expected != EIGEN[name]


# --------------------------------------------------------------------------- diffusion options


def test_diffusion_subgoals_are_the_generators():
    """The bridge's diffusion subgoals are generate_options' own (which works on this env), and
    the local maxima of the scores it returns: two-rooms' 8 corners, four-rooms' 16."""
    impl = import_simpleoptions()
    mdp = mdp_of("two-rooms")
    scores, subgoals, _ = so_diffusion(mdp)
    gen = impl.DiffusionOptionGenerator(mdp.n_states, 8, 1.0, 0.0, 1.0, 0, 1, 0.0)
    from adpart.subgoals.simpleoptions_bridge import _quiet

    with _quiet():
        _, theirs = gen.generate_options(mdp_environment(mdp), return_subgoals=True)
    assert subgoals.tolist() == list(theirs)
    assert sorted(subgoals.tolist()) == local_maxima(transition_graph(mdp), scores).tolist()
    assert sorted(subgoals.tolist()) == [0, 4, 5, 8, 46, 50, 51, 54]
    four = detect_simpleoptions(mdp_of("four-rooms"), SimpleOptionsSettings(generator="diffusion"))
    assert four.subgoals.tolist() == [0, 4, 5, 9, 41, 45, 52, 56, 57, 61, 68, 72, 94, 98, 99, 103]
    assert four.scores[four.subgoals].min() > 0


def dead_end_chain() -> FiniteMDP:
    """0 <-> 1 <-> 2 <-> 3 -> 4 -> 5, 5 only staying in place: 5 has no out-edge on the
    papers' graph, and 4's only out-edge leads to 5."""
    S, A = 6, 2  # action 0 left, action 1 right
    left = [max(s - 1, 0) for s in range(S)]
    right = [min(s + 1, S - 1) for s in range(S)]
    left[4], left[5] = 5, 5  # 4 and 5 lead only onwards
    P = sp.csr_array((np.ones(A * S), (np.arange(A * S), left + right)), shape=(A * S, S))
    return FiniteMDP(P, np.full((S, A), -1.0), 0.9, initial=np.eye(S)[0])


def test_diffusion_survives_a_state_left_without_edges_by_the_packages_removal():
    """The package removes the states without an out-edge once, so 4 (whose only out-edge led
    to 5) keeps degree 0 and its eigendecomposition fails; the bridge repeats the removal, and
    the other states' scores are the package's on the graph without 4 and 5."""
    impl = import_simpleoptions()
    mdp = dead_end_chain()
    gen = impl.DiffusionOptionGenerator(mdp.n_states, 8, 1.0, 0.0, 1.0, 0, 1, 0.0)
    _, _, adj, deg, _ = gen._extract_graph_matrices(mdp_environment(mdp))
    assert (np.asarray(deg).diagonal() == 0).any()  # 4, after one removal
    with pytest.raises(ValueError, match="infs or NaNs"), np.errstate(all="ignore"):
        gen._compute_eigendecomp(deg, adj)  # the package's own path
    scores, subgoals, stats = so_diffusion(mdp)
    assert np.isfinite(scores).all() and scores[[4, 5]].tolist() == [0.0, 0.0]
    # the same scores as the package gives on the chain that never had 4 and 5
    short = FiniteMDP(sp.csr_array((np.ones(8), (np.arange(8), [0, 0, 1, 2, 1, 2, 3, 3])),
                                   shape=(8, 4)), np.full((4, 2), -1.0), 0.9,
                      initial=np.eye(4)[0])
    theirs, _, _ = so_diffusion(short)
    np.testing.assert_allclose(scores[:4], theirs, atol=1e-10)
    assert stats["graph_states"] == 6 and set(subgoals.tolist()) <= {0, 1, 2, 3}


def test_a_failure_inside_the_package_is_named_as_an_adpart_error(monkeypatch):
    import adpart.subgoals.simpleoptions_bridge as bridge

    def broken(mdp, settings):
        raise ValueError("array must not contain infs or NaNs")

    monkeypatch.setattr(bridge, "so_diffusion", broken)
    with pytest.raises(TaskError, match=r"simpleoptions' diffusion generator failed on .*NaNs"):
        detect_simpleoptions(dead_end_chain(), SimpleOptionsSettings(generator="diffusion"))


# --------------------------------------------------------------------------- settings, plugin, CLI


@pytest.mark.parametrize(("values", "word"), [
    ({"generator": "eigen"}, "generator"), ({"k": 0}, "k"), ({"discount": 1.0}, "discount"),
    ({"time_scale": 0}, "time_scale"), ({"sinks": "some"}, "sinks"), ({"top": -1}, "top")])
def test_bad_settings_name_the_parameter(values, word):
    with pytest.raises(TaskError, match=word):
        build_settings(SimpleOptionsSettings, values)


def test_k_beyond_the_graph_is_refused():
    with pytest.raises(TaskError, match=r"--k 55 .* 55 states"):
        so_eigenoptions(mdp_of("two-rooms"), SimpleOptionsSettings(generator="eigenoptions", k=55))


def test_the_plugin_passes_the_detector_conformance_check():
    check_plugin_class(SimpleOptions)
    check_detector(SimpleOptions)
    check_detector(SimpleOptions, mdp_of("two-rooms"))
    spec = get_registry().get("subgoal-detector", "simpleoptions")
    assert spec.factory is SimpleOptions and spec.package == "adpart"


def test_the_detector_runs_through_the_cli(tmp_path):
    kb = str(tmp_path / "kb")
    runner = CliRunner()
    learned = runner.invoke(cli, ["learn", "two-rooms", "--learner", "value-iteration",
                                  "--episodes", "20", "--kb", kb, "--out", str(tmp_path / "o"),
                                  "--json"])
    assert learned.exit_code == 0, learned.output
    base = ["discover", "two-rooms", "--policy", "policy:1", "--kb", kb, "--detector",
            "simpleoptions"]
    eig = runner.invoke(cli, [*base, "--generator", "eigenoptions", "--json"])
    assert eig.exit_code == 0, eig.output
    out = json.loads(eig.output)
    assert out["subgoals"] == EIGEN["two-rooms"]
    assert out["params"]["generator"] == "eigenoptions" and out["params"]["k"] == 4
    assert [o["pvf"] for o in out["stats"]["eigenoptions"]] == ["1", "-1", "2", "-2", "3", "-3",
                                                                "4", "-4"]
    bet = runner.invoke(cli, [*base])
    assert bet.exit_code == 0, bet.output
    assert "simpleoptions on two-rooms" in bet.output and "subgoals: 23" in bet.output
    for args, word in [(["--generator", "eigen"], "--generator"), (["--time-scale", "0"],
                                                              "--time-scale"),
                       (["--generator", "eigenoptions", "--k", "60"], "--k")]:
        bad = runner.invoke(cli, [*base, *args])
        assert bad.exit_code == 2, bad.output
        lines = bad.output.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("Error:") and word in lines[0], lines


@pytest.mark.parametrize("missing", ["simpleoptions", "tqdm"])
def test_a_missing_package_names_the_extra(monkeypatch, tmp_path, missing):
    real = builtins.__import__

    def refuse(name, *args, **kwargs):
        if name == missing or name.startswith(f"{missing}."):
            raise ModuleNotFoundError(f"No module named {missing!r}", name=missing)
        return real(name, *args, **kwargs)

    for mod in [m for m in sys.modules if m == "simpleoptions" or m.startswith(
            ("simpleoptions.", "tqdm"))]:
        monkeypatch.delitem(sys.modules, mod)
    monkeypatch.setattr(builtins, "__import__", refuse)
    mdp = mdp_of("two-rooms")
    with pytest.raises(SimpleOptionsMissingError) as err:
        SimpleOptions(generator="eigenoptions").detect(mdp, None, np.random.default_rng(0))
    assert isinstance(err.value, AdpartError)
    assert INSTALL_HINT in str(err.value) == str(err.value)
    assert "pip install 'adpart[simpleoptions]'" in str(err.value)
    assert repr(missing) in str(err.value)
    # through the CLI: one line, exit 2
    kb = str(tmp_path / "kb")
    runner = CliRunner()
    monkeypatch.setattr(builtins, "__import__", real)
    learned = runner.invoke(cli, ["learn", "two-rooms", "--learner", "value-iteration",
                                  "--episodes", "5", "--kb", kb, "--out", str(tmp_path / "o")])
    assert learned.exit_code == 0, learned.output
    monkeypatch.setattr(builtins, "__import__", refuse)
    bad = runner.invoke(cli, ["discover", "two-rooms", "--policy", "policy:1", "--kb", kb,
                              "--detector", "simpleoptions"])
    assert bad.exit_code == 2, bad.output
    lines = bad.output.strip().splitlines()
    assert len(lines) == 1 and "pip install 'adpart[simpleoptions]'" in lines[0], lines

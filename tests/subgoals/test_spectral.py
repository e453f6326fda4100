"""Eigenoptions and covering options (adpart.subgoals.spectral), against independent oracles.

The oracles are built here by hand: Laplacians written entry by entry from an adjacency and
decomposed by a dense ``numpy.linalg.eigh``, option values by a value iteration looping over
states and actions, expected hitting times of the random walk by one linear system per target.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.sparse as sp
from click.testing import CliRunner

from adpart.cli import cli
from adpart.errors import TaskError
from adpart.mdp.model import FiniteMDP
from adpart.plugins.builtin.detectors import Covering, Eigenoptions
from adpart.subgoals.settings import CoveringSettings, EigenoptionSettings
from adpart.subgoals.spectral import (
    canonical_basis,
    covering_options,
    covering_rounds,
    eigenoptions,
    eigenpurpose_values,
    fiedler_vector,
    laplacian_eigenpairs,
    spectral_components,
)
from adpart.testing import check_detector, check_plugin_class
from adpart.workflows.resolve import resolve_domain

# --------------------------------------------------------------------------- oracles and graphs


def grid_adjacency(rows: int, cols: int) -> np.ndarray:
    """4-connected ``rows x cols`` grid, vertex ``y * cols + x``."""
    n = rows * cols
    W = np.zeros((n, n))
    for y in range(rows):
        for x in range(cols):
            s = y * cols + x
            if x + 1 < cols:
                W[s, s + 1] = W[s + 1, s] = 1.0
            if y + 1 < rows:
                W[s, s + cols] = W[s + cols, s] = 1.0
    return W


def path_adjacency(n: int) -> np.ndarray:
    W = np.zeros((n, n))
    for i in range(n - 1):
        W[i, i + 1] = W[i + 1, i] = 1.0
    return W


def random_connected(n: int, seed: int) -> np.ndarray:
    """A random spanning tree plus random extra edges."""
    rng = np.random.default_rng(seed)
    W = np.zeros((n, n))
    for v in range(1, n):
        u = int(rng.integers(0, v))
        W[u, v] = W[v, u] = 1.0
    extra = np.triu(rng.random((n, n)) < 0.08, 1)
    W = np.maximum(W, extra + extra.T)
    np.fill_diagonal(W, 0.0)
    return W


def oracle_laplacian(W: np.ndarray, kind: str) -> np.ndarray:
    """The Laplacian written out entry by entry."""
    n = W.shape[0]
    d = [sum(W[i, j] for j in range(n)) for i in range(n)]
    L = np.zeros((n, n))
    for i in range(n):
        for j in range(n):
            if kind == "combinatorial":
                L[i, j] = (d[i] if i == j else 0.0) - W[i, j]
            else:
                L[i, j] = (1.0 if i == j else 0.0) - W[i, j] / np.sqrt(d[i] * d[j])
    return L


def oracle_adjacency(mdp: FiniteMDP) -> np.ndarray:
    """The symmetrised transition graph of ``mdp``, by looping over (s, a, s')."""
    S, A = mdp.n_states, mdp.n_actions
    P = mdp.P.toarray()
    W = np.zeros((S, S))
    for s in range(S):
        for a in range(A):
            if mdp.admissible[s, a]:
                for t in range(S):
                    if t != s and P[a * S + s, t] > 0:
                        W[s, t] = W[t, s] = 1.0
    return W


def hitting_times(W: np.ndarray) -> np.ndarray:
    """``H[s, t]``: expected steps of the simple random walk from ``s`` to first reach ``t``,
    from ``(I - P restricted to V \\ {t}) h = 1`` for every target ``t``."""
    n = W.shape[0]
    P = W / W.sum(axis=1, keepdims=True)
    H = np.zeros((n, n))
    for t in range(n):
        keep = np.arange(n) != t
        H[keep, t] = np.linalg.solve(np.eye(n - 1) - P[np.ix_(keep, keep)], np.ones(n - 1))
    return H


def graph_mdp(W: np.ndarray, initial: np.ndarray | None = None,
              slip: float = 0.0) -> FiniteMDP:
    """An MDP whose action ``j`` moves to the ``j``-th neighbour (inadmissible past the degree);
    with ``slip`` > 0 it moves to a uniformly random neighbour with that probability instead."""
    n = W.shape[0]
    nbrs = [np.flatnonzero(W[s]) for s in range(n)]
    A = max(1, max(len(v) for v in nbrs))
    P = np.zeros((n, A, n))
    adm = np.zeros((n, A), dtype=bool)
    for s in range(n):
        if len(nbrs[s]) == 0:
            P[s, 0, s] = 1.0
            adm[s, 0] = True
        for j, t in enumerate(nbrs[s]):
            P[s, j, t] += 1.0 - slip
            P[s, j, nbrs[s]] += slip / len(nbrs[s])
            adm[s, j] = True
    return FiniteMDP.from_dense(P, np.zeros((n, A)), 0.9, admissible=adm, initial=initial)


def projector(U: np.ndarray) -> np.ndarray:
    return U @ U.T


# --------------------------------------------------------------------------- eigenpairs


GRAPHS = {"grid5x5": grid_adjacency(5, 5), "random30": random_connected(30, 7)}


@pytest.mark.parametrize("graph", GRAPHS)
@pytest.mark.parametrize("kind", ["normalised", "combinatorial"])
@pytest.mark.parametrize("dense_below", [10**6, 0], ids=["eigh", "eigsh"])
def test_eigenpairs_match_a_dense_eigh_of_the_hand_built_laplacian(graph, kind, dense_below):
    W = GRAPHS[graph]
    want_vals, want_vecs = np.linalg.eigh(oracle_laplacian(W, kind))
    m = 10
    vals, vecs = laplacian_eigenpairs(sp.csr_array(W), m, kind=kind, dense_below=dense_below)
    np.testing.assert_allclose(vals, want_vals[:m], atol=1e-10)
    np.testing.assert_allclose(vecs.T @ vecs, np.eye(m), atol=1e-10)
    # every eigenspace the first m cover whole: the same projector (vectors are defined up to
    # sign, and up to rotation inside a repeated eigenvalue)
    cuts = [j for j in range(1, m + 1) if want_vals[j] - want_vals[j - 1] > 1e-6]
    assert cuts, "no gap in the spectrum to compare subspaces at"
    for j in cuts:
        np.testing.assert_allclose(projector(vecs[:, :j]), projector(want_vecs[:, :j]),
                                   atol=1e-8)
    # ...and inside a repeated eigenvalue the basis is the canonical one of the oracle's span
    lo = 0
    for j in cuts:
        np.testing.assert_allclose(vecs[:, lo:j], canonical_basis(want_vecs[:, lo:j], 1e-10),
                                   atol=1e-8)
        lo = j


@pytest.mark.parametrize("kind", ["normalised", "combinatorial"])
def test_the_grid_has_repeated_eigenvalues_and_the_basis_ignores_the_rotation(kind):
    """The 5x5 grid's second and third eigenvalues are equal (the horizontal and vertical modes):
    any rotation of the pair is a solver's valid answer; the canonical basis is the same for
    all. Under the combinatorial Laplacian its extremes are the four corners (the projections of
    the corners 0 and then 4, the longest)."""
    W = grid_adjacency(5, 5)
    vals, vecs = np.linalg.eigh(oracle_laplacian(W, kind))
    assert vals[2] - vals[1] < 1e-12 < vals[3] - vals[2]
    block = vecs[:, 1:3]
    ref = canonical_basis(block, 1e-10)
    np.testing.assert_allclose(projector(ref), projector(block), atol=1e-12)
    for theta in (0.3, 1.1, 2.9):
        rot = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
        np.testing.assert_allclose(canonical_basis(block @ rot, 1e-10), ref, atol=1e-12)
        np.testing.assert_allclose(canonical_basis(-block @ rot, 1e-10), ref, atol=1e-12)
    if kind == "combinatorial":
        assert [int(ref[:, c].argmax()) for c in (0, 1)] == [0, 4]
        assert [int(ref[:, c].argmin()) for c in (0, 1)] == [24, 20]


# --------------------------------------------------------------------------- covering options


@pytest.mark.parametrize("n", [7, 10])
def test_path_fiedler_vector_is_monotone_and_the_first_pair_is_the_two_ends(n):
    W = path_adjacency(n)
    lam, v = fiedler_vector(sp.csr_array(W))
    assert lam == pytest.approx(np.linalg.eigvalsh(oracle_laplacian(W, "combinatorial"))[1])
    assert lam == pytest.approx(2 - 2 * np.cos(np.pi / n))  # the path's closed form
    step = np.diff(v)
    assert np.all(step < 0) or np.all(step > 0)
    first = covering_rounds(sp.csr_array(W), 1)
    assert {first[0][0], first[0][1]} == {0, n - 1}
    # through the MDP: a chain whose states are the path's vertices
    options, _ = covering_options(graph_mdp(W), CoveringSettings(rounds=1))
    assert set(options[0].ends) == {0, n - 1}


@pytest.mark.parametrize("graph", ["path10", "grid5x5", "grid4x6"])
def test_covering_options_reduce_the_expected_hitting_times(graph):
    """Each round's edge lowers the mean expected hitting time over all pairs (exact, linear
    systems); the largest one falls over the rounds (not in every round: on the path the
    second round's edge raises it from 25.0 to 26.7, on the grid the first from 85.5 to 87.6);
    the algebraic connectivity never falls, and matches the oracle's every round."""
    W = {"path10": path_adjacency(10), "grid5x5": grid_adjacency(5, 5),
         "grid4x6": grid_adjacency(4, 6)}[graph]
    n = W.shape[0]
    rounds = covering_rounds(sp.csr_array(W), 6)
    assert len(rounds) == 6
    G = W.copy()
    H = hitting_times(G)
    means, maxima, lams = [H.sum() / (n * (n - 1))], [H.max()], []
    for i, j, lam in rounds:
        want = np.linalg.eigvalsh(oracle_laplacian(G, "combinatorial"))
        assert lam == pytest.approx(want[1], abs=1e-10)
        if want[2] - want[1] > 1e-9:  # a simple eigenvalue: the oracle's extremes are the ends
            vec = np.linalg.eigh(oracle_laplacian(G, "combinatorial"))[1][:, 1]
            tied_lo = np.flatnonzero(vec <= vec.min() + 1e-9)
            tied_hi = np.flatnonzero(vec >= vec.max() - 1e-9)
            assert {i, j} == {int(tied_lo[0]), int(tied_hi[0])}  # the lowest id among ties
        assert G[i, j] == 0
        G[i, j] = G[j, i] = 1.0
        H = hitting_times(G)
        means.append(H.sum() / (n * (n - 1)))
        maxima.append(H.max())
        lams.append(lam)
    assert np.all(np.diff(means) < 0), means
    assert maxima[-1] < 0.6 * maxima[0], maxima
    assert np.all(np.diff(lams) >= -1e-12), lams
    if graph == "path10":  # 81 = (n - 1)^2 end to end; the cycle's largest is 5 * 5 = 25
        assert maxima[:3] == pytest.approx([81.0, 25.0, 26.7], abs=0.05)
    if graph == "grid5x5":
        assert maxima[:2] == pytest.approx([85.5, 87.6], abs=0.05)


def test_covering_stops_when_the_ends_are_already_neighbours():
    triangle = np.ones((3, 3)) - np.eye(3)
    assert covering_rounds(sp.csr_array(triangle), 4) == []


# --------------------------------------------------------------------------- eigenoption values


def loop_values(mdp: FiniteMDP, e: np.ndarray, discount: float, sweeps: int = 2000) -> tuple[
    np.ndarray, np.ndarray
]:
    """Value iteration of r(s, s') = e(s') - e(s) with a terminate action (value 0), by loops."""
    S, A = mdp.n_states, mdp.n_actions
    P = mdp.P.toarray()
    V = np.zeros(S)
    best = np.zeros(S)
    for _ in range(sweeps):
        new = np.zeros(S)
        for s in range(S):
            qs = []
            for a in range(A):
                if mdp.admissible[s, a]:
                    row = P[a * S + s]
                    qs.append(sum(row[t] * (e[t] - e[s] + discount * V[t]) for t in range(S)))
            best[s] = max(qs)
            new[s] = max(0.0, best[s])
        V = new
    return V, best


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("slip", [0.0, 0.3])
def test_eigenpurpose_values_match_a_loop_oracle_and_the_maximum_is_a_sink(seed, slip):
    W = random_connected(9, seed)
    mdp = graph_mdp(W, slip=slip)
    rng = np.random.default_rng(seed)
    E = rng.standard_normal((9, 3))
    V, Qmax, _ = eigenpurpose_values(mdp, E, 0.9)
    for j in range(3):
        want_V, want_best = loop_values(mdp, E[:, j], 0.9, sweeps=400)
        np.testing.assert_allclose(V[:, j], want_V, atol=1e-10)
        np.testing.assert_allclose(Qmax[:, j], want_best, atol=1e-10)
        top = int(E[:, j].argmax())
        assert Qmax[top, j] <= 1e-12  # the argmax of e is always a sink (module docstring)
        assert V[top, j] == 0.0


# --------------------------------------------------------------------------- the domains


def oracle_extremes(mdp: FiniteMDP, kind: str, m: int) -> list[set[frozenset[int]]]:
    """{argmax set, argmin set} of the oracle's eigenvectors 1..m (a vector's sign is
    arbitrary), each checked simple."""
    vals, vecs = np.linalg.eigh(oracle_laplacian(oracle_adjacency(mdp), kind))
    out = []
    for j in range(1, m + 1):
        assert min(vals[j] - vals[j - 1], vals[j + 1] - vals[j]) > 1e-6  # simple eigenvalue
        e = vecs[:, j]
        out.append({frozenset(np.flatnonzero(e >= e.max() - 1e-9).tolist()),
                    frozenset(np.flatnonzero(e <= e.min() + 1e-9).tolist())})
    return out


def unsigned(pairs: list[tuple[set[int], set[int]]]) -> list[set[frozenset[int]]]:
    return [{frozenset(a), frozenset(b)} for a, b in pairs]


def as_pairs(options) -> list[set[int]]:
    """Eigenoptions' subgoals by eigenvector: {+ subgoal states} and {- subgoal states}."""
    return [(set(options[2 * j].subgoals.tolist()), set(options[2 * j + 1].subgoals.tolist()))
            for j in range(len(options) // 2)]


def test_two_rooms():
    """Two-rooms (8-connected, 10 x 6, the doorway 23 at x = 5, y = 2; state 46 the start).

    Eigenoptions (normalised Laplacian, k = 4): the first eigenvector splits the rooms, its
    sinks 44 (x 8, y 4) and 38 (1, 4) lie one in each room; then 47 (1, 5) and 1 (1, 0), 7
    (8, 0) and 53 (8, 5), 32 (4, 3) and 28 (0, 3). Every one is the argmax / argmin of the
    oracle's eigenvector. Covering options: the first round joins the rooms' far bottom corners
    46 (0, 5) and 54 (9, 5), the second their far top corners 0 (0, 0) and 8 (9, 0).
    """
    mdp = resolve_domain("two-rooms").mdp("reach-goal")
    x = mdp.features["x"]
    options, stats = eigenoptions(mdp)
    assert stats["states"] == 55 and stats["components"] == 1
    pairs = as_pairs(options)
    assert pairs == [({44}, {38}), ({47}, {1}), ({7}, {53}), ({32}, {28})]
    assert unsigned(pairs) == oracle_extremes(mdp, "normalised", 4)
    (plus,), (minus,) = pairs[0]
    assert (x[plus] < 5) != (x[minus] < 5)  # one in each room
    for o in options:
        assert set(o.subgoals.tolist()) <= set(o.sinks.tolist())
    res = Eigenoptions().detect(mdp, None, np.random.default_rng(0))
    assert res.subgoals.tolist() == [1, 7, 28, 32, 38, 44, 47, 53]
    assert res.scores.sum() == 8 and res.threshold is None
    json.dumps(res.to_json())

    cover, _ = covering_options(mdp)
    assert [o.ends for o in cover] == [(46, 54), (0, 8), (50, 51), (18, 27)]
    vals, vecs = np.linalg.eigh(oracle_laplacian(oracle_adjacency(mdp), "combinatorial"))
    assert vals[2] - vals[1] > 1e-6
    assert {int(vecs[:, 1].argmin()), int(vecs[:, 1].argmax())} == {46, 54}
    res = Covering().detect(mdp, None, np.random.default_rng(0))
    assert res.subgoals.tolist() == [0, 8, 18, 27, 46, 50, 51, 54]


def test_four_rooms():
    """Four-rooms (4-connected, slippery; rooms' outer corners 0 (x 1, y 1), 9 (11, 1),
    94 (1, 11), 103 (11, 11)).

    With the combinatorial Laplacian the first three eigenvectors' eigenoptions end at those
    four far corners. With the paper's normalised Laplacian they end one cell diagonally inside
    them: 11 (2, 2), 18 (10, 2), 84 (2, 10), 92 (10, 10), because its eigenvector is D^{1/2}
    times the random walk's and a corner cell has degree 2 against an inner cell's 4. The fourth
    pair is 54 (9, 6, above the hallway 62) and 7 (9, 1). Covering options join opposite far
    corners: 9 and 94, then 103 and 0.
    """
    mdp = resolve_domain("four-rooms").mdp("G1")
    norm, _ = eigenoptions(mdp)
    pairs = as_pairs(norm)
    assert pairs[:3] == [({84}, {18}), ({11}, {92}), ({92}, {84})]
    assert pairs[3] == ({54}, {7})
    assert unsigned(pairs) == oracle_extremes(mdp, "normalised", 4)
    comb, _ = eigenoptions(mdp, EigenoptionSettings(laplacian="combinatorial", k=3))
    assert {s for o in comb for s in o.subgoals.tolist()} == {0, 9, 94, 103}
    assert unsigned(as_pairs(comb)) == oracle_extremes(mdp, "combinatorial", 3)
    # every sink rule keeps the extreme; "all" adds the other sinks
    every, _ = eigenoptions(mdp, EigenoptionSettings(sinks="all"))
    for one, all_ in zip(norm, every, strict=True):
        assert set(one.subgoals.tolist()) <= set(all_.subgoals.tolist())
        assert all_.subgoals.tolist() == all_.sinks.tolist()
    assert sum(o.sinks.size for o in every) > len(every)
    cover, _ = covering_options(mdp)
    assert [o.ends for o in cover[:2]] == [(9, 94), (103, 0)]


# --------------------------------------------------------------------------- components, errors


def test_components_are_those_of_the_reachable_states():
    """Two chains of 4 states with starts in both, a third chain nobody starts in."""
    W = np.zeros((11, 11))
    for lo, hi in ((0, 4), (4, 8), (8, 11)):
        W[lo:hi, lo:hi] = path_adjacency(hi - lo)
    initial = np.zeros(11)
    initial[[1, 6]] = 0.5
    mdp = graph_mdp(W, initial=initial)
    comps = spectral_components(mdp)
    assert [c.states.tolist() for c in comps] == [[0, 1, 2, 3], [4, 5, 6, 7]]
    np.testing.assert_array_equal(comps[1].W.toarray(), path_adjacency(4))
    options, stats = eigenoptions(mdp, EigenoptionSettings(k=1))
    assert stats["components"] == 2
    assert [set(o.subgoals.tolist()) for o in options] == [{0}, {3}, {4}, {7}]
    assert [o.component for o in options] == [0, 0, 1, 1]
    cover, _ = covering_options(mdp, CoveringSettings(rounds=1))
    assert [set(o.ends) for o in cover] == [{0, 3}, {4, 7}]
    # k up to the largest component's size - 1
    eigenoptions(mdp, EigenoptionSettings(k=3))
    with pytest.raises(TaskError, match=r"--k 4 .* largest connected component .* 4 states"):
        eigenoptions(mdp, EigenoptionSettings(k=4))


def test_a_graph_of_fewer_than_three_states_is_refused():
    W = path_adjacency(2)
    for run in (lambda m: eigenoptions(m), lambda m: covering_options(m)):
        with pytest.raises(TaskError, match="at least 3 states"):
            run(graph_mdp(W))
    with pytest.raises(TaskError, match=r"k = 0 must be >= 1 \(--k\)"):
        EigenoptionSettings(k=0)
    with pytest.raises(TaskError, match="discount"):
        EigenoptionSettings(discount=1.0)


# --------------------------------------------------------------------------- plugins and CLI


@pytest.mark.parametrize("cls", [Eigenoptions, Covering])
def test_the_plugins_pass_the_detector_conformance_check(cls):
    check_plugin_class(cls)
    check_detector(cls)


def test_the_detectors_run_through_the_cli(tmp_path):
    kb = str(tmp_path / "kb")
    runner = CliRunner()
    learned = runner.invoke(cli, ["learn", "two-rooms", "--learner", "value-iteration",
                                  "--episodes", "20", "--kb", kb, "--out", str(tmp_path / "o"),
                                  "--json"])
    assert learned.exit_code == 0, learned.output
    base = ["discover", "two-rooms", "--policy", "policy:1", "--kb", kb]
    eig = runner.invoke(cli, [*base, "--detector", "eigenoptions", "--json"])
    assert eig.exit_code == 0, eig.output
    out = json.loads(eig.output)
    assert out["subgoals"] == [1, 7, 28, 32, 38, 44, 47, 53]
    assert out["params"] == {"k": 4, "laplacian": "normalised", "discount": 0.9,
                             "sinks": "extreme"}
    assert len(out["stats"]["eigenoptions"]) == 8
    two = runner.invoke(cli, [*base, "--detector", "eigenoptions", "--k", "1", "--json"])
    assert json.loads(two.output)["subgoals"] == [38, 44]
    cov = runner.invoke(cli, [*base, "--detector", "covering", "--rounds", "2"])
    assert cov.exit_code == 0, cov.output
    assert "covering on two-rooms" in cov.output and "subgoals: 0, 8, 46, 54" in cov.output
    for args, word in [(["--detector", "eigenoptions", "--k", "0"], "--k"),
                       (["--detector", "eigenoptions", "--k", "60"], "--k"),
                       (["--detector", "covering", "--rounds", "0"], "--rounds")]:
        bad = runner.invoke(cli, [*base, *args])
        assert bad.exit_code == 2, bad.output
        lines = bad.output.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("Error:") and word in lines[0], lines

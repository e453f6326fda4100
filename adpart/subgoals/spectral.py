"""Spectral option discovery, reduced to subgoals: eigenoptions and covering options.

Both methods work on the **undirected transition graph of the states reachable from the start
distribution**: :func:`~adpart.subgoals.literature.transition_graph` (an edge ``s -> s'`` when an
admissible action moves ``s`` to ``s' != s``), restricted to the states a directed search from the
support of ``mdp.initial`` reaches, symmetrised (``W = 1`` where either direction is an edge) and
split into connected components. Every component holds a start state, and each is closed under
the dynamics (a move from a reachable state reaches a state of the same component), so each
component's eigenvectors and option values are computed on it alone. States the task never
reaches are left out: each unreachable region would be a component of its own, with an eigenvalue
0 of its own and eigenvectors (and hence subgoals) living where the agent never goes. A task's
terminal states are ordinary states here (the graph is the environment's: a goal of one task is a
cell of another, and :func:`transition_graph` keeps their moves). Components of fewer than 3 states
give no option.

* **Eigenoptions** (Machado, Bellemare & Bowling 2017, "A Laplacian Framework for Option Discovery
  in Reinforcement Learning"): the proto-value functions are the eigenvectors of the normalised
  Laplacian ``L = I - D^{-1/2} W D^{-1/2}`` (the paper's and the authors' code's;
  ``laplacian="combinatorial"`` takes ``D - W``) of the smallest eigenvalues, the eigenvalue-0 one
  skipped. Each of the first ``k`` and its negation ``e`` define an eigenpurpose
  ``r(s, s') = e(s') - e(s)``; the eigenoption maximises it with a terminate action of value 0
  (:func:`eigenpurpose_values`: value iteration on the MDP's own transitions, discount 0.9 as in
  the authors' code) and terminates where no action has a positive value: its **sinks**. The
  reduction to subgoals (``sinks="extreme"``, the default) takes the sink(s) of largest ``e``:
  the state(s) where ``e`` is largest on the component. That state is always a sink: the
  discounted return of any path from ``s`` is a convex combination of the values of ``e`` along
  it minus ``e(s)``, so it is ``<= 0`` where ``e`` is largest; on a deterministic connected grid
  it is where every eigenoption started nearby ends. ``sinks="all"`` takes every sink (local
  maxima the discount makes not worth leaving, too).
* **Covering options** (Jinnai, Park, Abel & Konidaris 2019, "Discovering Options for Exploration
  by Minimizing Cover Time"): per round, the Fiedler vector (eigenvector of the second-smallest
  eigenvalue of the combinatorial Laplacian ``D - W``, as their code computes it) of the current
  graph; its argmin and argmax states are the two ends of an option (one each way), an edge joins
  them, and the next round works on the new graph. Subgoals: the union of the ends. A round whose
  ends are already neighbours adds no edge, so every later round would repeat it: the rounds stop.

Eigenvectors come from a dense :func:`numpy.linalg.eigh` below :data:`DENSE_BELOW` states and
otherwise from :func:`scipy.sparse.linalg.eigsh` in shift-invert mode around a small negative
shift (the eigenvalues nearest it are the smallest; the Laplacian is positive semi-definite). A
degenerate eigenspace (a square grid's horizontal and vertical modes) has no preferred basis, and a
solver returns any rotation of it, so its basis is made canonical (:func:`canonical_basis`): the
subgoals do not depend on the solver. Ties of a vector's extreme (within :data:`TIE_RTOL` of its
range) all count for eigenoptions; covering options take the lowest state id among them.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.sparse as sp
from scipy.sparse import csgraph
from scipy.sparse.linalg import eigsh
from threadpoolctl import threadpool_limits

from adpart.errors import TaskError
from adpart.mdp.model import FiniteMDP
from adpart.subgoals.literature import transition_graph
from adpart.subgoals.policy import check_mdp
from adpart.subgoals.settings import CoveringSettings, EigenoptionSettings, given

__all__ = [
    "DENSE_BELOW",
    "MIN_STATES",
    "Component",
    "CoveringOption",
    "Eigenoption",
    "canonical_basis",
    "covering_options",
    "covering_rounds",
    "eigenoptions",
    "eigenpurpose_values",
    "fiedler_vector",
    "laplacian",
    "laplacian_eigenpairs",
    "reachable_states",
    "spectral_components",
]

#: Components of fewer states are decomposed densely (``numpy.linalg.eigh``), larger ones by
#: ``scipy.sparse.linalg.eigsh`` in shift-invert mode.
DENSE_BELOW = 500
#: The smallest connected graph the spectral detectors work on.
MIN_STATES = 3
#: Eigenvalues closer than this times the spectrum's bound are one (degenerate) eigenspace.
DEGENERATE_RTOL = 1e-8
#: A vector's entries within this times its range of its maximum (minimum) are tied extremes.
TIE_RTOL = 1e-8
#: Seed of the fixed start vector of ``eigsh`` (the results never depend on it).
_V0_SEED = 20170306


@dataclass(frozen=True, eq=False)
class Component:
    """A connected component of the undirected reachable graph.

    Attributes:
        states: ``(n,)`` int64 state ids, ascending; local vertex ``i`` is state ``states[i]``.
        W: ``(n, n)`` symmetric 0/1 CSR adjacency, zero diagonal.
    """

    states: np.ndarray
    W: sp.csr_array

    @property
    def n(self) -> int:
        return int(self.states.size)


@dataclass(frozen=True, eq=False)
class Eigenoption:
    """One eigenoption: eigenvector ``index`` of its component with a ``sign``, reduced.

    Attributes:
        component: index of its component in :func:`spectral_components`' list.
        index: 1 for the eigenvector of the smallest non-zero eigenvalue, 2 for the next...
        sign: +1 for the eigenpurpose ``e(s') - e(s)``, -1 for its negation.
        eigenvalue: the Laplacian's eigenvalue of ``e``.
        sinks: every state where the option terminates (no action has a positive value).
        subgoals: the states the detector reports for it (the settings' ``sinks`` rule).
    """

    component: int
    index: int
    sign: int
    eigenvalue: float
    sinks: np.ndarray
    subgoals: np.ndarray

    def to_json(self) -> dict[str, object]:
        return {"component": self.component, "eigenvector": self.index,
                "sign": "+" if self.sign > 0 else "-", "eigenvalue": self.eigenvalue,
                "sinks": int(self.sinks.size), "subgoals": self.subgoals.tolist()}


@dataclass(frozen=True)
class CoveringOption:
    """One round of covering options: the Fiedler vector's argmin and argmax states.

    Attributes:
        component: index of its component in :func:`spectral_components`' list.
        round: 1-based round within the component.
        ends: ``(argmin, argmax)`` state ids; the option runs both ways between them.
        connectivity: the algebraic connectivity (second-smallest eigenvalue of ``D - W``) of
            the graph the round started from.
    """

    component: int
    round: int
    ends: tuple[int, int]
    connectivity: float

    @property
    def subgoals(self) -> np.ndarray:
        """The two ends, as the detector reports them."""
        return np.asarray(self.ends, dtype=np.int64)

    def to_json(self) -> dict[str, object]:
        return {"component": self.component, "round": self.round, "ends": list(self.ends),
                "connectivity": self.connectivity}


# --------------------------------------------------------------------------- the graph


def reachable_states(mdp: FiniteMDP, graph: sp.csr_array | None = None) -> np.ndarray:
    """``(S,)`` bool: the states a directed search from the support of ``mdp.initial`` reaches
    along the edges of :func:`transition_graph` (one breadth-first search from a virtual source
    joined to every start state)."""
    mdp = check_mdp(mdp)
    g = transition_graph(mdp) if graph is None else graph
    S = mdp.n_states
    starts = np.flatnonzero(mdp.initial > 0)
    coo = sp.coo_array(g)
    rows = np.concatenate([coo.row, np.full(starts.size, S)])
    cols = np.concatenate([coo.col, starts])
    G = sp.csr_array((np.ones(rows.size), (rows, cols)), shape=(S + 1, S + 1))
    order = csgraph.breadth_first_order(G, S, directed=True, return_predecessors=False)
    seen = np.zeros(S + 1, dtype=bool)
    seen[order] = True
    return seen[:S]


def spectral_components(mdp: FiniteMDP) -> list[Component]:
    """The connected components of the symmetrised transition graph of the reachable states,
    ordered by their lowest state id (each holds a start state)."""
    mdp = check_mdp(mdp)
    g = transition_graph(mdp)
    states = np.flatnonzero(reachable_states(mdp, g)).astype(np.int64)
    A = sp.csr_array(g[states][:, states])
    W = sp.csr_array(((A + A.T) > 0).astype(np.float64))
    _, labels = csgraph.connected_components(W, directed=False)
    first = np.full(labels.max() + 1, states.size)
    np.minimum.at(first, labels, np.arange(states.size))
    rank = np.argsort(np.argsort(first, kind="stable"), kind="stable")[labels]
    order = np.lexsort((np.arange(states.size), rank))
    bounds = np.concatenate([[0], np.cumsum(np.bincount(rank))])
    Wp = sp.csr_array(W[order][:, order])
    out = []
    for lo, hi in itertools.pairwise(bounds):
        block = sp.csr_array(Wp[lo:hi][:, lo:hi]) if hi - lo > 1 else sp.csr_array((1, 1))
        out.append(Component(states[order[lo:hi]], block))
    return out


def laplacian(W: sp.sparray, kind: str = "normalised") -> sp.csr_array:
    """``I - D^{-1/2} W D^{-1/2}`` (``normalised``; an isolated vertex gets a 1 on the diagonal)
    or ``D - W`` (``combinatorial``) of a symmetric adjacency ``W``."""
    W = sp.csr_array(W, dtype=np.float64)
    d = np.asarray(W.sum(axis=1)).ravel()
    if kind == "combinatorial":
        return sp.csr_array(sp.diags_array(d) - W)
    if kind != "normalised":
        raise TaskError(f"unknown Laplacian {kind!r}; give normalised or combinatorial")
    inv = np.zeros_like(d)
    inv[d > 0] = d[d > 0] ** -0.5
    Dm = sp.diags_array(inv)
    return sp.csr_array(sp.eye_array(W.shape[0]) - Dm @ W @ Dm)


def canonical_basis(B: np.ndarray, atol: float = 0.0) -> np.ndarray:
    """An orthonormal basis of ``span(B)`` that depends on the span only, not on ``B``.

    Greedily: the unit vector ``u_i`` whose projection on the remaining span is longest (the
    lowest ``i`` among those within ``atol`` of the longest), normalised projection of ``u_i``
    as the next basis vector, then the span orthogonal to it. Each vector's largest entry is
    positive, which also fixes the sign of a one-dimensional eigenspace.
    """
    Q = np.asarray(B, dtype=np.float64)
    out = []
    for _ in range(Q.shape[1]):
        norms = np.linalg.norm(Q, axis=1)
        i = int(np.flatnonzero(norms >= norms.max() - atol)[0])
        c = Q[i] / norms[i]
        out.append(Q @ c)
        if Q.shape[1] > 1:
            Q = Q @ scipy.linalg.null_space(c[None, :])
    return np.column_stack(out)


def _canonical_eigenspaces(vals: np.ndarray, vecs: np.ndarray, tol: float) -> np.ndarray:
    """``vecs`` with the basis of every run of eigenvalues closer than ``tol`` made canonical."""
    out = vecs.copy()
    start = 0
    for j in range(1, vals.size + 1):
        if j == vals.size or vals[j] - vals[j - 1] > tol:
            block = vecs[:, start:j]
            out[:, start:j] = canonical_basis(block, 1e-8 * float(np.abs(block).max()))
            start = j
    return out


def laplacian_eigenpairs(W: sp.sparray, m: int, *, kind: str = "normalised",
                         dense_below: int = DENSE_BELOW) -> tuple[np.ndarray, np.ndarray]:
    """The ``m`` smallest eigenvalues (ascending) of the Laplacian of ``W`` and unit eigenvectors
    ``(n, m)``, each degenerate eigenspace in its :func:`canonical_basis`.

    Dense ``eigh`` below ``dense_below`` vertices, else ``eigsh`` around the shift
    ``-1e-6 x`` the spectrum's bound, computing a few more pairs than asked until the ``m``-th
    eigenspace is complete.
    """
    L = laplacian(W, kind)
    n = L.shape[0]
    if not 1 <= m <= n:
        raise TaskError(f"asked for {m} eigenpairs of a graph of {n} vertices; give 1..{n}")
    degree = float(np.asarray(sp.csr_array(W).sum(axis=1)).max(initial=0.0))
    bound = 2.0 if kind == "normalised" else max(2.0 * degree, 1.0)
    tol = DEGENERATE_RTOL * bound
    if n < dense_below or m + 2 >= n:
        # one BLAS thread: at these sizes more threads only contend (measured 0.19 s against
        # 0.001 s at 104 states on a busy 2-core machine)
        with threadpool_limits(1, user_api="blas"):
            vals, vecs = np.linalg.eigh(L.toarray())
    else:
        v0 = np.random.default_rng(_V0_SEED).random(n) + 0.5
        count = min(n - 1, m + 4)
        while True:
            vals, vecs = eigsh(sp.csc_array(L), k=count, sigma=-1e-6 * bound, which="LM",
                               v0=v0)
            order = np.argsort(vals, kind="stable")
            vals, vecs = vals[order], vecs[:, order]
            if count == n - 1 or vals[-1] - vals[m - 1] > tol:
                break
            count = min(n - 1, 2 * count)
    # keep the eigenspaces the first m touch, whole (the m-th may continue past m)
    gaps = np.flatnonzero(np.diff(vals[m - 1:]) > tol)
    end = m + int(gaps[0]) if gaps.size else vals.size
    vecs = _canonical_eigenspaces(vals[:end], vecs[:, :end], tol)
    return vals[:m].copy(), vecs[:, :m].copy()


def fiedler_vector(W: sp.sparray, *, dense_below: int = DENSE_BELOW) -> tuple[float, np.ndarray]:
    """``(lambda_2, v)``: the algebraic connectivity of ``W`` (second-smallest eigenvalue of
    ``D - W``) and its eigenvector (the first canonical one when the eigenvalue is repeated)."""
    vals, vecs = laplacian_eigenpairs(W, 2, kind="combinatorial", dense_below=dense_below)
    return float(vals[1]), vecs[:, 1]


def _extremes(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Indices within :data:`TIE_RTOL` of the range of ``v``'s minimum and of its maximum."""
    span = float(v.max() - v.min())
    slack = TIE_RTOL * span
    return np.flatnonzero(v <= v.min() + slack), np.flatnonzero(v >= v.max() - slack)


# --------------------------------------------------------------------------- eigenoptions


def eigenpurpose_values(mdp: FiniteMDP, E: np.ndarray, discount: float) -> tuple[
    np.ndarray, np.ndarray, int
]:
    """Value iteration of the eigenpurposes ``r(s, s') = E[s', j] - E[s, j]`` with a terminate
    action of value 0, all columns at once on the MDP's transitions.

    ``V(s) = max(0, max_a sum_s' P(s' | s, a) (r(s, s') + discount V(s')))``, admissible actions
    only; a task's terminal states are ordinary states (the option is the environment's). Sweeps
    run until every column changes by at most ``1e-10 (1 - discount)`` times its range (the
    remaining error is then below ``1e-10`` of the range).

    Returns:
        ``(V, Qmax, sweeps)``: ``(S, m)`` values, ``(S, m)`` best action value (a state is a
        sink of column ``j`` where ``Qmax[s, j] <= 0``, up to a tolerance), the sweeps run.
    """
    mdp = check_mdp(mdp)
    S, A = mdp.n_states, mdp.n_actions
    E = np.asarray(E, dtype=np.float64).reshape(S, -1)
    P = mdp.P
    live = mdp.admissible.T.reshape(A * S)
    reward = P @ E - np.tile(E, (A, 1))  # rows a*S + s: sum_s' P(s'|s,a) (e(s') - e(s))
    span = np.maximum(E.max(axis=0) - E.min(axis=0), np.finfo(float).tiny)
    tol = 1e-10 * (1.0 - discount) * span
    cap = int(np.ceil(np.log(1e-10 * (1.0 - discount)) / np.log(discount))) + 10
    V = np.zeros_like(E)
    Qmax = np.zeros_like(E)
    sweeps = 0
    for sweeps in range(1, cap + 1):  # noqa: B007 - the count is returned
        Q = reward + discount * (P @ V)
        Q[~live] = -np.inf
        Qmax = Q.reshape(A, S, -1).max(axis=0)
        new = np.maximum(Qmax, 0.0)
        done = np.all(np.abs(new - V).max(axis=0) <= tol)
        V = new
        if done:
            break
    return V, Qmax, sweeps


def _largest_component(components: list[Component], method: str) -> int:
    n_max = max((c.n for c in components), default=0)
    if n_max < MIN_STATES:
        raise TaskError(
            f"{method} needs a connected transition graph of at least {MIN_STATES} states "
            f"reachable from the start distribution; the largest here has {n_max}. Use a task "
            "whose start states reach more of the environment")
    return n_max


def eigenoptions(mdp: FiniteMDP, settings: EigenoptionSettings | None = None) -> tuple[
    list[Eigenoption], dict[str, object]
]:
    """The eigenoptions of every component (module docstring), and figures of the run.

    ``settings.k`` eigenvectors per component (fewer on a component of ``k`` states or less),
    each with both signs; :class:`~adpart.subgoals.settings.EigenoptionSettings`, None for its
    defaults.
    """
    s = given(EigenoptionSettings, settings)
    mdp = check_mdp(mdp)
    components = spectral_components(mdp)
    n_max = _largest_component(components, "eigenoptions")
    if s.k > n_max - 1:
        raise TaskError(
            f"--k {s.k} asks for {s.k} non-constant eigenvectors, but the largest connected "
            f"component of the reachable states has {n_max} states and so {n_max - 1}; give --k "
            f"between 1 and {n_max - 1}")
    S = mdp.n_states
    columns, meta = [], []
    for ci, comp in enumerate(components):
        if comp.n < MIN_STATES:
            continue
        m = min(s.k, comp.n - 1)
        vals, vecs = laplacian_eigenpairs(comp.W, m + 1, kind=s.laplacian)
        for j in range(1, m + 1):
            for sign in (1, -1):
                col = np.zeros(S)
                col[comp.states] = sign * vecs[:, j]
                columns.append(col)
                meta.append((ci, j, sign, float(vals[j])))
    E = np.column_stack(columns)
    _, Qmax, sweeps = eigenpurpose_values(mdp, E, s.discount)
    out = []
    for col, (ci, j, sign, lam) in enumerate(meta):
        states = components[ci].states
        e = E[states, col]
        span = float(e.max() - e.min())
        sinks = states[Qmax[states, col] <= 1e-8 * span]
        top = states[_extremes(e)[1]]
        out.append(Eigenoption(ci, j, sign, lam, sinks, sinks if s.sinks == "all" else top))
    stats = {"states": int(sum(c.n for c in components)), "components": len(components),
             "sweeps": sweeps}
    return out, stats


# --------------------------------------------------------------------------- covering options


def covering_rounds(W: sp.sparray, rounds: int, *, dense_below: int = DENSE_BELOW) -> list[
    tuple[int, int, float]
]:
    """Jinnai et al.'s rounds on a connected symmetric adjacency ``W``: ``(argmin, argmax,
    lambda_2)`` of each round's Fiedler vector (vertex ids of ``W``; the lowest id among tied
    extremes), each round on the graph with the earlier rounds' edges added. Stops early when the
    two ends are already neighbours (the graph would not change)."""
    G = sp.csr_array(W, dtype=np.float64)
    out = []
    for _ in range(rounds):
        lam, v = fiedler_vector(G, dense_below=dense_below)
        lo, hi = _extremes(v)
        i, j = int(lo[0]), int(hi[0])
        if G[i, j] != 0:
            break
        out.append((i, j, lam))
        G = sp.csr_array(G + sp.coo_array(([1.0, 1.0], ([i, j], [j, i])), shape=G.shape))
        G.data[:] = 1.0
    return out


def covering_options(mdp: FiniteMDP, settings: CoveringSettings | None = None) -> tuple[
    list[CoveringOption], dict[str, object]
]:
    """The covering options of every component (module docstring), and figures of the run.

    ``settings.rounds`` rounds per component of at least 3 states
    (:class:`~adpart.subgoals.settings.CoveringSettings`, None for its defaults).
    """
    s = given(CoveringSettings, settings)
    mdp = check_mdp(mdp)
    components = spectral_components(mdp)
    _largest_component(components, "covering options")
    out = []
    for ci, comp in enumerate(components):
        if comp.n < MIN_STATES:
            continue
        for r, (i, j, lam) in enumerate(covering_rounds(comp.W, s.rounds), start=1):
            out.append(CoveringOption(ci, r, (int(comp.states[i]), int(comp.states[j])), lam))
    stats = {"states": int(sum(c.n for c in components)), "components": len(components)}
    return out, stats

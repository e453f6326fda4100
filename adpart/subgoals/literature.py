"""Policy-independent subgoal scores from the literature, for comparison with the count metric.

* Betweenness centrality of the transition graph (Simsek & Barto 2008): edge ``s -> s'`` when some
  admissible action reaches ``s' != s`` with positive probability; subgoals are its local maxima
  (:func:`local_maxima`, the paper's rule) or its ``k`` highest states. Computed with Brandes'
  algorithm, vectorised over a chunk of sources at once: breadth-first distances from
  :func:`scipy.sparse.csgraph.shortest_path`, then shortest-path counts forward and dependencies
  backward one distance layer at a time, each layer one sparse-times-dense product. (networkx is
  not a dependency of adpart and runs Brandes in pure Python, one source at a time.)
* Visit frequency on successful random walks (Digney 1996; McGovern & Barto 2001): walks with
  uniformly random admissible actions from uniform non-terminal starts; a walk is successful when
  it arrives at a terminal state within the horizon; a state's score is the fraction of successful
  walks that arrive at it at least once (terminal states excluded).

The detectors' settings are :class:`~adpart.subgoals.settings.BetweennessSettings` and
:class:`~adpart.subgoals.settings.VisitFrequencySettings`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from adpart.errors import TaskError
from adpart.mdp.model import FiniteMDP
from adpart.subgoals.montecarlo import sample_trajectories
from adpart.subgoals.policy import check_mdp
from adpart.subgoals.settings import VisitFrequencySettings, given


def transition_graph(mdp: FiniteMDP) -> sp.csr_array:
    """``(S, S)`` 0/1 CSR: ``s -> s'`` when an admissible action moves ``s`` to ``s' != s``."""
    mdp = check_mdp(mdp)
    S = mdp.n_states
    P = mdp.P.tocoo()
    s, a = P.row % S, P.row // S
    keep = (P.data > 0) & mdp.admissible[s, a] & (s != P.col)
    g = sp.csr_array((np.ones(int(keep.sum())), (s[keep], P.col[keep])), shape=(S, S))
    g.sum_duplicates()
    g.data[:] = 1.0
    return g


def betweenness(graph: sp.csr_array, *, sources: np.ndarray | None = None,
                chunk: int = 256) -> np.ndarray:
    """Directed betweenness ``sum_{s != v != t} sigma_st(v) / sigma_st`` of every node.

    Args:
        graph: ``(S, S)`` adjacency (nonzero = edge), unweighted.
        sources: the source nodes to sum over (default all: exact; a random subset gives the
            sampled estimate of Brandes & Pich 2007 up to the factor ``S / len(sources)``).
        chunk: sources processed together (memory ``~ 4 * chunk * S`` floats).
    """
    A = sp.csr_array(graph, dtype=np.float64)
    A.data[:] = 1.0
    S = A.shape[0]
    AT = sp.csr_array(A.T)
    src_all = np.arange(S) if sources is None else np.asarray(sources, dtype=np.int64)
    bc = np.zeros(S)
    for lo in range(0, src_all.size, max(1, int(chunk))):
        src = src_all[lo:lo + chunk]
        D = np.atleast_2d(csgraph.shortest_path(A, unweighted=True, indices=src))
        D[~np.isfinite(D)] = -1
        depth = int(D.max())
        sigma = np.zeros_like(D)
        sigma[np.arange(src.size), src] = 1.0
        for d in range(1, depth + 1):
            frontier = np.where(D == d - 1, sigma, 0.0)
            sigma += np.where(D == d, (AT @ frontier.T).T, 0.0)
        delta = np.zeros_like(D)
        for d in range(depth - 1, -1, -1):
            safe = np.where(sigma > 0, sigma, 1.0)
            coef = np.where(D == d + 1, (1.0 + delta) / safe, 0.0)
            delta += np.where(D == d, sigma * (A @ coef.T).T, 0.0)
        delta[np.arange(src.size), src] = 0.0
        bc += delta.sum(axis=0)
    return bc


def visit_frequency(mdp: FiniteMDP, rng: np.random.Generator,
                    settings: VisitFrequencySettings | None = None) -> tuple[np.ndarray, int]:
    """Fraction of successful random walks arriving at each state, and the number of successes.

    ``settings.walks`` walks of at most ``settings.horizon`` steps (0: ``10 |S|``) each
    (:class:`~adpart.subgoals.settings.VisitFrequencySettings`; None: its defaults).
    """
    s = given(VisitFrequencySettings, settings)
    mdp = check_mdp(mdp)
    S = mdp.n_states
    if not mdp.terminal.any():
        raise TaskError(
            "visit-frequency needs a task with a terminal (goal) state: a walk is successful "
            "when it arrives at one"
        )
    uniform = mdp.admissible / mdp.admissible.sum(axis=1, keepdims=True)
    H = s.horizon or 10 * S
    traj = sample_trajectories(mdp, uniform, s.walks, rng, H)
    last = traj.paths[np.arange(traj.n), traj.lengths - 1]
    ok = ~traj.truncated & mdp.terminal[last] & (traj.lengths > 1)
    good = traj.paths[ok, 1:]
    rows = np.broadcast_to(np.arange(good.shape[0])[:, None], good.shape)
    seen = good >= 0
    pairs = np.unique(rows[seen] * S + good[seen])
    freq = np.bincount(pairs % S, minlength=S).astype(np.float64)
    n_ok = int(ok.sum())
    freq = freq / max(n_ok, 1)
    freq[mdp.terminal] = 0.0
    return freq, n_ok


def local_maxima(graph: sp.csr_array, scores: np.ndarray) -> np.ndarray:
    """States scoring strictly higher than every neighbour (either edge direction), score > 0.

    Şimşek & Barto (2008) take the local maxima of betweenness as subgoals: a state is a
    bottleneck when it is more central than the states around it, wherever it ranks globally.
    """
    S = graph.shape[0]
    coo = sp.coo_array(graph)
    u = np.concatenate([coo.row, coo.col]).astype(np.int64)
    v = np.concatenate([coo.col, coo.row]).astype(np.int64)
    off = u != v
    best_neighbour = np.full(S, -np.inf)
    np.maximum.at(best_neighbour, u[off], scores[v[off]])
    return np.flatnonzero((scores > best_neighbour) & (scores > 0)).astype(np.int64)


def top_states(scores: np.ndarray, k: int) -> np.ndarray:
    """The ``k`` highest-scoring states (ties to the lower id), among positive scores."""
    order = np.lexsort((np.arange(scores.size), -scores))[:k]
    return np.sort(order[scores[order] > 0]).astype(np.int64)

"""Gradient ratios along trajectories and the t-test threshold (section 4.1.1, eq. 4.2).

Along a path ``s_0, s_1, ...`` the slope of the count is ``Delta(s_t) = C*(s_t) - C*(s_{t-1})``
and a state's gradient ratio is ``Delta(s_t) / max(1, Delta(s_{t+1}))``, computed where
``Delta(s_t) > 0``. Interpretation (DESIGN.md): the path is the sampled trajectory with
self-loop steps removed (a self-loop does not move along the path), ratios exist at interior
positions only (``s_{t-1}`` and ``s_{t+1}`` both exist: the last state of an episode, the goal,
has no ratio and is left to reward variation, section 4.3.1). The normalised form of footnote 1,
``Delta-hat(s_t) / max(1/|S|, Delta-hat(s_{t+1}))``, is the same number (both sides scale by
``|S|``), so only the standard form is computed.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import scipy.sparse as sp

from adpart.errors import TaskError
from adpart.subgoals._walkers import path_ratio_sums
from adpart.subgoals.montecarlo import Trajectories


@dataclass(frozen=True, eq=False)
class RatioSamples:
    """Gradient ratio samples, one per (trajectory, interior position) with ``Delta(s_t) > 0``.

    Attributes:
        states: ``(K,)`` int64 the state ``s_t`` of each sample.
        ratios: ``(K,)`` float64 ``Delta(s_t) / max(1, Delta(s_{t+1}))``.
        next_delta: ``(K,)`` float64 ``Delta(s_{t+1})`` (theorem 4.3 raises the threshold by
            ``2 eps / max(1, Delta(s_{t+1}))``).
    """

    states: np.ndarray
    ratios: np.ndarray
    next_delta: np.ndarray

    @property
    def n(self) -> int:
        return int(self.ratios.size)

    def per_state_max(self, n_states: int, values: np.ndarray | None = None) -> np.ndarray:
        """``(S,)`` the largest of ``values`` (default the ratios) at each state, 0 where none."""
        out = np.zeros(n_states)
        np.maximum.at(out, self.states, self.ratios if values is None else values)
        return out

    def samples_per_state(self, n_states: int) -> np.ndarray:
        return np.bincount(self.states, minlength=n_states)

    def summary(self) -> tuple[float, float]:
        """Mean and sample standard deviation of all ratios (the nu, sigma of eq. 4.2)."""
        if self.n < 2:
            raise TaskError(
                f"only {self.n} gradient ratio(s) were sampled; the t-test needs at least 2. "
                "Sample more trajectories (the policy may end episodes in one step)"
            )
        return float(self.ratios.mean()), float(self.ratios.std(ddof=1))


def interior_triples(traj: Trajectories) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(prev, cur, nxt)``: every interior position ``s_{t-1}, s_t, s_{t+1}`` of the paths.

    Self-loop repeats are dropped first (the path does not move). The triples depend only on
    the paths, so a caller that re-scores the same paths under changing counts (the Monte Carlo
    detector, once per batch) computes them once.
    """
    p = traj.paths
    keep = p >= 0
    keep[:, 1:] &= p[:, 1:] != p[:, :-1]
    flat = p[keep]
    row = np.broadcast_to(np.arange(p.shape[0])[:, None], p.shape)[keep]
    if flat.size < 3:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, empty
    interior = row[:-2] == row[2:]
    return flat[:-2][interior], flat[1:-1][interior], flat[2:][interior]


def gradient_ratios(
    counts: np.ndarray, traj: Trajectories | tuple[np.ndarray, np.ndarray, np.ndarray]
) -> RatioSamples:
    """All gradient ratio samples of ``counts`` along the sampled trajectories (vectorised).

    ``traj`` is the :class:`Trajectories` or their :func:`interior_triples`.
    """
    prev, cur, nxt = interior_triples(traj) if isinstance(traj, Trajectories) else traj
    c = np.asarray(counts, dtype=np.float64)
    d_t = c[cur] - c[prev]
    d_next = c[nxt] - c[cur]
    pos = d_t > 0
    return RatioSamples(
        cur[pos].astype(np.int64), d_t[pos] / np.maximum(1.0, d_next[pos]), d_next[pos]
    )


def check_level(p: float) -> float:
    if isinstance(p, bool) or not isinstance(p, (int, float, np.floating)) or not 0.0 < p < 1.0:
        raise TaskError(f"level p = {p!r} must be in (0, 1), e.g. 0.025 (section 4.1.1.1)")
    return float(p)


@lru_cache(maxsize=256)
def _t_quantile(q: float, dof: int) -> float:
    from scipy import stats  # ~0.4 s to import; only detection needs it

    return float(stats.t.ppf(q, dof))


def t_test_threshold(mean: float, sd: float, n: int, p: float) -> float:
    """The sample mean ``rho`` a state needs to pass the one-sided t-test of eq. 4.2 at level p.

    ``mu = nu + t_{1-p, N-1} * sigma / sqrt(N)`` with ``N`` the ratio samples per state. The
    detectors' level is :class:`~adpart.subgoals.settings.CountSettings`' ``p``.
    """
    p = check_level(p)
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 2:
        raise TaskError(f"samples per state N = {n!r} must be an integer >= 2 for a t-test")
    if not (np.isfinite(mean) and np.isfinite(sd) and sd >= 0):
        raise TaskError(f"ratio mean {mean!r} and sd {sd!r} must be finite, sd >= 0")
    return float(mean + _t_quantile(1.0 - p, int(n) - 1) * sd / np.sqrt(int(n)))


def samples_per_state(samples: RatioSamples, n_states: int) -> int:
    """The ``N`` of eq. 4.2 chosen automatically: mean ratio samples per state that has any.

    Rounded, at least 2. (Interpretation: the seed's figures - mu = 1.8 from nu = 0.43,
    sigma = 0.57; mu = 35 from 5.427, 18.09; mu = 30 from 8.839, 20.12 - imply N of 3 to 6,
    the number of ratio samples a state sees over a handful of trajectories.)
    """
    per = samples.samples_per_state(n_states)
    seen = per[per > 0]
    return max(2, round(float(seen.mean()))) if seen.size else 2


#: ``N`` of eq. 4.2 when the ratios are taken over every path (``ratios="all"``, a choice; the
#: default ``"paths"`` keeps the automatic :func:`samples_per_state`): the seed's figures imply
#: N of 3 to 6 (two-rooms, Fig. 4.2: 3; section 5.1.4's exhaustive three-floor: 6; its Monte
#: Carlo run: 4-5; the 20,000-state urban task of 5.1.5 needs about 30), and the automatic rule
#: of :func:`samples_per_state` chose 4 on two-rooms, three-floor and three-floor-arm for most
#: ratio-path seeds. A constant, because over every path there is no sample whose per-state
#: size could set it.
ALL_PATHS_N = 4


@dataclass(frozen=True, eq=False)
class PathRatios:
    """Gradient ratios over **every** path of the count's walker, weighted by its likelihood.

    The exhaustive reading of section 4.1.1.1: the distribution of gradient ratios over the
    entire space is that of all interior positions ``(s_{t-1}, s_t, s_{t+1})`` of the paths
    eq. 4.1 sums over (the walker ``P_pi^0``: uniform start, no self-loop step, ending at a
    terminal state), each weighted by its accumulated likelihood (definition 4.2) - the limit of
    the ratio samples of ever more sampled paths - and "at least one path through s along which
    the gradient ratio is >= mu" is decided over all of them.

    Attributes:
        scores: ``(S,)`` the largest ratio of any path through each state, 0 where none has
            ``Delta(s_t) > 0`` and a successor: ``(C(s) - min C(s_{t-1})) /
            max(1, min C(s_{t+1}) - C(s))`` over the walker's predecessors and successors.
        next_delta: ``(S,)`` ``Delta(s_{t+1})`` of that path (``min C(s_{t+1}) - C(s)``).
        mean: ``nu``, the likelihood-weighted mean ratio.
        sd: ``sigma``, its standard deviation.
        weight: expected number of ratio positions on one walker path.
        n_triples: distinct ``(s_{t-1}, s_t, s_{t+1})`` with ``Delta(s_t) > 0``.
    """

    scores: np.ndarray
    next_delta: np.ndarray
    mean: float
    sd: float
    weight: float
    n_triples: int

    def summary(self) -> tuple[float, float]:
        """``(nu, sigma)`` of eq. 4.2; at least two ratio triples are needed."""
        if self.n_triples < 2 or not self.weight > 0:
            raise TaskError(
                f"the policy's paths have only {self.n_triples} gradient ratio(s); the t-test "
                "needs at least 2 (the policy may end episodes in one step)"
            )
        return self.mean, self.sd


class PathStructure:
    """The walker's edges, grouped by source and by target, for :meth:`ratios` under any counts.

    The edges do not change while the counts do (the Monte Carlo detector re-scores after every
    batch), so they are sorted once; each :meth:`ratios` call is one compiled ``O(nnz)`` pass
    (:func:`adpart.subgoals._walkers.path_ratio_sums`).
    """

    def __init__(self, walker: sp.sparray) -> None:
        W = sp.csr_array(walker)
        W.sort_indices()
        self.n_states = S = W.shape[0]
        self.out_ptr = W.indptr.astype(np.int64)
        self.out_dst = W.indices.astype(np.int64)
        self.out_w = np.asarray(W.data, dtype=np.float64)
        src = np.repeat(np.arange(S, dtype=np.int64), np.diff(self.out_ptr))
        order = np.argsort(self.out_dst, kind="stable")
        self.in_src = src[order]
        self.in_w = self.out_w[order]
        self.in_ptr = np.zeros(S + 1, dtype=np.int64)
        np.cumsum(np.bincount(self.out_dst, minlength=S), out=self.in_ptr[1:])

    def ratios(self, counts: np.ndarray) -> PathRatios:
        """:class:`PathRatios` of the standard counts ``counts`` (``C*`` or ``C_H``)."""
        S = self.n_states
        c = np.ascontiguousarray(counts, dtype=np.float64)
        scores, next_delta = np.empty(S), np.empty(S)
        t0, t1, t2, n_triples = path_ratio_sums(c, self.in_ptr, self.in_src, self.in_w,
                                                self.out_ptr, self.out_dst, self.out_w, scores,
                                                next_delta)
        if t0 > 0:
            mean = t1 / t0
            var = max(t2 / t0 - mean * mean, 0.0)
        else:
            mean, var = 0.0, 0.0
        return PathRatios(scores, next_delta, float(mean), float(np.sqrt(var)), t0 / S,
                          int(n_triples))


def path_ratios(walker: sp.sparray, counts: np.ndarray) -> PathRatios:
    """:class:`PathRatios` of ``counts`` over every path of ``walker`` (``P_pi^0``)."""
    return PathStructure(walker).ratios(counts)

"""Compiled walkers for the Monte Carlo count metric (definition 4.4) and the ratio paths.

Also :func:`reach_backwards`, the search behind ``trapped_states``. The two walkers both draw
from the caller's ``numpy.random.Generator`` (numba advances the same bit generator, so a seed
gives the same draws as numpy would):

* :func:`walk_paths` records whole trajectories. It consumes the generator exactly as the
  vectorised numpy walker did (time step by time step; per step first one action uniform per
  running walker for a stochastic policy, then one successor uniform per running walker, walkers
  in index order), so the ratio paths of a seed are the same as before the walker was compiled.
* :func:`expected_arrivals` adds up each trajectory's expected arrivals given its path (the
  Monte Carlo count's default estimator, lower variance than counting the arrivals drawn);
* :func:`count_arrivals` only adds up arrivals, one trajectory after another, and stops a
  trajectory at its first self-loop step: later arrivals do not count (eq. 4.1 sums over paths
  without self-loops), so walking on would spend random numbers and time on nothing.

Successors are drawn as in :meth:`adpart.mdp.model.FiniteMDP.sample_next`: the first entry of
row ``a*S + s`` whose row-offset cumulative probability (``FiniteMDP.sampler_keys``) exceeds
``a*S + s + u``, clipped to the row's last entry.
"""

from __future__ import annotations

import numba
import numpy as np

from adpart.mdp._sampling import successor


@numba.njit(cache=True, nogil=True)
def _action(s, u, actions, cdf, stochastic):  # pragma: no cover - compiled
    """The policy's action in ``s``: a lookup, or the ``u``-th quantile of its distribution.

    The stochastic rule is ``sample_actions``'s: the number of cumulative probabilities
    ``<= u * total``, at most ``A - 1``.
    """
    if not stochastic:
        return actions[s]
    A = cdf.shape[1]
    x = u * cdf[s, A - 1]
    a = 0
    for b in range(A):
        if x >= cdf[s, b]:
            a += 1
    return min(a, A - 1)


@numba.njit(cache=True, nogil=True)
def walk_paths(keys, indptr, indices, terminal, actions, cdf, stochastic, start, horizon,
               gen):  # pragma: no cover - compiled
    """Trajectories from ``start`` for at most ``horizon`` steps, time step by time step.

    Returns ``(columns, truncated)``: ``columns`` is ``(T + 1, n)`` with the states at each time
    (-1 once a walker has stopped), ``truncated`` marks walkers still running after ``horizon``.
    """
    n = start.shape[0]
    S = terminal.shape[0]
    state = start.copy()
    running = np.empty(n, dtype=np.int64)
    m = 0
    for i in range(n):
        if not terminal[state[i]]:
            running[m] = i
            m += 1
    cap = 64
    cols = np.full((cap, n), -1, dtype=np.int64)
    cols[0, :] = state
    act = np.empty(n, dtype=np.int64)
    t = 0
    while t < horizon and m > 0:
        for j in range(m):
            s = state[running[j]]
            act[j] = _action(s, gen.random() if stochastic else 0.0, actions, cdf, stochastic)
        if t + 2 > cap:
            grown = np.full((2 * cap, n), -1, dtype=np.int64)
            grown[:cap] = cols
            cols = grown
            cap *= 2
        kept = 0
        for j in range(m):
            i = running[j]
            s2 = successor(act[j] * S + state[i], gen.random(), keys, indptr, indices)
            state[i] = s2
            cols[t + 1, i] = s2
            if not terminal[s2]:
                running[kept] = i
                kept += 1
        m = kept
        t += 1
    truncated = np.zeros(n, dtype=np.bool_)
    for j in range(m):
        truncated[running[j]] = True
    return cols[: t + 1], truncated


@numba.njit(cache=True, nogil=True)
def count_arrivals(keys, indptr, indices, terminal, actions, cdf, stochastic, start, horizon,
                   gen, arrivals):  # pragma: no cover - compiled
    """Add each trajectory's arrivals before its first self-loop step to ``arrivals``.

    Returns the number of trajectories the horizon cut while they were still counting.
    """
    S = terminal.shape[0]
    cut = 0
    for i in range(start.shape[0]):
        s = start[i]
        if terminal[s]:
            continue
        t = 0
        while True:
            if t == horizon:
                cut += 1
                break
            a = _action(s, gen.random() if stochastic else 0.0, actions, cdf, stochastic)
            s2 = successor(a * S + s, gen.random(), keys, indptr, indices)
            if s2 == s:
                break
            arrivals[s2] += 1.0
            if terminal[s2]:
                break
            s = s2
            t += 1
    return cut


@numba.njit(cache=True, nogil=True)
def expected_arrivals(data, indptr, indices, terminal, actions, cdf, stochastic, start, horizon,
                      gen, arrivals):  # pragma: no cover - compiled
    """Add each trajectory's *accumulated likelihoods* of arrival (definition 4.4) to ``arrivals``.

    At each step in ``s`` (action ``a``) the expected arrivals ``w * P(s' | s, a)`` go to every
    successor ``s' != s`` at once, instead of 1 to the one successor drawn; the walk then moves
    to a successor drawn from ``P(. | s, a)`` without the self-loop, and the weight ``w`` (the
    probability that the walker has not self-looped yet, started at 1) is multiplied by
    ``1 - P(s | s, a)``. Each step's contribution is the conditional expectation of the plain
    count's given the path so far, so the estimator is unbiased for ``C*`` of eq. 4.1 (self-loop
    steps end a walker's count there) with a smaller variance: on deterministic dynamics it is
    the plain count; with slip only the branching of the sampled path is left to chance.

    Returns the number of trajectories the horizon cut while they were still counting.
    """
    S = terminal.shape[0]
    cut = 0
    for i in range(start.shape[0]):
        s = start[i]
        if terminal[s]:
            continue
        w = 1.0
        t = 0
        while True:
            if t == horizon:
                cut += 1
                break
            a = _action(s, gen.random() if stochastic else 0.0, actions, cdf, stochastic)
            row = a * S + s
            p_self = 0.0
            for k in range(indptr[row], indptr[row + 1]):
                s2 = indices[k]
                if s2 == s:
                    p_self += data[k]
                else:
                    arrivals[s2] += w * data[k]
            move = 1.0 - p_self
            if move <= 1e-15:
                break
            x = gen.random() * move
            nxt = -1
            acc = 0.0
            for k in range(indptr[row], indptr[row + 1]):
                s2 = indices[k]
                if s2 == s:
                    continue
                nxt = s2
                acc += data[k]
                if x < acc:
                    break
            w *= move
            if nxt < 0 or terminal[nxt]:
                break
            s = nxt
            t += 1
    return cut


@numba.njit(cache=True, nogil=True)
def reach_backwards(indptr, indices, reached):  # pragma: no cover - compiled
    """Mark every state with a path into a marked one (breadth-first from all marked at once).

    ``indptr``/``indices`` list, for each state ``j``, the states with an edge into ``j`` (the
    CSC form of the walker matrix); ``reached`` is updated in place.
    """
    queue = np.flatnonzero(reached)
    order = np.empty(reached.shape[0], dtype=np.int64)
    order[: queue.shape[0]] = queue
    head = 0
    tail = queue.shape[0]
    while head < tail:
        j = order[head]
        head += 1
        for k in range(indptr[j], indptr[j + 1]):
            i = indices[k]
            if not reached[i]:
                reached[i] = True
                order[tail] = i
                tail += 1


@numba.njit(cache=True, nogil=True)
def path_ratio_sums(counts, in_ptr, in_src, in_w, out_ptr, out_dst, out_w, scores,
                    next_delta):  # pragma: no cover - compiled
    """One pass over the walker's edges for :meth:`adpart.subgoals.ratios.PathStructure.ratios`.

    For each state ``s`` (in-edges ``in_ptr[s]:in_ptr[s+1]`` of ``in_src``/``in_w``, out-edges
    ``out_ptr[s]:out_ptr[s+1]`` of ``out_dst``/``out_w``): the in-sums ``A_k = sum w (1 + C(u))
    Delta^k`` over predecessors ``u`` with ``Delta = C(s) - C(u) > 0``, the out-sums ``B_k = sum
    P(v | s) / max(1, C(v) - C(s))^k``; every triple's weight is a product of the two, so the
    weighted moments are ``sum_s A_k B_k``. Writes ``scores`` (largest ratio, 0 where none) and
    ``next_delta`` in place; returns ``(sum A0 B0, sum A1 B1, sum A2 B2, number of triples)``.
    """
    S = counts.shape[0]
    t0 = 0.0
    t1 = 0.0
    t2 = 0.0
    n_triples = 0
    for s in range(S):
        c = counts[s]
        a0 = 0.0
        a1 = 0.0
        a2 = 0.0
        a_max = 0.0
        n_up = 0
        for k in range(in_ptr[s], in_ptr[s + 1]):
            u = in_src[k]
            a = c - counts[u]
            if a > 0:
                w = (1.0 + counts[u]) * in_w[k]
                a0 += w
                a1 += w * a
                a2 += w * a * a
                a_max = max(a_max, a)
                n_up += 1
        scores[s] = 0.0
        next_delta[s] = 0.0
        n_out = out_ptr[s + 1] - out_ptr[s]
        if n_up == 0 or n_out == 0:
            continue
        b0 = 0.0
        b1 = 0.0
        b2 = 0.0
        min_next = np.inf
        for k in range(out_ptr[s], out_ptr[s + 1]):
            v = out_dst[k]
            b = 1.0 / max(1.0, counts[v] - c)
            w = out_w[k]
            b0 += w
            b1 += w * b
            b2 += w * b * b
            min_next = min(min_next, counts[v])
        t0 += a0 * b0
        t1 += a1 * b1
        t2 += a2 * b2
        n_triples += n_up * n_out
        nd = min_next - c
        next_delta[s] = nd
        scores[s] = a_max / max(1.0, nd)
    return t0, t1, t2, n_triples

"""The draws every compiled sampler shares (learners and subgoal walkers).

``first_above(values, x, lo, hi)`` is the first position in ``values[lo:hi]`` (sorted) whose
value exceeds ``x`` (``hi`` when none does): numpy's ``searchsorted(side="right")``; the
learners draw start states with it. ``successor(row, u, keys, indptr, indices)`` is the CSR
position search of
:meth:`adpart.mdp.model.FiniteMDP.sample_next` for one ``(row = a*S + s, u)``: the first entry of
the row whose row-offset cumulative probability (``FiniteMDP.sampler_keys``) exceeds ``row + u``,
clipped to the row's last entry; it returns that entry's successor state.
``epsilon_greedy(u_explore, u_pick, epsilon, first, second, admissible)`` is the certainty-
equivalent learners' action choice at one state: with probability ``epsilon`` a uniform pick
among the admissible actions, else a uniform pick among those tied for the largest
``max(first[b], second[b])`` (pass one row twice for a single table); -1 when no action is
admissible. All are compiled with numba (a dependency), callable from compiled kernels and from
the interpreted reference kernels alike (integer and comparison logic only, so the two agree
exactly).
"""

from __future__ import annotations

import math

import numba

#: ``numba.njit`` for helpers the compiled kernels call.
compiled = numba.njit(cache=True, nogil=True)


@compiled
def first_above(values, x, lo, hi):  # pragma: no cover - compiled
    left = lo
    right = hi
    while left < right:
        mid = (left + right) >> 1
        if values[mid] <= x:
            left = mid + 1
        else:
            right = mid
    return left


@compiled
def successor(row, u, keys, indptr, indices):  # pragma: no cover - compiled
    hi = indptr[row + 1]
    return indices[min(first_above(keys, row + u, indptr[row], hi), hi - 1)]


@compiled
def epsilon_greedy(u_explore, u_pick, epsilon, first, second, admissible):  # pragma: no cover
    m = 0
    for b in range(admissible.size):
        if admissible[b]:
            m += 1
    if m == 0:
        return -1
    if u_explore < epsilon:
        pick = int(u_pick * m)
        for b in range(admissible.size):
            if admissible[b]:
                if pick == 0:
                    return b
                pick -= 1
        return -1
    best = -math.inf
    ties = 0
    for b in range(admissible.size):
        if admissible[b]:
            g = max(first[b], second[b])
            if g > best:
                best = g
                ties = 1
            elif g == best:
                ties += 1
    pick = int(u_pick * ties)
    for b in range(admissible.size):
        if admissible[b] and max(first[b], second[b]) == best:
            if pick == 0:
                return b
            pick -= 1
    return -1

"""The successor draw every compiled sampler shares (learners and subgoal walkers).

``successor(row, u, keys, indptr, indices)`` is the CSR position search of
:meth:`adpart.mdp.model.FiniteMDP.sample_next` for one ``(row = a*S + s, u)``: the first entry of
the row whose row-offset cumulative probability (``FiniteMDP.sampler_keys``) exceeds ``row + u``,
clipped to the row's last entry; it returns that entry's successor state. With numba it is
compiled (and callable from compiled kernels); without, it is the same plain function.
"""

from __future__ import annotations


def _successor(row, u, keys, indptr, indices):  # pragma: no cover - compiled when numba imports
    x = row + u
    lo = indptr[row]
    hi = indptr[row + 1]
    left = lo
    right = hi
    while left < right:  # first position in the row with keys > x
        mid = (left + right) >> 1
        if keys[mid] <= x:
            left = mid + 1
        else:
            right = mid
    return indices[min(left, hi - 1)]


try:
    import numba
except ImportError:  # pragma: no cover - numba is a dependency; kept for a bare interpreter
    successor = _successor
else:
    successor = numba.njit(cache=True, nogil=True)(_successor)

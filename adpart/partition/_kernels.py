"""numba kernels of the partition refiners: greedy interval cuts and the exact-lumping worklist.

Both are sequential by nature (a greedy cut depends on where the previous group started; a worklist
pops one splitter at a time), so they are compiled rather than vectorised. They receive validated
arrays only; the public functions in :mod:`adpart.partition.refine` and
:mod:`adpart.partition.lumping` check every input first.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def greedy_groups(segment: np.ndarray, values: np.ndarray, width: float) -> np.ndarray:
    """Group ids for values sorted by ``(segment, value)``: a new group starts whenever the
    segment changes or the value exceeds the current group's first value by more than ``width``.

    This is DESIGN.md's delta-splitting rule: within one block and one criterion, sorting the masses
    and cutting greedily yields the fewest sub-blocks whose spans are all ``<= width``.
    """
    n = values.size
    out = np.empty(n, dtype=np.int64)
    if n == 0:
        return out
    g = 0
    start = values[0]
    out[0] = 0
    for i in range(1, n):
        if segment[i] != segment[i - 1] or values[i] - start > width:
            g += 1
            start = values[i]
        out[i] = g
    return out


@njit(cache=True)
def lump(n, n_act, pred_ptr, pred_row, pred_val, init_labels, n_init, tol):
    """Coarsest exact lumping of ``n`` states under ``n_act`` matched actions (worklist refinement).

    A Valmari-Franceschinis style splitter worklist for weighted transition systems with action
    labels: popping a splitter block ``C``, the mass ``w(s, a) = sum_{t in C} F(t | s, a)`` is
    accumulated over the *predecessors* of ``C`` only, and every block holding a touched state is
    split by ``w(., a)`` (untouched states have mass 0), action after action. New blocks join the
    worklist; when a block that was not waiting is split, its largest part is left out, because
    stability with respect to it follows from the parent and the other parts
    (``w(s, largest) = w(s, parent) - sum of the others``). Each state is thus re-scanned
    ``O(log n)`` times and the whole run costs ``O(m log n)`` for ``m`` transitions.

    Args:
        n, n_act: number of states and of actions.
        pred_ptr, pred_row, pred_val: CSR of the transposed model: for a target ``t``, entries
            ``pred_ptr[t]:pred_ptr[t+1]`` hold rows ``a*n + s`` and masses ``F(t | s, a) > 0``.
        init_labels: ``(n,)`` int64 initial blocks ``0..n_init-1``.
        tol: masses within ``tol`` of a group's first (sorted) mass are equal; masses ``<= tol``
            count as zero.

    Returns:
        ``(labels, n_blocks)``.
    """
    # refinable partition: elems ordered by block, pos[s] index of s in elems
    elems = np.argsort(init_labels, kind="mergesort").astype(np.int64)
    pos = np.empty(n, dtype=np.int64)
    for i in range(n):
        pos[elems[i]] = i
    blk = init_labels.copy()
    bstart = np.zeros(n + 1, dtype=np.int64)
    bend = np.zeros(n + 1, dtype=np.int64)
    counts = np.zeros(n_init, dtype=np.int64)
    for i in range(n):
        counts[init_labels[i]] += 1
    acc = 0
    for b in range(n_init):
        bstart[b] = acc
        acc += counts[b]
        bend[b] = acc
    nb = n_init

    inwl = np.zeros(n + 1, dtype=np.bool_)
    wl = np.empty(n + 1, dtype=np.int64)
    top = 0
    for b in range(n_init):
        wl[top] = b
        top += 1
        inwl[b] = True

    w = np.zeros(n_act * n, dtype=np.float64)
    marked = np.zeros(n_act * n, dtype=np.bool_)
    touched = np.empty(n_act * n, dtype=np.int64)
    bmark = np.zeros(n + 1, dtype=np.int64)
    tblocks = np.empty(n + 1, dtype=np.int64)
    gstart = np.empty(n + 1, dtype=np.int64)

    while top > 0:
        top -= 1
        c = wl[top]
        inwl[c] = False
        nt = 0
        for i in range(bstart[c], bend[c]):
            t = elems[i]
            for k in range(pred_ptr[t], pred_ptr[t + 1]):
                r = pred_row[k]
                if not marked[r]:
                    marked[r] = True
                    touched[nt] = r
                    nt += 1
                w[r] += pred_val[k]
        for a in range(n_act):
            base = a * n
            ntb = 0
            for i in range(nt):
                r = touched[i]
                if r < base or r >= base + n or w[r] <= tol:
                    continue
                s = r - base
                b = blk[s]
                if bmark[b] == 0:
                    tblocks[ntb] = b
                    ntb += 1
                p = pos[s]
                q = bstart[b] + bmark[b]
                u = elems[q]
                elems[q] = s
                pos[s] = q
                elems[p] = u
                pos[u] = p
                bmark[b] += 1
            for ib in range(ntb):
                b = tblocks[ib]
                m = bmark[b]
                bmark[b] = 0
                lo = bstart[b]
                size = bend[b] - lo
                keys = np.empty(m, dtype=np.float64)
                for i in range(m):
                    keys[i] = w[base + elems[lo + i]]
                if m == size and keys.max() - keys.min() <= tol:
                    continue
                order = np.argsort(keys)
                moved = elems[lo:lo + m].copy()
                for i in range(m):
                    s = moved[order[i]]
                    elems[lo + i] = s
                    pos[s] = lo + i
                    keys[i] = w[base + s]
                # greedy groups over the sorted touched region
                ng = 1
                gstart[0] = lo
                first = keys[0]
                for i in range(1, m):
                    if keys[i] - first > tol:
                        gstart[ng] = lo + i
                        ng += 1
                        first = keys[i]
                gstart[ng] = lo + m
                # the zero group (untouched states) is [lo + m, bend[b]) and keeps id b if non-empty
                if m < size:
                    n_new = ng
                    kept_lo, kept_hi = lo + m, bend[b]
                else:
                    n_new = ng - 1
                    kept_lo, kept_hi = gstart[ng - 1], lo + m
                was_waiting = inwl[b]
                largest = b
                largest_size = kept_hi - kept_lo
                first_new = nb
                for g in range(n_new):
                    nbid = nb
                    nb += 1
                    bstart[nbid] = gstart[g]
                    bend[nbid] = gstart[g + 1]
                    for i in range(gstart[g], gstart[g + 1]):
                        blk[elems[i]] = nbid
                    if gstart[g + 1] - gstart[g] > largest_size:
                        largest_size = gstart[g + 1] - gstart[g]
                        largest = nbid
                bstart[b] = kept_lo
                bend[b] = kept_hi
                for nbid in range(first_new, nb):
                    if was_waiting or nbid != largest:
                        wl[top] = nbid
                        top += 1
                        inwl[nbid] = True
                if not was_waiting and largest != b:
                    wl[top] = b
                    top += 1
                    inwl[b] = True
        for i in range(nt):
            r = touched[i]
            w[r] = 0.0
            marked[r] = False
    return blk, nb

"""The delta worklist as it was before its rewrite for issue 22, kept as a test oracle.

A verbatim copy of the earlier compiled kernel's body, run as plain Python (small inputs only):
the rewritten kernel in :mod:`adpart.partition._kernels` must return the same labels on every
input, since it pops the same splitters and makes the same cuts in the same order.
"""

from __future__ import annotations

import numpy as np

from adpart.partition._kernels import _heap_pop, _heap_push, move_to, refinable_partition


def delta_worklist_reference(n, n_act, pred_ptr, pred_row, pred_val, init_labels, n_init,
                             width, max_pops):
    """delta-refinement to a fixpoint with a splitter worklist (eq. 4.6, DESIGN.md's split rule).

    The shape of :func:`lump`, with the greedy delta cut instead of exact equality: popping a
    splitter block ``C``, the masses ``w(s, a) = sum_{t in C} F(t | s, a)`` are accumulated over
    the predecessors of ``C`` only; then, option after option, every block ``B`` holding a
    predecessor is checked on the one criterion ``(a, C)``: its states' masses (0 for the
    untouched ones) are sorted and, if their span exceeds ``width``, cut greedily - a new group
    whenever a mass exceeds the group's first by more than ``width`` (the fewest sub-blocks for
    that criterion). Blocks without a predecessor in ``C`` have span 0 and are never looked at.

    Why this reaches a delta-stable fixpoint: a sub-block of a block that was stable for a
    criterion stays stable for it (a subset's span is at most the set's), so stability can be lost
    only with respect to a *target* that changed - and every block that is split is pushed back as
    a splitter, *all* its parts (with delta > 0 the "all but the largest" shortcut of exact
    lumping is unsound: spans do not subtract). The run ends when the worklist is empty: every
    block then was popped after its last change, and every block was checked against it since.

    To keep the cut region of a block contiguous, touched states are moved to the *end* of their
    block's slice: the untouched states (mass 0) and the touched ones whose mass is within
    ``width`` of 0 then form the first group, which keeps the block's id.

    Args:
        n, n_act: states and stacked options.
        pred_ptr, pred_row, pred_val: CSR of the transposed model (rows ``a*n + s``).
        init_labels: ``(n,)`` int64 initial blocks ``0..n_init-1``.
        width: ``delta + atol``.
        max_pops: give up after this many splitters (returns ``pops = -1``); ``<= 0``: no cap.

    Returns:
        ``(labels, n_blocks, pops)``.
    """
    elems, pos, blk, bstart, bend = refinable_partition(n, init_labels, n_init)
    nb = n_init

    # the worklist: a min-heap on block size (a block is in it at most once: <= n entries)
    inwl = np.zeros(n + 1, dtype=np.bool_)
    hkey = np.empty(n + 1, dtype=np.int64)
    hval = np.empty(n + 1, dtype=np.int64)
    hsize = 0
    for b in range(n_init):
        hsize = _heap_push(hkey, hval, hsize, bend[b] - bstart[b], b)
        inwl[b] = True

    w = np.zeros(n_act * n, dtype=np.float64)
    marked = np.zeros(n_act * n, dtype=np.bool_)
    touched = np.empty(n_act * n, dtype=np.int64)
    bmark = np.zeros(n + 1, dtype=np.int64)
    tblocks = np.empty(n + 1, dtype=np.int64)
    gstart = np.empty(n + 2, dtype=np.int64)
    bya = np.empty(n_act * n, dtype=np.int64)  # touched rows bucketed by option
    aptr = np.zeros(n_act + 1, dtype=np.int64)
    pops = 0

    while hsize > 0:
        if max_pops > 0 and pops >= max_pops:
            return blk, nb, -1
        c, hsize = _heap_pop(hkey, hval, hsize)  # the smallest waiting splitter first
        inwl[c] = False
        pops += 1
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
        # counting sort of the touched rows by option: each option's pass reads only its rows
        aptr[:] = 0
        for i in range(nt):
            aptr[touched[i] // n + 1] += 1
        for a in range(n_act):
            aptr[a + 1] += aptr[a]
        fill = aptr[:n_act].copy()
        for i in range(nt):
            a = touched[i] // n
            bya[fill[a]] = touched[i]
            fill[a] += 1
        for a in range(n_act):
            base = a * n
            ntb = 0
            for i in range(aptr[a], aptr[a + 1]):
                r = bya[i]
                if w[r] <= 0.0:
                    continue
                s = r - base
                b = blk[s]
                if bmark[b] == 0:
                    tblocks[ntb] = b
                    ntb += 1
                # move s to the end of its block's slice (touched states fill it from the back)
                move_to(elems, pos, s, bend[b] - 1 - bmark[b])
                bmark[b] += 1
            for ib in range(ntb):
                b = tblocks[ib]
                m = bmark[b]
                bmark[b] = 0
                lo = bstart[b]
                hi = bend[b]
                size = hi - lo
                t0 = hi - m  # touched states occupy [t0, hi)
                keys = np.empty(m, dtype=np.float64)
                for i in range(m):
                    keys[i] = w[base + elems[t0 + i]]
                kmin = keys.min() if m == size else 0.0
                if keys.max() - kmin <= width:
                    continue  # span within delta: stable for this criterion
                order = np.argsort(keys, kind="mergesort")
                moved = elems[t0:hi].copy()
                for i in range(m):
                    s = moved[order[i]]
                    elems[t0 + i] = s
                    pos[s] = t0 + i
                    keys[i] = w[base + s]
                # greedy groups over [lo, hi): untouched states (mass 0) come first
                ng = 1
                gstart[0] = lo
                first = kmin
                for i in range(m):
                    if keys[i] - first > width:
                        gstart[ng] = t0 + i
                        ng += 1
                        first = keys[i]
                gstart[ng] = hi
                # group 0 keeps id b; the others get new ids; every part is a new splitter
                for g in range(1, ng):
                    nbid = nb
                    nb += 1
                    bstart[nbid] = gstart[g]
                    bend[nbid] = gstart[g + 1]
                    for i in range(gstart[g], gstart[g + 1]):
                        blk[elems[i]] = nbid
                    hsize = _heap_push(hkey, hval, hsize, gstart[g + 1] - gstart[g], nbid)
                    inwl[nbid] = True
                bend[b] = gstart[1]
                if not inwl[b]:
                    hsize = _heap_push(hkey, hval, hsize, gstart[1] - lo, b)
                    inwl[b] = True
        for i in range(nt):
            r = touched[i]
            w[r] = 0.0
            marked[r] = False
    return blk, nb, pops

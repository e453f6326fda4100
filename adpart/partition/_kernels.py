"""numba kernels of the partition refiners: greedy interval cuts, the exact-lumping worklist, the
delta worklist and the predecessor lists both read (with the two plain functions that size them).

They are sequential by nature (a greedy cut depends on where the previous group started; a worklist
pops one splitter at a time; a transpose scatters), so they are compiled rather than vectorised.
They receive validated arrays only; the public functions in :mod:`adpart.partition.refine` and
:mod:`adpart.partition.lumping` check every input first.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def first_seen_labels(flat, n_labels):  # pragma: no cover - compiled
    """Relabel ``flat`` (ints in ``0..n_labels-1``) ``0, 1, ...`` in the order each label is
    first seen: the canonical form of a partition (one pass, no sort)."""
    rank = np.full(n_labels, -1, dtype=np.int64)
    out = np.empty(flat.size, dtype=np.int64)
    nxt = 0
    for i in range(flat.size):
        r = rank[flat[i]]
        if r < 0:
            r = nxt
            rank[flat[i]] = r
            nxt += 1
        out[i] = r
    return out


@njit(cache=True, inline="always")
def short_way(d, n):  # pragma: no cover - compiled
    """``d = s - t`` taken the shorter way round the ``n`` state indices: ``d`` or ``d -+ n``,
    whichever lies in ``[-(n // 2), n // 2]`` (a predecessor across a grid's wrapped edge - a
    cylinder's or a torus's - is then as near as one inside it)."""
    half = n // 2
    if d > half:
        return d - n
    if d < -half:
        return d + n
    return d


@njit(cache=True, inline="always")
def add_masses(lo, hi, off, val, t, ring, w, marked, touched, nt):  # pragma: no cover - compiled
    """``w[s] += val[k]`` over the entries ``lo <= k < hi`` of one predecessor list of target
    ``t``, where ``s = t + off[k]``, taken mod ``ring`` when the lists wrap round (``ring = n``,
    else 0: :func:`predecessor_fill`); a state touched for the first time is marked and appended
    to ``touched`` (first-touch order). Returns the new number of touched states."""
    for k in range(lo, hi):
        s = t + off[k]
        if ring:  # the same every entry: compiled as two loops, one without the test
            if s < 0:
                s += ring
            elif s >= ring:
                s -= ring
        if not marked[s]:
            marked[s] = True
            touched[nt] = s
            nt += 1
        w[s] += val[k]
    return nt


@njit(cache=True, inline="always")
def take_splitter(c, elems, bstart, bend, pred_start, splitter, cursor
                  ):  # pragma: no cover - compiled
    """Copy block ``c``'s members into ``splitter`` (every option then sees the block that was
    popped, though an earlier option's cut may split it) and point each member's ``cursor`` at
    its first predecessor entry (option 0's list). Returns the number of members."""
    nc = bend[c] - bstart[c]
    for i in range(nc):
        t = elems[bstart[c] + i]
        splitter[i] = t
        cursor[i] = pred_start[t]
    return nc


@njit(cache=True, inline="always")
def splitter_masses(ring, nc, n_act, splitter, cursor, pred_len, pred_off, pred_val, w, marked,
                    touched, a):  # pragma: no cover - compiled
    """The splitter step of both worklists: ``w(s) = sum_{t in C} F(t | s, a)`` for option ``a``
    over the predecessors of the popped block ``C`` (its ``nc`` members in ``splitter``), member
    after member; the options are taken in increasing order, each member's ``cursor`` advancing
    over its lists. Returns the number of touched states (first-touch order in ``touched``)."""
    nt = 0
    for i in range(nc):
        t = splitter[i]
        lo = cursor[i]
        hi = lo + pred_len[t * n_act + a]
        cursor[i] = hi
        nt = add_masses(lo, hi, pred_off, pred_val, t, ring, w, marked, touched, nt)
    return nt


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
def refinable_partition(n, init_labels, n_init):  # pragma: no cover - compiled
    """The refinable partition both refiners start from (Paige-Tarjan's representation).

    ``elems`` lists the states block by block (stable within a block), ``pos[s]`` is the index of
    ``s`` in ``elems``, ``blk`` the block of each state, and block ``b`` is
    ``elems[bstart[b]:bend[b]]`` (arrays sized ``n + 1``: blocks never outnumber states).
    ``elems`` is the stable order of ``init_labels`` (a stable argsort's), built by one counting
    sort: the labels are ``0..n_init-1``, and numba's merge sort took most of a one-block
    refinement's time. Every array has the int type of ``init_labels`` (int32 below 2^31 states
    halves them).
    """
    blk = init_labels.copy()
    bstart = np.zeros(n + 1, dtype=init_labels.dtype)
    bend = np.zeros(n + 1, dtype=init_labels.dtype)
    for i in range(n):
        bend[init_labels[i]] += 1
    acc = 0
    for b in range(n_init):
        bstart[b] = acc
        acc += bend[b]
        bend[b] = bstart[b]  # the fill cursor until every state is placed
    elems = np.empty(n, dtype=init_labels.dtype)
    pos = np.empty(n, dtype=init_labels.dtype)
    for i in range(n):
        q = bend[init_labels[i]]
        elems[q] = i
        pos[i] = q
        bend[init_labels[i]] = q + 1
    return elems, pos, blk, bstart, bend


@njit(cache=True)
def move_to(elems, pos, s, q):  # pragma: no cover - compiled
    """Swap state ``s`` into slot ``q`` of the refinable partition (its occupant takes ``s``'s)."""
    p = pos[s]
    u = elems[q]
    elems[q] = s
    pos[s] = q
    elems[p] = u
    pos[u] = p


@njit(cache=True)
def lump(n, n_act, pred_start, pred_len, pred_off, pred_val, pred_ring, init_labels, n_init,
         tol):
    """Coarsest exact lumping of ``n`` states under ``n_act`` matched actions (worklist refinement).

    A Valmari-Franceschinis style splitter worklist for weighted transition systems with action
    labels: popping a splitter block ``C``, then action after action, the mass
    ``w(s) = sum_{t in C} F(t | s, a)`` is accumulated over the *predecessors* of ``C`` under
    ``a`` only, and every block holding a touched state is split by ``w`` (untouched states have
    mass 0). New blocks join the worklist; when a block that was not waiting is split, its largest
    part is left out, because stability with respect to it follows from the parent and the other
    parts (``w(s, largest) = w(s, parent) - sum of the others``). Each state is thus re-scanned
    ``O(log n)`` times and the whole run costs ``O(m log n)`` for ``m`` transitions.

    ``C``'s members are copied when it is popped, so every action sees the ``C`` that was popped
    (an earlier action's cut may split it); each state's mass sums the same terms in the same
    order (``C``'s members in turn) as one pass over all actions at once would, and the touched
    states of one action come in the same first-touch order, so the cuts are those of that pass,
    with one mass slot per state instead of one per (state, action).

    Args:
        n, n_act: number of states and of actions.
        pred_start, pred_len, pred_off, pred_val, pred_ring: predecessor lists from
            :func:`predecessors_of_rows`.
        init_labels: ``(n,)`` initial blocks ``0..n_init-1`` (int32 or int64: the int type of
            the state and block arrays).
        tol: masses within ``tol`` of a group's first (sorted) mass are equal; masses ``<= tol``
            count as zero.

    Returns:
        ``(labels, n_blocks)``.
    """
    # refinable partition: elems ordered by block, pos[s] index of s in elems
    elems, pos, blk, bstart, bend = refinable_partition(n, init_labels, n_init)
    nb = n_init

    idx = init_labels.dtype
    inwl = np.zeros(n + 1, dtype=np.bool_)
    wl = np.empty(n + 1, dtype=idx)
    top = 0
    for b in range(n_init):
        wl[top] = b
        top += 1
        inwl[b] = True

    w = np.zeros(n, dtype=np.float64)
    marked = np.zeros(n, dtype=np.bool_)
    touched = np.empty(n, dtype=idx)
    splitter = np.empty(n, dtype=idx)
    cursor = np.empty(n, dtype=pred_start.dtype)
    bmark = np.zeros(n + 1, dtype=idx)
    tblocks = np.empty(n + 1, dtype=idx)
    gstart = np.empty(n + 1, dtype=idx)

    while top > 0:
        top -= 1
        c = wl[top]
        inwl[c] = False
        nc = take_splitter(c, elems, bstart, bend, pred_start, splitter, cursor)
        for a in range(n_act):
            nt = splitter_masses(pred_ring, nc, n_act, splitter, cursor, pred_len, pred_off,
                                 pred_val, w, marked, touched, a)
            ntb = 0
            for i in range(nt):
                s = touched[i]
                if w[s] <= tol:
                    continue
                b = blk[s]
                if bmark[b] == 0:
                    tblocks[ntb] = b
                    ntb += 1
                move_to(elems, pos, s, bstart[b] + bmark[b])
                bmark[b] += 1
            for ib in range(ntb):
                b = tblocks[ib]
                m = bmark[b]
                bmark[b] = 0
                lo = bstart[b]
                size = bend[b] - lo
                keys = np.empty(m, dtype=np.float64)
                for i in range(m):
                    keys[i] = w[elems[lo + i]]
                if m == size and keys.max() - keys.min() <= tol:
                    continue
                order = np.argsort(keys)
                moved = elems[lo:lo + m].copy()
                for i in range(m):
                    s = moved[order[i]]
                    elems[lo + i] = s
                    pos[s] = lo + i
                    keys[i] = w[s]
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
                s = touched[i]
                w[s] = 0.0
                marked[s] = False
    return blk, nb


@njit(cache=True)
def _heap_push(hkey, hval, size, key, val):
    """Push ``(key, val)`` on the binary min-heap ``hkey/hval`` of ``size`` entries."""
    i = size
    hkey[i] = key
    hval[i] = val
    while i > 0:
        parent = (i - 1) // 2
        if hkey[parent] < hkey[i] or (hkey[parent] == hkey[i] and hval[parent] <= hval[i]):
            break
        hkey[parent], hkey[i] = hkey[i], hkey[parent]
        hval[parent], hval[i] = hval[i], hval[parent]
        i = parent
    return size + 1


@njit(cache=True)
def _heap_pop(hkey, hval, size):
    """Pop the smallest ``(key, val)`` (ties: smallest val); returns ``(val, new size)``."""
    top = hval[0]
    size -= 1
    hkey[0] = hkey[size]
    hval[0] = hval[size]
    i = 0
    while True:
        left = 2 * i + 1
        if left >= size:
            break
        child = left
        right = left + 1
        if right < size and (hkey[right] < hkey[left]
                             or (hkey[right] == hkey[left] and hval[right] < hval[left])):
            child = right
        if hkey[i] < hkey[child] or (hkey[i] == hkey[child] and hval[i] <= hval[child]):
            break
        hkey[i], hkey[child] = hkey[child], hkey[i]
        hval[i], hval[child] = hval[child], hval[i]
        i = child
    return top, size


@njit(cache=True)
def predecessor_counts(n, indptr, indices, data, options, states, keep
                       ):  # pragma: no cover - compiled
    """Pass 1 of the predecessor lists (:func:`predecessor_fill`): where each target's entries
    start, how far a predecessor lies from its target, and the longest list.

    The rows read are those :func:`predecessor_fill` scatters: option ``options[j]``'s row of the
    ``i``-th of ``states`` where ``keep[i, j]``, exact zeros skipped.

    Returns:
        ``(start, far, longest, wraps)``: ``(n + 1,)`` int64 ``start``, ``start[t]`` the first
        entry of target ``t`` and ``start[n]`` the number of entries; ``far`` the largest
        ``|short_way(s - t, n)|`` over the entries, ``longest`` the most entries of one
        (target, option) list (0 if none), and whether some offset is the way round
        (``short_way(s - t, n) != s - t``).
    """
    k = options.size
    start = np.zeros(n + 1, dtype=np.int64)
    count = np.zeros(n, dtype=np.int64)
    far = 0
    longest = 0
    wraps = False
    for j in range(k):
        base = options[j] * n
        for i in range(states.size):
            if keep[i, j]:
                s = states[i]
                r = base + s
                for q in range(indptr[r], indptr[r + 1]):
                    if data[q] != 0.0:
                        t = indices[q]
                        count[t] += 1
                        d = short_way(s - t, n)
                        far = max(far, d if d >= 0 else -d)
                        wraps |= d != s - t
        for t in range(n):
            start[t + 1] += count[t]
            longest = max(longest, count[t])
            count[t] = 0
    for t in range(n):
        start[t + 1] += start[t]
    return start, far, longest, wraps


@njit(cache=True)
def predecessor_fill(n, indptr, indices, data, options, states, keep, start, length, off, val
                     ):  # pragma: no cover - compiled
    """Pass 2: the predecessor lists of the selected rows, one per (target, option), in place.

    The stacked matrix is ``F`` (``(O*n, n)`` CSR of every option); the ``j``-th option of the
    lists is ``options[j]``, and its row for the ``i``-th of ``states`` (sorted, distinct) is
    ``F[options[j]*n + states[i]]`` where ``keep[i, j]``, empty elsewhere - the masked rows
    (zero where an option is not admissible: eq. 4.6 compares admissible options only), read
    straight from the model without forming them.

    Target ``t``'s entries are ``start[t]:start[t + 1]`` of ``off`` / ``val``, option after
    option, ``length[t*k + j]`` of them for the ``j``-th: the states ``s`` with
    ``F(t | s, options[j]) > 0`` in increasing ``s``, stored as ``off = short_way(s - t, n)``
    (``s = (t + off) mod n``), and those masses (exact zeros are dropped, as ``eliminate_zeros``
    would). This is the transpose of the masked rows (column ``t``'s entries in row order, which
    groups them by option), scattered in one pass over the rows; ``start`` is
    :func:`predecessor_counts`'s. ``length`` (``(n*k,)``), ``off`` and ``val`` (``(start[n],)``)
    are allocated by the caller, which picks their dtypes: a list's length fits a byte or two
    where a head pointer per list would take four or eight, an offset needs fewer bytes than a
    state when predecessors lie near their targets, the shorter way round (a grid's do, a
    cylinder's too), and ``val`` holds the masses in the order the worklists read them.
    """
    k = options.size
    fill = start[:n].copy()
    begun = start[:n].copy()
    for j in range(k):
        base = options[j] * n
        for i in range(states.size):
            if keep[i, j]:
                s = states[i]
                r = base + s
                for q in range(indptr[r], indptr[r + 1]):
                    x = data[q]
                    if x != 0.0:
                        t = indices[q]
                        f = fill[t]
                        off[f] = short_way(s - t, n)
                        val[f] = x
                        fill[t] = f + 1
        for t in range(n):
            length[t * k + j] = fill[t] - begun[t]
            begun[t] = fill[t]


def index_labels(labels: np.ndarray) -> np.ndarray:
    """A copy of ``labels`` in the int type the worklists index states and blocks with: int32
    below 2^31 - 1 states (their arrays then take half the bytes), int64 beyond."""
    return labels.astype(np.int32 if labels.size < 2**31 - 1 else np.int64)


def offset_dtype(far: int) -> type:
    """The narrowest signed int of 16, 32 or 64 bits holding every offset ``|off| <= far``."""
    for dtype in (np.int16, np.int32):
        if far <= np.iinfo(dtype).max:
            return dtype
    return np.int64


def length_dtype(longest: int) -> type:
    """The narrowest of uint8, uint16 and int64 holding every list length ``<= longest``."""
    for dtype in (np.uint8, np.uint16):
        if longest <= np.iinfo(dtype).max:
            return dtype
    return np.int64


def predecessors_of_rows(n, indptr, indices, data, options, states, keep, off_dtype=None):
    """The predecessor lists ``(start, length, off, val, ring)`` of :func:`predecessor_fill` (two
    compiled passes): ``ring = n`` when some offset is the way round (a state is then
    ``(t + off) mod n``), else 0 (``t + off``, and the worklists skip the test).

    ``start`` is int32 when the entries number fewer than 2^31 (int64 otherwise), ``length``
    has :func:`length_dtype` of the longest list and ``off`` :func:`offset_dtype` of the farthest
    predecessor unless ``off_dtype`` is given (wide enough); ``val`` is float64.
    Beside them only pass 1's ``(n + 1,)`` starts remain: on the 10^6-state rooms grid with 20
    options the lists take 10 bytes per entry (an int16 offset and the mass) and one byte per
    (target, option), against the model's 12 per entry (an int32 column and the mass) and four
    per row.
    """
    options = np.ascontiguousarray(options, dtype=np.int64)
    states = np.ascontiguousarray(states, dtype=np.int64)
    data = np.asarray(data, dtype=np.float64)
    start, far, longest, wraps = predecessor_counts(n, indptr, indices, data, options, states,
                                                    keep)
    m = int(start[n])
    if m < 2**31:
        start = start.astype(np.int32)
    length = np.empty(n * options.size, dtype=length_dtype(int(longest)))
    off = np.empty(m, dtype=offset_dtype(int(far)) if off_dtype is None else off_dtype)
    val = np.empty(m, dtype=np.float64)
    predecessor_fill(n, indptr, indices, data, options, states, keep, start, length, off, val)
    return start, length, off, val, n if wraps else 0


def predecessors_by_option(n, n_act, indptr, indices, data, off_dtype=None):
    """:func:`predecessors_of_rows` of every row of the stacked ``(n_act*n, n)`` CSR ``F``:
    target ``t``'s entries from ``start[t]`` on are its lists for options ``0, 1, ...``,
    ``length[t*n_act + a]`` entries for option ``a``: the states ``(t + off) mod n`` with
    ``F(t | s, a) > 0``, increasing, and those masses; last ``ring``."""
    keep = np.broadcast_to(np.True_, (n, n_act))  # every row kept, no (n, n_act) mask stored
    return predecessors_of_rows(n, indptr, indices, data, np.arange(n_act), np.arange(n), keep,
                                off_dtype)


@njit(cache=True)
def _stable_sort_by_key(keys, items, lo, hi):  # pragma: no cover - compiled
    """Sort ``keys[lo:hi]`` ascending and permute ``items[lo:hi]`` alike; stable.

    Insertion sort below 32 entries (no allocation), else a stable argsort of the slice; either
    way the permutation is that of ``np.argsort(keys[lo:hi], kind="mergesort")``.
    """
    m = hi - lo
    if m <= 32:
        for i in range(lo + 1, hi):
            k = keys[i]
            x = items[i]
            j = i - 1
            while j >= lo and keys[j] > k:
                keys[j + 1] = keys[j]
                items[j + 1] = items[j]
                j -= 1
            keys[j + 1] = k
            items[j + 1] = x
        return
    order = np.argsort(keys[lo:hi], kind="mergesort")
    k_sorted = keys[lo:hi][order]
    i_sorted = items[lo:hi][order]
    keys[lo:hi] = k_sorted
    items[lo:hi] = i_sorted


@njit(cache=True)
def delta_worklist(n, n_act, pred_start, pred_len, pred_off, pred_val, pred_ring, init_labels,
                   n_init, width, max_pops):  # pragma: no cover - compiled
    """delta-refinement to a fixpoint with a splitter worklist (eq. 4.6, DESIGN.md's split rule).

    The shape of :func:`lump`, with the greedy delta cut instead of exact equality: popping a
    splitter block ``C``, then option after option, the masses ``w(s) = sum_{t in C} F(t | s, a)``
    are accumulated over the predecessors of ``C`` under ``a`` only, and every block ``B`` holding
    one is checked on the one criterion ``(a, C)``: its states' masses (0 for the untouched ones)
    are sorted and, if their span exceeds ``width``, cut greedily - a new group whenever a mass
    exceeds the group's first by more than ``width`` (the fewest sub-blocks for that criterion).
    Blocks without a predecessor in ``C`` have span 0 and are never looked at, nor are blocks of
    one state (they cannot be split).

    Why this reaches a delta-stable fixpoint: a sub-block of a block that was stable for a
    criterion stays stable for it (a subset's span is at most the set's), so stability can be lost
    only with respect to a *target* that changed - and every block that is split is pushed back as
    a splitter, *all* its parts (with delta > 0 the "all but the largest" shortcut of exact
    lumping is unsound: spans do not subtract). The run ends when the worklist is empty: every
    block then was popped after its last change, and every block was checked against it since.

    To keep the cut region of a block contiguous, touched states are moved to the *end* of their
    block's slice: the untouched states (mass 0) and the touched ones whose mass is within
    ``width`` of 0 then form the first group, which keeps the block's id.

    ``C``'s members are copied when it is popped (it may itself be split by an earlier option's
    cut), so every option sees the ``C`` that was popped. The work per pop is proportional to the
    predecessor entries of ``C`` plus the sorts of the touched blocks; the mass array has one slot
    per state (not per state and option), so it stays in cache far longer on large models.

    Args:
        n, n_act: states and stacked options.
        pred_start, pred_len, pred_off, pred_val, pred_ring: predecessor lists from
            :func:`predecessors_of_rows`.
        init_labels: ``(n,)`` initial blocks ``0..n_init-1`` (int32 or int64: the int type of
            the state and block arrays).
        width: ``delta + atol``.
        max_pops: give up after this many splitters (returns ``pops = -1``); ``<= 0``: no cap.

    Returns:
        ``(labels, n_blocks, pops)``.
    """
    elems, pos, blk, bstart, bend = refinable_partition(n, init_labels, n_init)
    nb = n_init

    # the worklist: a min-heap on block size (a block is in it at most once: <= n entries)
    idx = init_labels.dtype
    inwl = np.zeros(n + 1, dtype=np.bool_)
    hkey = np.empty(n + 1, dtype=idx)
    hval = np.empty(n + 1, dtype=idx)
    hsize = 0
    for b in range(n_init):
        hsize = _heap_push(hkey, hval, hsize, bend[b] - bstart[b], b)
        inwl[b] = True

    w = np.zeros(n, dtype=np.float64)
    marked = np.zeros(n, dtype=np.bool_)
    touched = np.empty(n, dtype=idx)
    splitter = np.empty(n, dtype=idx)
    cursor = np.empty(n, dtype=pred_start.dtype)
    keys = np.empty(n, dtype=np.float64)
    bmark = np.zeros(n + 1, dtype=idx)
    tblocks = np.empty(n + 1, dtype=idx)
    gstart = np.empty(n + 2, dtype=idx)
    pops = 0

    while hsize > 0:
        if max_pops > 0 and pops >= max_pops:
            return blk, nb, -1
        c, hsize = _heap_pop(hkey, hval, hsize)  # the smallest waiting splitter first
        inwl[c] = False
        pops += 1
        nc = take_splitter(c, elems, bstart, bend, pred_start, splitter, cursor)
        for a in range(n_act):
            # masses into C under option a, first-touch order
            nt = splitter_masses(pred_ring, nc, n_act, splitter, cursor, pred_len, pred_off,
                                 pred_val, w, marked, touched, a)
            ntb = 0
            for i in range(nt):
                s = touched[i]
                if w[s] <= 0.0:
                    continue
                b = blk[s]
                if bend[b] - bstart[b] == 1:
                    continue  # a single state is stable for every criterion
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
                kmax = -np.inf
                kmin = np.inf
                for i in range(t0, hi):
                    x = w[elems[i]]
                    keys[i] = x
                    kmax = max(kmax, x)
                    kmin = min(kmin, x)
                if m < size:
                    kmin = 0.0
                if kmax - kmin <= width:
                    continue  # span within delta: stable for this criterion
                _stable_sort_by_key(keys, elems, t0, hi)
                for i in range(t0, hi):
                    pos[elems[i]] = i
                # greedy groups over [lo, hi): untouched states (mass 0) come first
                ng = 1
                gstart[0] = lo
                first = kmin
                for i in range(t0, hi):
                    if keys[i] - first > width:
                        gstart[ng] = i
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
                s = touched[i]
                w[s] = 0.0
                marked[s] = False
    return blk, nb, pops

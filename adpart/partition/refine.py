"""Refinement to delta-stability (eq. 4.6) and epsilon reward homogeneity (eq. 4.7).

Definition 4.4 asks, for every pair of blocks ``B_i, B_j``, every option ``o`` and all
``s, s' in B_i``::

    | sum_{s'' in B_j} F(s''|s,o) - sum_{s'' in B_j} F(s''|s',o) | <= delta      (4.6)
    | R(s,o) - R(s',o) | <= epsilon                                             (4.7)

With ``delta > 0`` "the maximal delta-stable sub-block" of section 4.2.1.1 is not unique (the
relation is not transitive), so adpart commits to DESIGN.md's rule: a block is split on *one*
criterion at a time - one ``(option, target block)`` mass, or one option's reward - by sorting its
states' values and cutting greedily whenever the span from the current group's first value would
exceed the threshold (the fewest sub-blocks for that criterion); this repeats to a fixpoint.
With ``delta = epsilon = 0`` every cut separates states that any exact lumping must separate, so
the fixpoint is the unique coarsest exact lumping (stochastic bisimulation), and :func:`refine`
computes it with :mod:`adpart.partition.lumping`.

Rewards only shrink blocks, never make them unstable again, so eq. 4.7 is enforced first (one
greedy pass per option suffices: sub-blocks of a homogeneous block stay homogeneous). The delta
refinement then runs a splitter worklist (:func:`delta_refine`): popping a block ``C`` touches only
the predecessors of ``C``, and each block holding one is checked, and if need be split, on the
criteria ``(option, C)`` one option after another; every block that is split is pushed back,
all its parts. A sub-block of a stable block stays stable for the same criterion, so only blocks
whose target masses changed are ever re-examined. The order of the cuts differs from the earlier
round-based rule (every dirty block split on its worst criterion per round, still available as
:func:`delta_refine_rounds`), so with ``delta > 0`` the result can be a different - equally
delta-stable - partition; with ``delta = 0`` the fixpoint is unique and both give the exact
lumping, which is then computed by :mod:`adpart.partition.lumping`.

Comparisons allow ``atol`` (default 1e-9) on top of delta and epsilon, so that masses equal up to
floating-point rounding count as equal.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp

from adpart.errors import ModelError
from adpart.mdp.model import SMDPModel
from adpart.partition._kernels import (
    delta_worklist,
    greedy_groups,
    index_labels,
    predecessors_by_option,
    predecessors_of_rows,
)
from adpart.partition._validate import (
    DEFAULT_ATOL,
    as_model,
    check_atol,
    check_delta,
    check_epsilon,
    check_partition_fits,
    check_rewards,
    require_cover,
    select_options,
    selected_admissible,
)
from adpart.partition.partition import (
    Partition,
    block_all,
    canonical_labels,
    combine_labels,
    row_codes,
)


def regroup(
    labels: np.ndarray, n_blocks: int, states: np.ndarray, values: np.ndarray, width: float
) -> tuple[np.ndarray, int, np.ndarray]:
    """Split the blocks of ``states`` greedily by ``values`` (the delta-splitting rule).

    ``states`` must hold every member of each block it touches. The first group of a block keeps
    the block's id; later groups get new ids ``n_blocks, n_blocks + 1, ...``.

    Returns:
        ``(labels, n_blocks, split)``: updated labels (a new array), block count, and the ids of
        the blocks that were split (old ids).
    """
    if states.size == 0:
        return labels, n_blocks, np.zeros(0, dtype=np.int64)
    seg = labels[states]
    order = np.lexsort((values, seg))
    st, v, seg = states[order], values[order], seg[order]
    group = greedy_groups(seg, np.ascontiguousarray(v, dtype=np.float64), float(width))
    starts = np.flatnonzero(np.r_[True, group[1:] != group[:-1]])
    seg_first = np.r_[True, seg[starts][1:] != seg[starts][:-1]]
    new_rank = np.cumsum(~seg_first) - 1
    group_label = np.where(seg_first, seg[starts], n_blocks + new_rank)
    out = labels.copy()
    out[st] = group_label[group]
    split = np.unique(seg[starts][~seg_first])
    return out, n_blocks + int((~seg_first).sum()), split


def reward_split(
    labels: np.ndarray, rewards: np.ndarray, adm: np.ndarray, options: np.ndarray, width: float,
    states: np.ndarray | None = None,
) -> np.ndarray:
    """Split blocks so every option's reward varies by at most ``width`` inside a block (eq. 4.7).

    One greedy pass per option (a loop over options, each vectorised over all states); rewards of
    inadmissible pairs are ignored (blocks are admissibility-consistent, so they are 0 throughout).
    ``states`` restricts the passes to those states, which must hold every member of each block
    they touch (one block being refined); the other blocks are left as they are.
    """
    n_blocks = int(labels.max()) + 1
    states = np.arange(labels.size) if states is None else np.asarray(states, dtype=np.int64)
    for o in options:
        values = np.where(adm[states, o], rewards[states, o], 0.0)
        labels, n_blocks, _ = regroup(labels, n_blocks, states, values, width)
    return labels


def _span_table(
    sub: sp.csr_array, dstates: np.ndarray, labels: np.ndarray, n_blocks: int, k: int,
    sizes: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Masses of the dirty states into every block, per option, and their span per criterion.

    Returns per non-zero mass ``(key, state, mass)`` and per criterion ``(ukey, span)`` where
    ``key = (block * k + option) * n_blocks + target``.
    """
    nd = dstates.size
    S = labels.size
    onehot = sp.csr_array(
        (np.ones(S), labels.astype(np.int64), np.arange(S + 1, dtype=np.int64)), shape=(S, n_blocks)
    )
    M = sp.csr_array(sub @ onehot)  # a sparse product has one entry per (row, column)
    rows = np.repeat(np.arange(M.shape[0], dtype=np.int64), np.diff(M.indptr))
    nz = M.data > 0
    row, target, mass = rows[nz], M.indices[nz].astype(np.int64), M.data[nz]
    state = dstates[row % nd]
    block = labels[state]
    key = (block * k + row // nd) * n_blocks + target
    order = np.argsort(key, kind="stable")
    key, state, mass = key[order], state[order], mass[order]
    if key.size == 0:
        empty = np.zeros(0, dtype=np.int64)
        return key, state, mass, empty, np.zeros(0)
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    ukey = key[starts]
    hi = np.maximum.reduceat(mass, starts)
    lo = np.minimum.reduceat(mass, starts)
    count = np.diff(np.r_[starts, key.size])
    ublock = ukey // (k * n_blocks)
    lo = np.where(count < sizes[ublock], 0.0, lo)
    return key, state, mass, ukey, hi - lo


def delta_refine(
    labels: np.ndarray, F: sp.csr_array, k: int, delta: float, atol: float,
    max_rounds: int | None = None,
) -> tuple[np.ndarray, int]:
    """Refine ``labels`` until every block is delta-stable for the ``k`` stacked options of ``F``.

    A splitter worklist (:func:`adpart.partition._kernels.delta_worklist`, Paige-Tarjan /
    Derisavi style): only blocks with a predecessor in the popped splitter are re-examined, on the
    one criterion (option, splitter); every block that is split goes back on the list. With
    ``delta = 0`` the fixpoint is the unique coarsest exact lumping, computed by the exact-lumping
    worklist (:func:`adpart.partition.lumping.lump_labels`, which may skip the largest part).

    Args:
        labels: ``(S,)`` labels ``0..B-1`` whose blocks are admissibility-consistent.
        F: ``(k*S, S)`` CSR, row ``j*S + s`` = masses of option ``j`` (zero rows = inadmissible).
        k: number of options stacked in ``F``.
        delta, atol: the threshold of eq. 4.6 and the rounding allowance.
        max_rounds: safety cap on splitters popped (None: until the fixpoint).

    Returns:
        ``(labels, splitters popped)`` (0 on the exact-lumping path).
    """
    labels = np.ascontiguousarray(labels, dtype=np.int64)
    if delta == 0.0:
        from adpart.partition.lumping import lump_labels  # lumping imports this module

        return lump_labels(labels, F, k, atol), 0
    F = sp.csr_array(F)
    # the model's arrays as they are (no int64 / float64 copies: at 10^6 states and 20 options
    # each copy of the entries is ~2 GB); the kernels compile for the index dtype given
    preds = predecessors_by_option(labels.size, k, F.indptr, F.indices, F.data)
    return _worklist(labels, preds, k, delta, atol, max_rounds)


def model_predecessors(
    model: SMDPModel, options: np.ndarray, states: np.ndarray | None, keep: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The predecessor lists of the masked rows (eq. 4.6 compares admissible options only), read
    straight from ``model.F``: the ``j``-th option is ``options[j]``, its row for the ``i``-th of
    ``states`` (sorted, distinct; None: every state) is kept where ``keep[i, j]`` (None: every
    row), every other row is empty (:func:`adpart.partition._kernels.predecessor_fill`).

    No masked or stacked copy of ``F`` is formed (:func:`adpart.partition._validate.masked_rows`
    builds one): only the lists, 10 bytes per kept entry and one per (state, option) on a grid.
    """
    F = model.F if isinstance(model.F, sp.csr_array) else sp.csr_array(model.F)
    S = model.n_states
    options = np.ascontiguousarray(options, dtype=np.int64)
    states = np.arange(S, dtype=np.int64) if states is None else states
    if keep is None or keep.all():
        keep = np.broadcast_to(np.True_, (states.size, options.size))
    return predecessors_of_rows(S, F.indptr, F.indices, F.data, options, states,
                                np.asarray(keep, dtype=bool))


def delta_refine_rows(
    labels: np.ndarray, model: SMDPModel, options: np.ndarray, states: np.ndarray | None,
    keep: np.ndarray | None, delta: float, atol: float, max_rounds: int | None = None,
) -> tuple[np.ndarray, int]:
    """:func:`delta_refine` of the masked rows of :func:`model_predecessors`: option
    ``options[j]``'s row of the ``i``-th state of ``states`` where ``keep[i, j]``, read straight
    from ``model.F`` (the matrix :func:`adpart.partition._validate.block_rows` would build).

    With every state and ``keep`` the selected admissibility this is :func:`refine`'s delta stage.
    With some states only blocks holding them can be split (every other row is empty), so this
    refines one block of a layer against all its blocks (section 4.3.3) at the cost of the block's
    rows. ``delta = 0`` gives the exact lumping (:func:`adpart.partition.lumping.lump_lists`).
    """
    labels = np.ascontiguousarray(labels, dtype=np.int64)
    if states is not None:
        states = np.ascontiguousarray(states, dtype=np.int64)
    preds = model_predecessors(model, options, states, keep)
    k = np.size(options)
    if delta == 0.0:
        from adpart.partition.lumping import lump_lists  # lumping imports this module

        return lump_lists(labels, preds, k, atol), 0
    return _worklist(labels, preds, k, delta, atol, max_rounds)


def _worklist(labels: np.ndarray, preds: tuple[np.ndarray, ...], k: int, delta: float,
              atol: float, max_rounds: int | None) -> tuple[np.ndarray, int]:
    out, _, pops = delta_worklist(
        labels.size, k, *preds, index_labels(labels), int(labels.max()) + 1,
        float(delta + atol), 0 if max_rounds is None else int(max_rounds),
    )
    if pops < 0:
        raise ModelError(f"delta refinement did not reach a fixpoint in {max_rounds} splitters")
    return out.astype(np.int64), int(pops)


def delta_refine_rounds(
    labels: np.ndarray, F: sp.csr_array, k: int, delta: float, atol: float,
    max_rounds: int | None = None,
) -> tuple[np.ndarray, int]:
    """The earlier round-based refinement (kept as the benchmark's reference and a test oracle).

    Per round every dirty block (split, or holding a predecessor of a split block) is re-signed
    on all criteria and split on its worst one. Same contract as :func:`delta_refine`; it re-scans
    large dirty sets every round (measured ``time ~ S^1.45`` on grids) where the worklist scans
    only the predecessors of one splitter at a time.

    Args:
        labels: ``(S,)`` labels ``0..B-1`` whose blocks are admissibility-consistent.
        F: ``(k*S, S)`` CSR, row ``j*S + s`` = masses of option ``j`` (zero rows = inadmissible).
        k: number of options stacked in ``F``.
        delta, atol: the threshold of eq. 4.6 and the rounding allowance.

    Returns:
        ``(labels, rounds)``.
    """
    S = labels.size
    labels = labels.astype(np.int64, copy=True)
    n_blocks = int(labels.max()) + 1
    # Who steps into whom under some option, deduplicated across options (a dirty block's
    # predecessors are looked up in it every round).
    into = sp.csr_array(F.T).tocoo()
    preds_of = sp.csr_array((np.ones(into.nnz, dtype=np.int8), (into.row, into.col % S)),
                            shape=(S, S))
    preds_of.sum_duplicates()
    width = delta + atol
    dirty = np.ones(n_blocks, dtype=bool)
    rounds = 0
    while True:
        dstates = np.flatnonzero(dirty[labels])
        if dstates.size == 0:
            break
        if max_rounds is not None and rounds >= max_rounds:
            raise ModelError(f"delta refinement did not reach a fixpoint in {max_rounds} rounds")
        rounds += 1
        rows = (np.arange(k, dtype=np.int64)[:, None] * S + dstates[None, :]).ravel()
        sizes = np.bincount(labels, minlength=n_blocks)
        key, state, mass, ukey, span = _span_table(F[rows], dstates, labels, n_blocks, k, sizes)
        bad = np.flatnonzero(span > width)
        if bad.size == 0:
            break
        bad_block = ukey[bad] // (k * n_blocks)
        pick = np.lexsort((ukey[bad], -span[bad], bad_block))
        first = np.r_[True, bad_block[pick][1:] != bad_block[pick][:-1]]
        chosen = np.full(n_blocks, -1, dtype=np.int64)
        chosen[bad_block[pick][first]] = ukey[bad][pick][first]
        hit = key == chosen[labels[state]]
        values = np.zeros(S)
        values[state[hit]] = mass[hit]
        members = dstates[chosen[labels[dstates]] >= 0]
        old_n = n_blocks
        labels, n_blocks, split = regroup(labels, n_blocks, members, values[members], width)
        # dirty next round: the split blocks, their new parts, and blocks of their predecessors
        changed = np.zeros(n_blocks, dtype=bool)
        changed[split] = True
        changed[old_n:] = True
        moved = np.flatnonzero(changed[labels])
        dirty = changed.copy()
        if moved.size:
            dirty[labels[preds_of[moved].indices]] = True
    return labels, rounds


def refine(
    partition: Partition,
    model: SMDPModel | object,
    *,
    options: Sequence[int] | np.ndarray | None = None,
    delta: float,
    epsilon: float | None = None,
    rewards: np.ndarray | None = None,
    atol: float = DEFAULT_ATOL,
    require_admissible: bool = True,
    max_rounds: int | None = None,
) -> Partition:
    """Refine ``partition`` to epsilon,delta-stability (definition 4.4) for a set of options.

    Args:
        partition: the initial partition (the result refines it).
        model: an :class:`SMDPModel` of the options (or a FiniteMDP: its primitive actions).
        options: indices of the options the partition must be stable for (default: all).
        delta: threshold of eq. 4.6, in ``[0, 1]``.
        epsilon: threshold of eq. 4.7, ``>= 0``; None ignores rewards (phases 1 and 2).
        rewards: ``(S, O)`` task rewards ``R(s, o)`` (default: the model's ``R``).
        atol: rounding allowance added to both thresholds.
        require_admissible: raise when a state has no selected admissible option (the decision
            layer needs one everywhere); phase 1 of a single option turns this off.
        max_rounds: safety cap on delta rounds (None: until the fixpoint).

    Returns:
        The refined :class:`Partition`; its ``admissible`` table offers the selected options only.
    """
    smdp = as_model(model)
    d = check_delta(delta)
    e = check_epsilon(epsilon)
    tol = check_atol(atol)
    if not isinstance(partition, Partition):
        raise ModelError(f"partition must be a Partition, got {type(partition).__name__}")
    check_partition_fits(partition.labels, smdp.n_states)
    sel = select_options(smdp, options)
    adm = selected_admissible(smdp, sel)
    if require_admissible:
        require_cover(adm, sel)
    labels = combine_labels(partition.labels, row_codes(adm[:, sel]))
    if e is not None:
        R = check_rewards(smdp.R if rewards is None else rewards, smdp)
        labels = canonical_labels(reward_split(labels, R, adm, sel, e + tol))
    # the masked rows' predecessor lists straight from the model (no masked copy of F)
    keep = adm[:, sel]
    keep = None if keep.all() else keep
    labels, _ = delta_refine_rows(labels, smdp, sel, None, keep, d, tol, max_rounds)
    labels = canonical_labels(labels)
    n_blocks = int(labels.max()) + 1
    return Partition(labels, block_all(labels, n_blocks, adm))

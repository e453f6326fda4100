"""The delta worklist against its earlier implementation and against a brute-force refinement.

With ``delta > 0`` the coarsest delta-stable refinement of a partition is not unique: eq. 4.6 is
not transitive, so masses 0, 0.2 and 0.4 into one target with delta = 0.3 can be cut as
``{0, 0.2} {0.4}`` or as ``{0} {0.2, 0.4}``, both stable and both with the fewest blocks
(:func:`test_two_coarsest_delta_stable_refinements_exist`). Which one a refiner returns depends on
the order of its cuts, so a brute-force refiner that cuts in another order is compared on what
every correct refiner must satisfy - the result is delta-stable, refines the initial partition,
and is refined by the exact lumping (no cut ever separates two bisimilar states) - while the
rewritten kernel is compared label for label with the earlier one
(``tests/partition/_delta_reference.py``): it pops the same splitters and makes the same cuts,
so on every input it must return the same partition.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from adpart.mdp.model import SMDPModel
from adpart.partition import Partition, check_stability, exact_lumping, refine
from adpart.partition._kernels import (
    delta_worklist,
    predecessors_by_option,
    predecessors_of_rows,
)
from adpart.partition._validate import block_rows
from adpart.partition.partition import canonical_labels
from adpart.partition.refine import delta_refine, delta_refine_rows
from tests.partition._delta_reference import delta_worklist_reference
from tests.partition.test_partition_properties import (
    _initial,
    _stacked,
    brute_force_bisimulation,
    random_smdps,
)

ATOL = 1e-9


def reference_labels(labels: np.ndarray, F: sp.csr_array, k: int, width: float):
    """The earlier kernel's labels and pops, fed the transposed model it was written for."""
    FT = sp.csr_array(F.T)
    FT.eliminate_zeros()
    out, _, pops = delta_worklist_reference(
        labels.size, k, FT.indptr.astype(np.int64), FT.indices.astype(np.int64),
        FT.data.astype(np.float64), labels.astype(np.int64).copy(), int(labels.max()) + 1,
        width, 0,
    )
    return out, pops


def brute_force_delta(labels: np.ndarray, F: sp.csr_array, k: int, width: float) -> np.ndarray:
    """delta-refinement by exhaustive search: cut the first unstable (block, option, target).

    Dense masses into every block are recomputed after every single cut; the cut is the same
    greedy rule (sort the block's masses, start a new group whenever a mass exceeds the group's
    first by more than ``width``), but the order of the cuts is plain index order.
    """
    S = labels.size
    Fd = F.toarray()
    labels = canonical_labels(labels)
    while True:
        B = int(labels.max()) + 1
        M = Fd @ np.eye(B)[labels]  # (k*S, B) masses into every block
        cut = None
        for b in range(B):
            members = np.flatnonzero(labels == b)
            for a in range(k):
                for j in range(B):
                    v = M[a * S + members, j]
                    if v.max() - v.min() > width:
                        cut = members, v
                        break
                if cut:
                    break
            if cut:
                break
        if cut is None:
            return labels
        members, v = cut
        order = np.argsort(v, kind="stable")
        group, first = 0, v[order[0]]
        new = labels.copy()
        for s, x in zip(members[order], v[order], strict=True):
            if x - first > width:
                group, first = group + 1, x
            if group:
                new[s] = B + group - 1
        labels = canonical_labels(new)


def _partition(labels: np.ndarray, model: SMDPModel) -> Partition:
    return Partition.from_labels(canonical_labels(labels), model.admissible)


@settings(max_examples=60, deadline=None)
@given(random_smdps(), st.sampled_from([0.05, 0.2, 0.3, 0.6, 1.0]))
def test_worklist_returns_the_earlier_kernels_partition(case, delta):
    model, rng = case
    initial = _initial(model, rng)
    labels, F, k = _stacked(model, initial)
    new, pops = delta_refine(labels, F, k, delta, ATOL)
    old, old_pops = reference_labels(labels, F, k, delta + ATOL)
    assert np.array_equal(new, old)
    assert pops == old_pops
    # and through the public entry point
    part = refine(initial, model, delta=delta)
    assert np.array_equal(part.labels, canonical_labels(old))


@settings(max_examples=60, deadline=None)
@given(random_smdps(), st.sampled_from([0.05, 0.2, 0.3, 0.6, 1.0]))
def test_worklist_and_brute_force_are_stable_refinements_no_finer_than_the_lumping(case, delta):
    model, rng = case
    initial = _initial(model, rng)
    labels, F, k = _stacked(model, initial)
    lumping = exact_lumping(model, initial=initial, use_rewards=False)
    fast = _partition(delta_refine(labels, F, k, delta, ATOL)[0], model)
    slow = _partition(brute_force_delta(labels, F, k, delta + ATOL), model)
    for part in (fast, slow):
        assert part.is_refinement_of(initial)
        assert check_stability(part, model, delta=delta)
        assert lumping.is_refinement_of(part)  # bisimilar states are never cut apart


@settings(max_examples=40, deadline=None)
@given(random_smdps())
def test_kernel_at_zero_width_is_the_unique_exact_lumping(case):
    # refine() sends delta = 0 to exact lumping; the worklist itself must agree with the oracle
    model, rng = case
    initial = _initial(model, rng)
    labels, F, k = _stacked(model, initial)
    lists = predecessors_by_option(labels.size, k, F.indptr, F.indices, F.data)
    out, _, _ = delta_worklist(labels.size, k, *lists, labels.copy(), int(labels.max()) + 1,
                               ATOL, 0)
    oracle = brute_force_bisimulation(model, initial.labels, rewards=False)
    assert np.array_equal(canonical_labels(out), oracle)
    assert np.array_equal(brute_force_delta(labels, F, k, ATOL), oracle)


@settings(max_examples=30, deadline=None)
@given(random_smdps())
def test_predecessor_lists_are_the_transpose_grouped_by_option(case):
    model, _ = case
    F = sp.csr_array(model.F)
    S, k = model.n_states, model.n_actions
    lists = predecessors_by_option(S, k, F.indptr, F.indices, F.data)
    start, length, off, val, ring = lists
    assert ring in (0, S)
    # offsets from the target fit 16 bits, list lengths a byte
    assert start.dtype == np.int32 and length.dtype == np.uint8 and off.dtype == np.int16
    # large models come with int64 indices; far predecessors need wider offsets
    for wide in (predecessors_by_option(S, k, F.indptr.astype(np.int64),
                                        F.indices.astype(np.int64), F.data),
                 predecessors_by_option(S, k, F.indptr, F.indices, F.data, off_dtype=np.int64)):
        for x, y in zip(lists, wide, strict=True):
            assert np.array_equal(x, y)
    Fd = F.toarray()
    for t in range(S):
        lo = start[t]
        for a in range(k):
            hi = lo + length[t * k + a]
            expect = np.flatnonzero(Fd[a * S:(a + 1) * S, t])
            assert np.array_equal((t + off[lo:hi]) % S, expect)
            assert np.all(np.abs(off[lo:hi]) <= S // 2)  # the shorter way round
            assert np.array_equal(val[lo:hi], Fd[a * S + expect, t])
            lo = hi
        assert lo == start[t + 1]


def test_offsets_and_lengths_widen_with_the_farthest_predecessor_and_the_longest_list():
    from adpart.partition._kernels import length_dtype, offset_dtype

    assert offset_dtype(0) == np.int16 and offset_dtype(2**15 - 1) == np.int16
    assert offset_dtype(2**15) == np.int32 and offset_dtype(2**31 - 1) == np.int32
    assert offset_dtype(2**31) == np.int64
    assert length_dtype(0) == np.uint8 and length_dtype(255) == np.uint8
    assert length_dtype(256) == np.uint16 and length_dtype(2**16) == np.int64
    # a ring: each state steps to the next, the last to the first: offsets -1 the short way
    S = 2**15 + 2
    ring = sp.csr_array((np.full(S, 0.9), (np.arange(S), (np.arange(S) + 1) % S)), shape=(S, S))
    lists = predecessors_by_option(S, 1, ring.indptr, ring.indices, ring.data)
    assert lists[2].dtype == np.int16 and np.all(lists[2] == -1) and lists[4] == S
    # each state steps half way round: offsets of S / 2 > 2^15 - 1
    S = 2**16 + 4
    half = sp.csr_array((np.full(S, 0.9), (np.arange(S), (np.arange(S) + S // 2) % S)),
                        shape=(S, S))
    _, _, off, _, wrap = predecessors_by_option(S, 1, half.indptr, half.indices, half.data)
    assert off.dtype == np.int32 and wrap == 0  # S / 2 is as short one way as the other
    assert np.array_equal((np.arange(S) + off) % S, (np.arange(S) - S // 2) % S)
    # a star: every state steps into state 0, whose one list is S long
    S = 300
    F = sp.csr_array((np.full(S, 0.9), (np.arange(S), np.zeros(S, dtype=np.int64))), shape=(S, S))
    start, length, off, _, ring = predecessors_by_option(S, 1, F.indptr, F.indices, F.data)
    assert length.dtype == np.uint16 and length[0] == S and start[1] == S and ring == S
    assert np.array_equal(off % S, np.arange(S))


@settings(max_examples=30, deadline=None)
@given(random_smdps(), st.sampled_from([0.0, 0.3]))
def test_the_worklists_do_not_depend_on_the_widths_of_their_arrays(case, delta):
    # int16 / int32 / int64 offsets and int32 / int64 state arrays: one partition, one trajectory
    from adpart.partition._kernels import lump

    model, rng = case
    labels, F, k = _stacked(model, _initial(model, rng))
    runs = set()
    for off_dtype in (None, np.int32, np.int64):
        lists = predecessors_by_option(labels.size, k, F.indptr, F.indices, F.data, off_dtype)
        for idx in (np.int32, np.int64):
            init = labels.astype(idx)
            if delta:
                out, nb, pops = delta_worklist(labels.size, k, *lists, init,
                                               int(labels.max()) + 1, delta + ATOL, 0)
            else:
                (out, nb), pops = lump(labels.size, k, *lists, init, int(labels.max()) + 1,
                                       ATOL), 0
            assert out.dtype == idx
            runs.add((out.astype(np.int64).tobytes(), int(nb), int(pops)))
    assert len(runs) == 1


@settings(max_examples=40, deadline=None)
@given(random_smdps(), st.integers(0, 2**31 - 1))
def test_rows_of_some_states_give_the_lists_and_the_refinement_of_their_masked_matrix(case, draw):
    # the learner's one-block refinement reads the rows straight from the model; it must equal
    # the transpose of the masked matrix block_rows builds, and refine alike from it
    model, rng = case
    S, n_opt = model.n_states, model.n_actions
    pick = np.random.default_rng(draw)
    states = np.flatnonzero(pick.random(S) < 0.5)
    options = np.flatnonzero(pick.random(n_opt) < 0.7)
    if states.size == 0 or options.size == 0:
        return
    keep = model.admissible[np.ix_(states, options)] & (pick.random((states.size, options.size))
                                                         < 0.8)
    F = sp.csr_array(model.F)
    lists = predecessors_of_rows(S, F.indptr, F.indices, F.data, options, states, keep)
    masked = block_rows(model, options, states, keep)
    expect = predecessors_by_option(S, options.size, masked.indptr, masked.indices, masked.data)
    for x, y in zip(lists, expect, strict=True):
        assert np.array_equal(x, y)
    labels = _initial(model, rng).labels
    for delta in (0.0, 0.3):
        assert np.array_equal(
            delta_refine_rows(labels, model, options, states, keep, delta, ATOL)[0],
            delta_refine(labels, masked, options.size, delta, ATOL)[0])


def test_two_coarsest_delta_stable_refinements_exist():
    # states 0, 1, 2 put 0, 0.2, 0.4 on the absorbing state 3 and the rest of 0.9 on themselves
    p = np.array([0.0, 0.2, 0.4])
    F = np.zeros((4, 4))
    F[[0, 1, 2], 3] = p
    F[[0, 1, 2], [0, 1, 2]] = 0.9 - p
    F[3, 3] = 0.9
    model = SMDPModel(R=np.zeros((4, 1)), F=sp.csr_array(F), admissible=np.ones((4, 1), bool))
    start = Partition.from_labels(np.array([0, 0, 0, 1]), model.admissible)
    assert not check_stability(start, model, delta=0.3)
    greedy = refine(start, model, delta=0.3)
    other = Partition.from_labels(np.array([0, 1, 1, 2]), model.admissible)
    assert np.array_equal(greedy.labels, [0, 0, 1, 2])  # cut from the smallest mass up
    for part in (greedy, other):
        assert part.n_blocks == 3
        assert check_stability(part, model, delta=0.3)


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 40), st.integers(1, 8), st.integers(0, 5), st.integers(0, 2**31 - 1))
def test_block_admissibility_is_the_and_over_each_blocks_states(S, B, n_opt, seed):
    from adpart.partition.partition import block_all

    rng = np.random.default_rng(seed)
    labels = rng.integers(0, B, size=S)
    mask = rng.random((S, n_opt)) < 0.8
    expect = np.array([[mask[labels == b, o].all() for o in range(n_opt)] for b in range(B)],
                      dtype=bool).reshape(B, n_opt)  # empty blocks: vacuously True
    assert np.array_equal(block_all(labels, B, mask), expect)

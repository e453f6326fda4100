"""The refiners read their predecessor lists straight from the model and still give the partitions
they gave when they read a masked copy of ``F`` transposed by scipy.

The lists (:func:`adpart.partition._kernels.predecessor_fill`) keep a predecessor as its offset
from the target and one length per (target, option); :func:`refine` and :func:`exact_lumping` no
longer form the masked rows of the selected options (eq. 4.6 compares admissible options only).
Pinned here:

* on the benchmark's workloads (``benchmarks/bench_partition.py``: 20 macro options on the rooms
  and the lumpable grid), the labels' digests and the splitters popped, as the code before the
  change computed them, with the independent checker (definition 4.4) on the delta partition and
  the exact lumping refining it (bisimilar states are never cut apart);
* on random models with option subsets, partial admissibility and rewards, the earlier kernel
  (``tests/partition/_delta_reference.py``) fed scipy's transpose of the masked matrix, and the
  round-based refiner's exact lumping of that matrix.
"""

from __future__ import annotations

import hashlib

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from adpart.mdp.model import SMDPModel
from adpart.partition import Partition, check_stability, exact_lumping, refine
from adpart.partition._validate import masked_rows, select_options, selected_admissible
from adpart.partition.partition import canonical_labels, combine_labels, row_codes
from adpart.partition.refine import delta_refine_rounds, delta_refine_rows, reward_split
from tests.partition.test_partition_delta_worklist import ATOL, reference_labels
from tests.partition.test_partition_properties import _initial, random_smdps

# sha256 of the int64 labels and the splitters popped by delta = 0.3, computed by the code
# before the lists were read from the model (delta = 0.3 and exact lumping agree on both grids)
PINNED = {
    ("rooms", 10_000): ("385d316d923e9969ae7ffbf9adfc8ea59c2397dd3d12f5f384ff3ec6b7ef3b6d",
                        10_180),
    ("lumpable", 10_000): ("be2db98c6a0f71ea7f828b02b95ed440ca2b35f4a50b5289f323889afe92e1eb",
                           101),
    ("rooms", 100_000): ("2e04d9ab52fea5998736cc7bbf3d87aa73eeac7f0389cb794f89596c7fbfe79e",
                         104_384),
    ("lumpable", 100_000): ("b9115b3e5d920dbf9d40dd9268dca07ff0aabfda1f5d5606e0d9a97a573b5702",
                            317),
}


def _digest(labels: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(labels, dtype=np.int64).tobytes()).hexdigest()


@pytest.mark.parametrize(("workload", "n"), list(PINNED))
def test_benchmark_workloads_keep_their_partitions(workload, n):
    from benchmarks.bench_partition import delta_workload, macro_options

    mdp, lab = delta_workload(workload, n)
    model = macro_options(mdp)
    start = Partition.from_labels(lab, model.admissible)
    digest, pops = PINNED[(workload, n)]
    part = refine(start, model, delta=0.3)
    exact = exact_lumping(model, initial=start, use_rewards=False)
    assert _digest(part.labels) == digest
    assert _digest(exact.labels) == digest
    labels = combine_labels(start.labels, row_codes(model.admissible))
    _, popped = delta_refine_rows(labels, model, np.arange(model.n_actions), None, None, 0.3,
                                  ATOL)
    assert popped == pops
    if n <= 10_000:  # the checker builds a dense (members x blocks) table per block and option
        assert check_stability(part, model, delta=0.3)
        assert exact.is_refinement_of(part)


def _with_rows_where_inadmissible(model: SMDPModel, pick: np.random.Generator) -> SMDPModel:
    """The model with a redrawn admissibility and a non-zero row for every (state, option): a
    self-loop of mass 0.5 where its row was empty, so that only the mask keeps an inadmissible
    option's masses out of the refinement."""
    S, n_opt = model.n_states, model.n_actions
    F = sp.csr_array(model.F)
    empty = np.flatnonzero(np.diff(F.indptr) == 0)
    F = sp.csr_array(F + sp.csr_array((np.full(empty.size, 0.5), (empty, empty % S)),
                                      shape=F.shape))
    admissible = pick.random((S, n_opt)) < 0.6
    admissible[np.arange(S), pick.integers(0, n_opt, size=S)] = True
    return SMDPModel(R=model.R, F=F, admissible=admissible)


@settings(max_examples=60, deadline=None)
@given(random_smdps(), st.sampled_from([0.05, 0.2, 0.3]), st.sampled_from([None, 0.5]),
       st.integers(0, 2**31 - 1))
def test_option_subsets_and_partial_admissibility_give_the_masked_matrix_partitions(
        case, delta, epsilon, draw):
    model, rng = case
    pick = np.random.default_rng(draw)
    options = np.flatnonzero(pick.random(model.n_actions) < 0.7)
    assume(options.size > 0)
    model = _with_rows_where_inadmissible(model, pick)
    initial = _initial(model, rng)
    part = refine(initial, model, options=options, delta=delta, epsilon=epsilon,
                  require_admissible=False)
    lumping = exact_lumping(model, initial=initial, options=options,
                            use_rewards=epsilon is not None, require_admissible=False)
    # the path before: the masked rows of the selected options, transposed by scipy
    sel = select_options(model, options)
    adm = selected_admissible(model, sel)
    labels = combine_labels(initial.labels, row_codes(adm[:, sel]))
    if epsilon is not None:
        labels = canonical_labels(reward_split(labels, model.R, adm, sel, epsilon + ATOL))
        exact_start = canonical_labels(reward_split(
            combine_labels(initial.labels, row_codes(adm[:, sel])), model.R, adm, sel, ATOL))
    else:
        exact_start = labels
    F = masked_rows(model, sel, adm)
    old, _ = reference_labels(labels, F, sel.size, delta + ATOL)
    assert np.array_equal(part.labels, canonical_labels(old))
    rounds, _ = delta_refine_rounds(exact_start, F, sel.size, 0.0, ATOL)
    assert np.array_equal(lumping.labels, canonical_labels(rounds))
    assert check_stability(part, model, options=options, delta=delta, epsilon=epsilon)


def test_an_inadmissible_options_masses_never_split_a_block():
    # states 0 and 1 agree on option 0 and may not start option 1, whose rows send them into
    # different blocks (0 -> 2, 1 -> 0): with the mask they stay together, without it delta = 0.3
    # and exact lumping would split them
    F = np.zeros((8, 4))
    F[[0, 1, 2, 3], [2, 2, 2, 3]] = 0.9
    F[4, 2] = F[5, 0] = F[6, 2] = F[7, 3] = 0.9
    admissible = np.array([[True, False], [True, False], [True, True], [True, True]])
    model = SMDPModel(R=np.zeros((4, 2)), F=sp.csr_array(F), admissible=admissible)
    start = Partition.trivial(admissible)
    for part in (refine(start, model, delta=0.3),
                 exact_lumping(model, initial=start, use_rewards=False)):
        assert part.labels.tolist() == [0, 0, 1, 1]
        assert check_stability(part, model, delta=0.0)

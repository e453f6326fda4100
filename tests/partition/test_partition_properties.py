"""Property tests of the refiners on random small MDPs and SMDPs with planted equivalences.

The oracle is an independent brute-force coarsest bisimulation: Python signature refinement with
rounded masses, iterated until the block count stops growing.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from adpart.mdp.model import FiniteMDP, SMDPModel
from adpart.partition import Partition, check_stability, exact_lumping, refine
from adpart.partition.partition import canonical_labels


def brute_force_bisimulation(model: SMDPModel, initial: np.ndarray, rewards: bool) -> np.ndarray:
    """Coarsest exact lumping by naive signature refinement (dicts of rounded masses)."""
    S, n_opt = model.n_states, model.n_actions
    F = model.F.toarray()
    adm = model.admissible

    def key(x: float) -> float:
        return round(float(x), 8) + 0.0

    labels = [
        (int(initial[s]), tuple(bool(v) for v in adm[s]),
         tuple(key(model.R[s, o]) if rewards and adm[s, o] else 0.0 for o in range(n_opt)))
        for s in range(S)
    ]
    labels = canonical_labels(np.array([hash(x) for x in labels]))
    while True:
        B = labels.max() + 1
        sigs = []
        for s in range(S):
            per_option = []
            for o in range(n_opt):
                mass = np.zeros(B)
                if adm[s, o]:
                    for t in range(S):
                        mass[labels[t]] += F[o * S + s, t]
                per_option.append(tuple(key(m) for m in mass))
            sigs.append((int(labels[s]), tuple(per_option)))
        index = {}
        new = np.array([index.setdefault(sg, len(index)) for sg in sigs])
        new = canonical_labels(new)
        if new.max() == labels.max():
            return labels
        labels = new


@st.composite
def planted_mdps(draw):
    """A random MDP lifted from a small quotient, so that non-trivial lumpings exist."""
    k = draw(st.integers(1, 4))
    A = draw(st.integers(1, 3))
    copies = draw(st.lists(st.integers(1, 3), min_size=k, max_size=k))
    seed = draw(st.integers(0, 2**31 - 1))
    rng = np.random.default_rng(seed)
    block_of = np.repeat(np.arange(k), copies)
    S = block_of.size
    members = [np.flatnonzero(block_of == j) for j in range(k)]
    weights = rng.integers(0, 4, size=(k, A, k)).astype(float)
    weights[..., 0] += (weights.sum(axis=2) == 0)
    P = np.zeros((S, A, S))
    for s in range(S):
        for a in range(A):
            for j in range(k):
                w = weights[block_of[s], a, j]
                if w == 0:
                    continue
                # split the block's mass among its copies in random integer quarters
                parts = rng.multinomial(4, np.ones(members[j].size) / members[j].size)
                P[s, a, members[j]] += w * parts / 4.0
    P /= P.sum(axis=2, keepdims=True)
    R = rng.integers(-1, 2, size=(k, A)).astype(float)[block_of]
    noisy = rng.random(S) < draw(st.sampled_from([0.0, 0.2]))
    R[noisy] += rng.integers(1, 3, size=(noisy.sum(), A))
    terminal = rng.random(S) < draw(st.sampled_from([0.0, 0.15]))
    admissible = rng.random((S, A)) < 0.85
    admissible[np.arange(S), rng.integers(0, A, size=S)] = True
    gamma = draw(st.sampled_from([0.9, 0.95]))
    mdp = FiniteMDP.from_dense(P, R, gamma, terminal=terminal, admissible=admissible)
    return mdp.as_smdp(), rng


@st.composite
def random_smdps(draw):
    """A random SMDP with discounted rows of varying mass (options of varying duration)."""
    model, rng = draw(planted_mdps())
    S, n_opt = model.n_states, model.n_actions
    scale = rng.choice([0.5, 0.7, 0.9], size=n_opt * S)
    F = sp.csr_array(sp.diags_array(scale) @ model.F)
    return SMDPModel(R=model.R, F=F, admissible=model.admissible), rng


def _initial(model: SMDPModel, rng: np.random.Generator) -> Partition:
    return Partition.from_labels(rng.integers(0, 2, size=model.n_states), model.admissible)


@settings(max_examples=40)
@given(planted_mdps())
def test_exact_lumping_equals_brute_force(case):
    model, rng = case
    initial = _initial(model, rng)
    fast = exact_lumping(model, initial=initial)
    rounds = refine(initial, model, delta=0.0, epsilon=0.0)
    oracle = brute_force_bisimulation(model, initial.labels, rewards=True)
    assert np.array_equal(fast.labels, oracle)
    assert np.array_equal(rounds.labels, oracle)
    assert fast.is_refinement_of(initial)
    assert check_stability(fast, model, delta=0.0, epsilon=0.0)


@settings(max_examples=30)
@given(random_smdps())
def test_reward_independent_lumping_of_smdps(case):
    model, rng = case
    initial = _initial(model, rng)
    fast = exact_lumping(model, initial=initial, use_rewards=False)
    rounds = refine(initial, model, delta=0.0)
    oracle = brute_force_bisimulation(model, initial.labels, rewards=False)
    assert np.array_equal(fast.labels, oracle)
    assert np.array_equal(rounds.labels, oracle)
    assert check_stability(fast, model, delta=0.0)


@settings(max_examples=40)
@given(random_smdps(), st.sampled_from([0.05, 0.2, 0.3, 0.6, 1.0]),
       st.sampled_from([None, 0.0, 0.5, 2.0]))
def test_delta_refinement_is_stable_and_refines_the_initial_partition(case, delta, epsilon):
    model, rng = case
    initial = _initial(model, rng)
    part = refine(initial, model, delta=delta, epsilon=epsilon)
    assert part.is_refinement_of(initial)
    assert check_stability(part, model, delta=delta, epsilon=epsilon)
    # the exact lumping is always at least as fine as any delta-stable greedy refinement's needs
    exact = exact_lumping(model, initial=initial, use_rewards=epsilon is not None)
    assert part.n_blocks <= exact.n_blocks or delta == 0.0


@settings(max_examples=25)
@given(random_smdps(), st.sampled_from([0.1, 0.3]))
def test_option_subsets_only_need_their_own_stability(case, delta):
    model, rng = case
    n_opt = model.n_actions
    subset = sorted(set(rng.integers(0, n_opt, size=max(1, n_opt - 1)).tolist()))
    assume(model.admissible[:, subset].any(axis=1).all())
    part = refine(Partition.trivial(model.admissible), model, options=subset, delta=delta)
    assert check_stability(part, model, options=subset, delta=delta)
    offered = np.flatnonzero(part.admissible.any(axis=0))
    assert set(offered.tolist()) <= set(subset)


def _stacked(model: SMDPModel, initial: Partition):
    from adpart.partition._validate import masked_rows, select_options, selected_admissible
    from adpart.partition.partition import combine_labels, row_codes

    sel = select_options(model, None)
    adm = selected_admissible(model, sel)
    labels = combine_labels(initial.labels, row_codes(adm[:, sel]))
    return labels, masked_rows(model, sel, adm), sel.size


@settings(max_examples=40)
@given(planted_mdps())
def test_round_based_refinement_at_delta_zero_equals_the_oracle(case):
    # refine() routes delta = 0 to the exact-lumping worklist; the round-based refiner stays an
    # independent implementation of the same fixpoint
    from adpart.partition.refine import delta_refine_rounds

    model, rng = case
    initial = _initial(model, rng)
    labels, F, k = _stacked(model, initial)
    rounds, _ = delta_refine_rounds(labels, F, k, 0.0, 1e-9)
    oracle = brute_force_bisimulation(model, initial.labels, rewards=False)
    assert np.array_equal(canonical_labels(rounds), oracle)
    assert np.array_equal(refine(initial, model, delta=0.0).labels, oracle)


@settings(max_examples=40)
@given(random_smdps(), st.sampled_from([0.05, 0.2, 0.3, 0.6]))
def test_worklist_and_round_based_refinement_are_both_stable(case, delta):
    # the cut order differs, so the partitions may differ; both must be delta-stable refinements
    from adpart.partition.refine import delta_refine, delta_refine_rounds

    model, rng = case
    initial = _initial(model, rng)
    labels, F, k = _stacked(model, initial)
    counts = []
    for fn in (delta_refine, delta_refine_rounds):
        out, _ = fn(labels, F, k, delta, 1e-9)
        part = Partition.from_labels(canonical_labels(out), model.admissible)
        assert part.is_refinement_of(initial)
        assert check_stability(part, model, delta=delta)
        counts.append(part.n_blocks)
    assert counts[0] <= 2 * counts[1] + 1  # comparable, not only valid


@settings(max_examples=300, deadline=None)
@given(st.lists(st.integers(min_value=-3, max_value=40), min_size=1, max_size=60),
       st.sampled_from([np.int64, np.int32, np.int8]))
def test_canonical_labels_numbers_blocks_by_their_first_state(values, dtype):
    """Both paths of canonical_labels (the compiled pass for small non-negative ints, np.unique
    for the rest) against a plain Python oracle: the block of state s is the count of distinct
    labels first seen before s's label."""
    labels = np.array(values, dtype=dtype)
    order: dict[int, int] = {}
    expected = [order.setdefault(int(v), len(order)) for v in labels]
    assert canonical_labels(labels).tolist() == expected
    assert canonical_labels(labels.astype(np.float64)).tolist() == expected


@settings(max_examples=150, deadline=None)
@given(st.integers(min_value=1, max_value=12), st.integers(min_value=1, max_value=4),
       st.integers(min_value=0, max_value=2**32 - 1))
def test_one_blocks_rows_and_rewards_match_the_whole_state_space_path(S, n_opt, seed):
    """masked_rows(..., states=) and reward_split(..., states=) - what refine_block uses to refine
    one block - against the same calls over every state with the other states masked out."""
    from adpart.partition import masked_rows
    from adpart.partition.refine import reward_split

    rng = np.random.default_rng(seed)
    F = sp.random(n_opt * S, S, density=0.4, random_state=rng, format="csr") * 0.9
    model = SMDPModel(R=rng.integers(0, 3, (S, n_opt)).astype(float), F=sp.csr_array(F),
                      admissible=np.ones((S, n_opt), dtype=bool))
    labels = canonical_labels(rng.integers(0, 3, S))
    block = int(labels[rng.integers(S)])
    members = labels == block
    adm = (rng.random((S, n_opt)) < 0.8) & members[:, None]
    options = np.flatnonzero(rng.random(n_opt) < 0.7)
    assume(options.size > 0)
    inside = np.flatnonzero(members)
    whole = masked_rows(model, options, adm)
    one = masked_rows(model, options, adm, states=inside)
    assert np.array_equal(whole.indptr, one.indptr)
    assert abs(whole - one).sum() == 0.0
    assert np.array_equal(reward_split(labels, model.R, adm, options, 0.5),
                          reward_split(labels, model.R, adm, options, 0.5, states=inside))

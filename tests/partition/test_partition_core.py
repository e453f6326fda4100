"""The Partition type: canonical labels, intersect, refine, split, value mapping; BPSMDP; phases."""

from __future__ import annotations

import numpy as np
import pytest

from adpart.errors import ModelError
from adpart.mdp.generate import random_mdp
from adpart.mdp.solvers import solve
from adpart.partition import (
    BPSMDP,
    MultiPhasePartitioner,
    Partition,
    check_stability,
    exact_lumping,
    point_model,
    refine,
    theorem_4_5_bound,
    value_gap,
)
from tests.partition.example_grid import slide_options

ADM = np.ones((6, 2), dtype=bool)


def test_from_labels_is_canonical_and_equal_partitions_compare_equal():
    p = Partition.from_labels(np.array([7, 3, 7, 1, 3, 1]), ADM)
    assert p.labels.tolist() == [0, 1, 0, 2, 1, 2]
    assert p == Partition.from_labels(np.array([0, 5, 0, 9, 5, 9]), ADM)
    assert p.sizes.tolist() == [2, 2, 2]
    assert p.members(1).tolist() == [1, 4]


def test_from_canonical_equals_the_checked_constructor_and_is_read_only():
    labels = np.array([0, 1, 0, 2, 1, 2], dtype=np.int32)
    adm = np.array([[True, False], [True, True], [False, True]])
    p = Partition.from_canonical(labels, adm)
    assert p == Partition(labels.astype(np.int64), adm) and p.labels.dtype == np.int64
    labels[0] = 2  # the partition holds its own copies, frozen
    assert p.labels[0] == 0 and not p.labels.flags.writeable and not p.admissible.flags.writeable


def test_intersect_is_the_product_partition_and_refines_both():
    a = Partition.from_labels(np.array([0, 0, 0, 1, 1, 1]), ADM)
    b = Partition.from_labels(np.array([0, 1, 0, 1, 0, 1]), ADM)
    c = a.intersect(b)
    assert c.labels.tolist() == [0, 1, 0, 2, 3, 2]
    assert c.is_refinement_of(a) and c.is_refinement_of(b)
    assert not a.is_refinement_of(c)


def test_block_admissibility_is_the_and_over_members_and_children_inherit_it():
    adm = ADM.copy()
    adm[2, 1] = False
    p = Partition.from_labels(np.array([0, 0, 0, 1, 1, 1]), adm)
    assert p.admissible.tolist() == [[True, False], [True, True]]
    q = p.split_block(0, np.array([0, 1, 1]))
    assert q.labels.tolist() == [0, 1, 1, 2, 2, 2]
    assert q.admissible.tolist() == [[True, False], [True, False], [True, True]]


def test_map_values_children_inherit_the_parent_q():
    coarse = Partition.from_labels(np.array([0, 0, 0, 1, 1, 1]), ADM)
    fine = coarse.split_block(1, np.array([0, 1, 0]))
    Q = np.array([[1.0, 2.0], [3.0, 4.0]])
    assert fine.map_values(Q, coarse).tolist() == [[1.0, 2.0], [3.0, 4.0], [3.0, 4.0]]
    with pytest.raises(ModelError, match="does not refine"):
        coarse.map_values(np.zeros(3), fine)


def test_partition_rejects_bad_input():
    with pytest.raises(ModelError, match="canonical"):
        Partition(np.array([1, 0]), np.ones((2, 1), dtype=bool))
    with pytest.raises(ModelError, match="admissible"):
        Partition(np.array([0, 1]), np.ones((3, 1), dtype=bool))
    p = Partition.from_labels(np.array([0, 1]), np.ones((2, 1), dtype=bool))
    with pytest.raises(ModelError, match="block 5"):
        p.members(5)
    with pytest.raises(ModelError, match="same state space"):
        p.intersect(Partition.trivial(ADM))


def test_refiners_do_not_modify_the_model():
    mdp = random_mdp(12, 2, density=0.3, seed=3)
    adm = np.ones((12, 2), dtype=bool)
    adm[0, 1] = False
    mdp = mdp.with_rewards(mdp.R)
    from adpart.mdp.model import SMDPModel

    model = SMDPModel(R=mdp.R, F=mdp.as_smdp().F, admissible=adm)
    before = model.F.toarray().copy()
    refine(Partition.trivial(adm), model, delta=0.2)
    exact_lumping(model)
    assert np.array_equal(model.F.toarray(), before)


def test_bpsmdp_intervals_contain_every_state_value_and_exact_lumping_is_lossless():
    model, _cells, _term, _goal = slide_options([".....", ".#...", ".#..G", "....."])
    for delta in (0.0, 0.5, 1.0):
        part = refine(Partition.trivial(model.admissible), model, delta=delta, epsilon=1.0)
        V = solve(model, 1e-10).V
        iv = BPSMDP.from_partition(part, model).interval_values(tol=1e-10)
        assert np.all(iv.lower[part.labels] <= V + 1e-6)
        assert np.all(V <= iv.upper[part.labels] + 1e-6)
        gap = value_gap(part, model, epsilon=1.0, delta=delta)
        assert gap["inside_interval"] == 1.0
        assert gap["bound"] == pytest.approx(theorem_4_5_bound(0.95, 1.0, delta))
    exact = exact_lumping(model)
    assert value_gap(exact, model, epsilon=0.0, delta=0.0)["measured"] < 1e-6
    # an exact lumping's interval model is a point model: the intervals collapse on V*
    iv = BPSMDP.from_partition(exact, model).interval_values(tol=1e-10)
    assert np.max(iv.upper - iv.lower) < 1e-6


def test_point_model_uses_the_given_weights():
    model, _cells, _term, _goal = slide_options(["...G"])
    part = Partition.trivial(model.admissible)
    w = np.zeros(model.n_states)
    w[0] = 1.0
    pm = point_model(part, model, weights=w)
    assert pm.R[0].tolist() == pytest.approx(model.R[0].tolist())
    uniform = point_model(part, model)
    assert uniform.R[0].tolist() == pytest.approx(model.R.mean(axis=0).tolist())


def test_multiphase_caches_phase_one_and_reruns_only_phases_two_and_three():
    model, _cells, term, _goal = slide_options([".....", ".#...", ".#..G", "....."])
    mp = MultiPhasePartitioner(model, term, delta=0.5)
    first = mp.run([0, 1, 2, 3], epsilon=1.0)
    assert mp.phase1_runs == 4
    second = mp.run([1, 3], epsilon=1.0)
    assert mp.phase1_runs == 4
    assert second.phase2.is_refinement_of(second.phase1[1].intersect(second.phase1[3]))
    assert check_stability(second.phase3, model, options=[1, 3], delta=0.5, epsilon=1.0)
    assert first.block_counts()["phase2"] == first.phase2.n_blocks
    assert set(first.seconds) == {"phase1", "phase2", "phase3"}

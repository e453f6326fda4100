"""The expected-learning-time estimator on hand-built tasks (section 4.4), answers by hand."""

from __future__ import annotations

import numpy as np
import pytest

from adpart.errors import TaskError
from adpart.hierarchy import LearnedTask, expected_time, t_conv
from adpart.partition import Partition

NEG = -np.inf


def layer(labels, admissible) -> Partition:
    return Partition(np.asarray(labels, dtype=np.int64), np.asarray(admissible, dtype=bool))


def task(Q, occupancy, threshold=0.5, weight=1.0, labels=None) -> LearnedTask:
    return LearnedTask("t", np.asarray(Q, float), np.asarray(occupancy, float), threshold,
                       weight, None if labels is None else np.asarray(labels))


# column 0 is best everywhere; column 1 is as good in states 1-3 and far worse in state 0
Q = [[5.0, 1.0], [4.0, 3.9], [3.0, 3.0], [2.0, 2.0]]
D = [0.4, 0.1, 0.3, 0.2]
A = 1  # column 0 is the primitive action, column 1 an option


def test_no_refinement_costs_t_conv_uniform_option_sets():
    c = 2.5
    p = layer([0, 0, 1, 1], [[True, False], [True, False]])
    est = expected_time([task(Q, D)], p, c=c, n_primitives=A)
    assert est.total == pytest.approx(c * 2**2 * 1)  # c |P|^2 |O|, |O| = 1
    assert np.all(est.p_refine == 0)
    both = layer([0, 0, 1, 1], [[True, True], [True, True]])
    assert expected_time([task(Q, D)], both, c=c, n_primitives=A).total == pytest.approx(
        c * 2**2 * 2)


def test_block_lacking_the_best_action_pays_the_refinement_term():
    c = 1.5
    # block 0 = {0, 1} offers only column 1, which loses 4 > L in state 0
    p = layer([0, 0, 1, 1], [[False, True], [True, False]])
    est = expected_time([task(Q, D)], p, c=c, n_primitives=A)
    t = c * 2 * (1 + 1)  # c |P| sum_B |O_B|
    refine = 1.0 * c * 2**2 * (1 + A)  # P_refine (B_0) = 1, c n^2 (|O_B| + A)
    assert est.t_conv == pytest.approx(t)
    assert est.p_refine[0] == pytest.approx([1.0, 0.0])
    assert est.total == pytest.approx(t + refine)


def test_commitment_the_block_value_picks_the_column():
    # one block offering both columns commits to column 0 (weighted value 3.7 vs 2.63): no loss
    p = layer([0, 0, 0, 0], [[True, True]])
    est = expected_time([task(Q, D)], p, n_primitives=A, c=1.0)
    assert est.committed[0, 0] == 0 and est.p_refine[0, 0] == 0
    # a task where column 0 wins on average but loses 3 in state 3: the block must be refined,
    # although the seed's any-column test finds column 1 good there
    Q2 = [[5.0, 1.0], [4.0, 1.0], [3.0, 1.0], [2.0, 5.0]]
    est2 = expected_time([task(Q2, D)], p, n_primitives=A, c=1.0)
    assert est2.committed[0, 0] == 0 and est2.p_refine[0, 0] == 1
    assert est2.total == pytest.approx(1 * 2 + 4**2 * (2 + A))


def test_threshold_decides_what_is_significant():
    p = layer([0, 0, 0, 0], [[False, True]])
    assert expected_time([task(Q, D, threshold=4.5)], p, n_primitives=A,
                         c=1.0).total == pytest.approx(1.0)
    small = expected_time([task(Q, D, threshold=0.05)], p, n_primitives=A, c=1.0)
    # states 0 and 1 lose more than L under column 1: refined once, n = 4, |O_B| + A = 2
    assert small.total == pytest.approx(1.0 + 16 * 2)


def test_unoccupied_states_do_not_force_refinement():
    p = layer([0, 0, 0, 0], [[False, True]])
    d = [0.0, 0.4, 0.3, 0.3]  # state 0 (where column 1 loses 4) is never met
    assert expected_time([task(Q, d)], p, n_primitives=A, c=1.0).total == pytest.approx(1.0)


def test_block_without_options_always_refines_where_the_task_goes():
    p = layer([0, 0, 0, 0], [[False, False]])
    est = expected_time([task(Q, D)], p, c=1.0, n_primitives=A)
    assert est.total == pytest.approx(1 * 1 + 1.0 * 4**2 * (0 + A))


def test_flat_time_is_the_flat_layers_estimate():
    from adpart.hierarchy import flat_time

    adm = np.array([[True, False], [True, True], [True, True], [True, False]])
    flat = layer([0, 1, 2, 3], adm)
    Qa = np.where(adm, np.asarray(Q), -np.inf)
    est = expected_time([task(Qa, D)], flat, n_primitives=2, c=1.0)
    assert not est.p_refine.any()
    assert flat_time(adm, c=2.0) == pytest.approx(2.0 * est.total) == pytest.approx(2 * 4 * 6)


def test_task_partition_counts_task_blocks_and_their_occupancy():
    # task blocks {0,1} and {2,3}; column 1 loses more than L in task block 0
    p = layer([0, 0, 0, 0], [[False, True]])
    est = expected_time([task(Q, D, labels=[0, 0, 1, 1])], p, c=1.0, n_primitives=A)
    # refined once, n = 2 task blocks, |O_B| + A = 2
    assert est.total == pytest.approx(1 + 2**2 * 2)


def test_importance_weights_average_the_tasks():
    p = layer([0, 0, 1, 1], [[False, True], [True, False]])
    a = task(Q, D, weight=3.0)
    b = task(np.fliplr(np.asarray(Q)), D, weight=1.0)  # column 1 now best: block 1 lacks it
    ea = expected_time([a], p, n_primitives=A, c=1.0).total
    eb = expected_time([b], p, n_primitives=A, c=1.0).total
    assert expected_time([a, b], p, n_primitives=A, c=1.0).total == pytest.approx((3 * ea + eb) / 4)


def test_t_conv_matches_c_p2_o_for_uniform_sets():
    p = layer([0, 1, 2, 2], [[True, True]] * 3)
    assert t_conv(p, c=0.5) == pytest.approx(0.5 * 9 * 2)


def test_errors_name_the_problem():
    p = layer([0, 0, 1, 1], [[True, False], [True, False]])
    with pytest.raises(TaskError, match="same columns"):
        expected_time([task(np.zeros((4, 3)), D)], p, n_primitives=A, c=1.0)
    with pytest.raises(TaskError, match="at least one"):
        expected_time([], p, n_primitives=A, c=1.0)
    with pytest.raises(TaskError, match="n_primitives"):
        expected_time([task(Q, D)], p, n_primitives=3, c=1.0)
    with pytest.raises(TaskError, match="occupancy"):
        task(Q, [0.0, 0.0, 0.0, 0.0])
    with pytest.raises(TaskError, match="positive"):
        expected_time([task(Q, D)], p, c=0.0, n_primitives=A)

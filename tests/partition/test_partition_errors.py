"""Bad input gives clear AdpartErrors naming the problem and the fix."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from adpart.errors import ModelError
from adpart.mdp.model import SMDPModel
from adpart.partition import (
    MultiPhasePartitioner,
    Partition,
    check_stability,
    exact_lumping,
    phase1,
    phase2,
    refine,
)
from tests.partition.example_grid import slide_options


@pytest.fixture
def grid():
    return slide_options(["....", "...G"])


@pytest.mark.parametrize("delta", [-0.1, 1.5, float("nan"), "0.3"])
def test_delta_outside_unit_interval(grid, delta):
    model = grid[0]
    with pytest.raises(ModelError, match="delta"):
        refine(Partition.trivial(model.admissible), model, delta=delta)
    with pytest.raises(ModelError, match="delta"):
        MultiPhasePartitioner(model, grid[2], delta=delta)
    with pytest.raises(ModelError, match="delta"):
        check_stability(Partition.trivial(model.admissible), model, delta=delta)


@pytest.mark.parametrize("epsilon", [-1.0, float("inf")])
def test_negative_epsilon(grid, epsilon):
    model = grid[0]
    with pytest.raises(ModelError, match="epsilon"):
        refine(Partition.trivial(model.admissible), model, delta=0.3, epsilon=epsilon)


def test_shape_mismatches(grid):
    model, _cells, term, _goal = grid
    small = Partition.trivial(np.ones((3, 4), dtype=bool))
    with pytest.raises(ModelError, match="has 3 states but the model has"):
        refine(small, model, delta=0.0)
    with pytest.raises(ModelError, match="task rewards have shape"):
        refine(Partition.trivial(model.admissible), model, delta=0.0, epsilon=1.0,
               rewards=np.zeros((2, 2)))
    with pytest.raises(ModelError, match="termination must be a boolean"):
        MultiPhasePartitioner(model, term[:, :2], delta=0.0)
    with pytest.raises(ModelError, match="termination mask of option 0"):
        phase1(model, 0, term[:3, 0], delta=0.0)
    bad = SMDPModel(R=model.R, F=sp.csr_array((3, 3)), admissible=model.admissible)
    with pytest.raises(ModelError, match="model F has shape"):
        exact_lumping(bad)


def test_missing_models(grid):
    model, _cells, term, _goal = grid
    with pytest.raises(ModelError, match="no option models"):
        refine(Partition.trivial(model.admissible), None, delta=0.0)
    with pytest.raises(ModelError, match="option index 7 has no model"):
        refine(Partition.trivial(model.admissible), model, options=[0, 7], delta=0.0)
    with pytest.raises(ModelError, match="no phase-1 partition for option"):
        phase2(model, {0: phase1(model, 0, term[:, 0], delta=0.0)}, [0, 1], delta=0.0)
    with pytest.raises(ModelError, match="expected an SMDPModel"):
        exact_lumping(object())


def test_option_set_leaving_a_state_without_options():
    S = 3
    F = sp.csr_array((np.full(3, 0.9), ([0, 1, 5], [1, 2, 2])), shape=(2 * S, S))
    adm = np.array([[True, False], [True, False], [False, True]])
    model = SMDPModel(R=np.zeros((S, 2)), F=F, admissible=adm)
    msg = r"leaves 1 state\(s\) with no admissible option \(first: state 2\)"
    with pytest.raises(ModelError, match=msg):
        refine(Partition.trivial(adm), model, options=[0], delta=0.0)
    with pytest.raises(ModelError, match="no admissible option"):
        exact_lumping(model, options=[0])
    assert refine(Partition.trivial(adm), model, options=[0, 1], delta=0.0).n_blocks >= 2

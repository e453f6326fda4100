"""The built-in partition criteria register through the hook and refine as documented."""

from __future__ import annotations

import numpy as np

from adpart.partition import Partition, check_stability, exact_lumping
from adpart.plugins.builtin import criteria
from adpart.plugins.manager import PluginManager, build_registry
from tests.partition.example_grid import slide_options


def _registry():
    pm = PluginManager()
    pm.register_checked(criteria, "criteria", "adpart", "test")
    return build_registry(pm)


def test_criteria_are_registered_with_params():
    reg = _registry()
    names = set(reg.names("partition-criterion"))
    assert {"bisimulation", "reward", "termination", "exact-lumping"} <= names
    spec = reg.get("partition-criterion", "bisimulation")
    assert {p.name for p in spec.params} >= {"delta", "reward-epsilon"}


def test_criteria_refine_a_partition():
    model, _cells, term, _goal = slide_options([".....", ".#...", ".#..G", "....."])
    reg = _registry()
    start = Partition.trivial(model.admissible)
    bis = reg.get("partition-criterion", "bisimulation").create(
        {"delta": 0.5, "reward-epsilon": 1.0})
    part = bis.refine(start, model, rewards=model.R)
    assert check_stability(part, model, delta=0.5, epsilon=1.0)
    rew = reg.get("partition-criterion", "reward").create({"reward-epsilon": 1.0}).refine(
        start, model)
    assert check_stability(rew, model, delta=1.0, epsilon=1.0)
    term_part = reg.get("partition-criterion", "termination").create().refine(
        start, model, termination=term, options=[0])
    assert term_part.n_blocks == 2
    lump = reg.get("partition-criterion", "exact-lumping").create().refine(start, model)
    assert lump == exact_lumping(model)
    assert np.array_equal(lump.labels, exact_lumping(model).labels)

"""Report files load in strict parsers; default output folders need no quoting."""

from __future__ import annotations

import json

import numpy as np
import pytest

from adpart.workflows.reports import folder_name, strict_json


def _strict_loads(text: str):
    def refuse(constant: str):
        raise ValueError(f"non-standard JSON constant {constant}")

    return json.loads(text, parse_constant=refuse)


def test_non_finite_numbers_become_null_and_numpy_values_plain():
    data = {"never": float("inf"), "nan": np.float64("nan"), "n": np.int64(3),
            "runs": np.array([1.5, np.inf]), "nested": [{"x": -np.inf}]}
    assert _strict_loads(strict_json(data)) == {
        "never": None, "nan": None, "n": 3, "runs": [1.5, None], "nested": [{"x": None}]}
    with pytest.raises(ValueError, match="Infinity"):
        _strict_loads(json.dumps({"x": float("inf")}))  # what the strict parser refuses


@pytest.mark.parametrize(("parts", "name"), [
    (("two-rooms", "goal:x=9,y=5"), "two-rooms_goal-x-9-y-5"),
    (("gym:FrozenLake-v1[map_name=4x4]",), "gym-FrozenLake-v1-map_name-4x4"),
    (("three-floor", "reach-goal", "q-learning", "seed0"),
     "three-floor_reach-goal_q-learning_seed0"),
])
def test_folder_names_keep_only_safe_characters(parts, name):
    assert folder_name(*parts) == name

"""Sweep configuration: validation errors name the key; cells are enumerated deterministically."""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict

import pytest

from adpart.workflows.sweep import SweepConfigError, cell_key, load_config, parse_config, plan_cells

BASE = {"seeds": [0, 1], "environments": ["two-rooms"], "runs": 1, "episodes": 5}


def _plan(**overrides):
    return plan_cells(parse_config({**BASE, **overrides}, source="t.toml"))


@pytest.mark.parametrize(
    ("overrides", "key"),
    [
        ({"seed": 3}, "seed`.*Did you mean `seeds`"),
        ({"runs": 0}, "runs"),
        ({"episodes": True}, "episodes"),
        ({"seeds": [0, -1]}, r"seeds\[1\]"),
        ({"seeds": []}, "seeds"),
        ({"environments": []}, "environments"),
        ({"environments": ["two-rooms", {"name": "four-rooms", "task": "G1"}]},
         r"environments\[1\]\.task`"),
        ({"environments": [{"tasks": ["G1"]}]}, r"environments\[0\]\.name"),
        ({"params": {"alpha": []}}, r"params\.alpha"),
        ({"params": {"alpha": [{"x": 1}]}}, r"params\.alpha"),
    ],
)
def test_sweep_config_errors_name_the_key(overrides, key):
    with pytest.raises(SweepConfigError, match=f"t.toml: `{key}"):
        parse_config({**BASE, **overrides}, source="t.toml")


def test_sweep_config_missing_keys_are_named():
    with pytest.raises(SweepConfigError, match="`environments` is missing"):
        parse_config({"seeds": 1})


@pytest.mark.parametrize(
    ("overrides", "key"),
    [
        ({"learner": "q-lerning"}, "learner`.*Did you mean 'q-learning'"),
        ({"environments": ["two-room"]}, r"environments\[0\]`.*two-room"),
        ({"environments": [{"name": "four-rooms", "tasks": ["G9"]}]},
         r"environments\[0\]\.tasks\[0\]"),
        ({"params": {"gamma": 0.9}}, r"params\.gamma`.*no parameter --gamma"),
        ({"params": {"max_steps": [10, 0]}}, r"params\.max_steps`.*>= 1"),
    ],
)
def test_sweep_plan_errors_name_the_key(overrides, key):
    with pytest.raises(SweepConfigError, match=key):
        _plan(**overrides)


def test_sweep_bad_toml_and_missing_file_are_explained(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("seeds = [0, 1\n")
    with pytest.raises(SweepConfigError, match="not valid TOML"):
        load_config(bad)
    with pytest.raises(SweepConfigError, match="cannot read"):
        load_config(tmp_path / "missing.toml")


def test_sweep_cells_enumerate_the_grid_in_file_order():
    cells = _plan(
        environments=["two-rooms", {"name": "four-rooms", "tasks": ["G2", "G1"]}],
        params={"alpha": ["0.1", "0.5"], "epsilon": "0.2"},
        seeds=3,
    )
    grid = [(c.request.env, c.request.task, c.request.params["alpha"], c.request.seed)
            for c in cells]
    expected = [(e, t, a, s) for e, t in (("two-rooms", "reach-goal"), ("four-rooms", "G2"),
                                          ("four-rooms", "G1"))
                for a in ("0.1", "0.5") for s in (0, 1, 2)]
    assert grid == expected
    assert [c.index for c in cells] == list(range(18))
    assert all(c.request.params["epsilon"] == "0.2" for c in cells)
    # defaults are filled in, so the request (and its key) is fully explicit
    assert cells[0].request.params["max_steps"] == 1000
    assert cells[0].label == "two-rooms/reach-goal alpha=0.1 seed=0"
    assert [c.key for c in cells] == [c.key for c in _plan(
        environments=["two-rooms", {"name": "four-rooms", "tasks": ["G2", "G1"]}],
        params={"alpha": ["0.1", "0.5"], "epsilon": "0.2"}, seeds=3)]


def test_sweep_cell_key_is_the_hash_of_the_canonical_request():
    cell = _plan()[0]
    text = json.dumps(cell.request.to_dict(), sort_keys=True, separators=(",", ":"))
    assert cell.key == hashlib.sha256(text.encode()).hexdigest()
    assert cell_key(json.loads(json.dumps(asdict(cell.request)))) == cell.key
    assert len({c.key for c in _plan(seeds=[0, 1, 1, 0])}) == 2  # duplicates collapse


def test_sweep_config_file_accepts_hyphenated_keys(tmp_path):
    path = tmp_path / "grid.toml"
    path.write_text('seeds = 2\nenvironments = ["two-rooms"]\neval-every = 5\n'
                    '[params]\nalpha = ["0.1", "0.2"]\n')
    config = load_config(path)
    assert config.eval_every == 5 and config.name == "grid" and config.seeds == (0, 1)

"""The renderer: PNGs with each overlay kind, per-cell reductions, extras and bad overlays."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pytest
import scipy.sparse as sp

from adpart.envs.base import Domain, Dynamics, GoalSpec, TaskFactory
from adpart.envs.domains.four_rooms import FourRooms
from adpart.envs.domains.three_floor import ThreeFloorArm
from adpart.envs.domains.two_rooms import TwoRooms
from adpart.envs.render import label_colours, render_domain
from adpart.errors import ModelError

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def is_png(path) -> bool:
    return path.exists() and path.read_bytes()[:8] == PNG_MAGIC


@pytest.fixture(scope="module")
def four_rooms() -> FourRooms:
    return FourRooms()


@pytest.mark.parametrize("overlay", ["none", "values", "marked", "labels", "all"])
def test_each_overlay_writes_a_png(tmp_path, four_rooms, overlay: str) -> None:
    S = four_rooms.n_states
    kwargs = {
        "values": np.linspace(0.0, 1.0, S),
        "marked": four_rooms.dynamics().features["hallway"] == 1,
        "labels": np.arange(S) % 5,
    }
    chosen = kwargs if overlay == "all" else {k: v for k, v in kwargs.items() if k == overlay}
    path = tmp_path / f"{overlay}.png"
    fig = four_rooms.render(str(path), title=overlay, **chosen)
    assert is_png(path)
    assert fig._suptitle.get_text() == overlay
    if "values" in chosen:
        assert len(fig.axes) == 2  # the panel and its colour bar


def test_factored_states_reduce_per_cell(tmp_path) -> None:
    d = ThreeFloorArm()
    f = d.dynamics().features
    fig = render_domain(
        d, tmp_path / "arm.png", values=f["holding"].astype(float), marked=f["holding"] == 1,
        labels=f["object"],
    )
    assert is_png(tmp_path / "arm.png")
    panels = [ax for ax in fig.axes if ax.get_title().startswith("floor")]
    assert len(panels) == 3
    shown = panels[0].images[-1].get_array()  # the value layer of floor 0
    free = d.layout()[0]
    assert np.all(shown[free] == 1.0)  # max over the factored states of each cell
    assert shown.mask[~free].all()
    markers = panels[0].collections[-1].get_offsets()
    assert len(markers) == free.sum()  # any over the factored states


def test_labels_use_the_first_state_of_each_cell(tmp_path) -> None:
    d = TwoRooms()
    labels = np.zeros(d.n_states, dtype=np.int64)
    labels[d.cell_state(x=8, y=1)] = 7
    fig = render_domain(d, labels=labels)
    rgb = fig.axes[0].images[0].get_array()
    colours = label_colours(2)
    assert np.allclose(rgb[1, 8], colours[1]) and np.allclose(rgb[5, 0], colours[0])
    assert np.allclose(rgb[0, 5], rgb[1, 5])  # walls keep the wall colour


def test_many_labels_get_distinct_colours() -> None:
    colours = label_colours(63)
    assert len({tuple(c.round(6)) for c in colours}) == 63


def test_bad_overlay_shape_is_a_model_error(four_rooms) -> None:
    with pytest.raises(ModelError, match=r"values has shape \(3,\); give one entry per state"):
        render_domain(four_rooms, values=np.zeros(3))


class Line(Domain):
    """A domain without layout(): walls are inferred from the occupied cells."""

    name = "line"

    def __init__(self) -> None:
        self.extras: list[int] = []

    def _build_dynamics(self) -> Dynamics:
        P = sp.csr_array(np.eye(3))
        return Dynamics(P=P, action_names=("stay",), action_costs=np.zeros(1),
                        features={"x": np.array([0, 2, 3]), "y": np.array([0, 0, 1])})

    def tasks(self) -> Mapping[str, TaskFactory | GoalSpec]:
        return {"end": GoalSpec(goal={"x": 3})}

    def draw_extras(self, ax, floor: int) -> None:
        self.extras.append(floor)


def test_domain_without_layout_and_with_extras(tmp_path) -> None:
    d = Line()
    fig = d.render(str(tmp_path / "line.png"), marked=np.array([True, False, False]))
    assert is_png(tmp_path / "line.png")
    assert d.extras == [0]
    rgb = fig.axes[0].images[0].get_array()
    assert rgb.shape == (2, 4, 3)
    assert rgb[0, 1].sum() < rgb[0, 0].sum()  # (1, 0) holds no state: drawn as wall


def test_domain_without_coordinates_is_refused() -> None:
    class NoXY(Line):
        def _build_dynamics(self) -> Dynamics:
            return Dynamics(P=sp.csr_array(np.eye(1)), action_names=("stay",),
                            action_costs=np.zeros(1))

    with pytest.raises(ModelError, match="no x and y state features"):
        render_domain(NoXY())


def test_the_goal_and_start_letters_are_the_drawn_tasks():
    """Read back the letters: a custom goal is lettered where it is, not at the map's G."""
    from adpart.envs.registry import get_domain

    domain = get_domain("two-rooms")

    def letters(fig, letter):
        return sorted(tuple(int(v) for v in t.get_position())
                      for t in fig.axes[0].texts if t.get_gid() == letter)

    custom = domain.render(task="goal:x=9,y=5")
    assert letters(custom, "G") == [(9, 5)]
    task = domain.task(None)
    default = domain.render()
    feats = domain.dynamics().features
    goal = np.flatnonzero(task.terminal)
    assert letters(default, "G") == sorted(zip(feats["x"][goal].tolist(),
                                               feats["y"][goal].tolist(), strict=True))
    start = np.flatnonzero(task.initial > 0)
    assert letters(default, "S") == sorted(zip(feats["x"][start].tolist(),
                                               feats["y"][start].tolist(), strict=True))
    assert letters(default, "G") != letters(custom, "G")

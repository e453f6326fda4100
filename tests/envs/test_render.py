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
    assert not np.allclose(rgb[1, 8], rgb[5, 0])  # the one-cell block stands out
    assert np.allclose(rgb[1, 7], rgb[5, 0])  # its neighbour belongs to the big block
    assert np.allclose(rgb[0, 5], rgb[1, 5])  # walls keep the wall colour


def _touching_pairs(grid: np.ndarray) -> set[tuple[int, int]]:
    """Independent of the renderer: every pair of labels on neighbouring cells."""
    pairs = set()
    F, H, W = grid.shape
    for f in range(F):
        for y in range(H):
            for x in range(W):
                for dy, dx in ((0, 1), (1, 0)):
                    if y + dy < H and x + dx < W:
                        a, b = grid[f, y, x], grid[f, y + dy, x + dx]
                        if a >= 0 and b >= 0 and a != b:
                            pairs.add((min(a, b), max(a, b)))
    return pairs


def test_touching_blocks_never_share_a_colour():
    """The 48-block layer problem: many blocks, a short palette. Read each floor's pixels back
    and check that no two neighbouring cells of different blocks have one colour."""
    from adpart.envs.domains.three_floor import ThreeFloor

    d = ThreeFloor()
    f = d.dynamics().features
    x, y, fl = (np.asarray(f[k], dtype=np.int64) for k in ("x", "y", "floor"))
    labels = (x // 4) * 100 + (y // 3) * 10 + fl  # rectangles: ~50 blocks, many neighbours
    fig = render_domain(d, labels=labels)
    panels = [ax for ax in fig.axes if ax.get_title().startswith("floor")]
    free = d.layout()
    grid = np.full(free.shape, -1, dtype=np.int64)
    grid[fl, y, x] = labels
    for floor, ax in enumerate(panels):
        rgb = ax.images[0].get_array()
        for a, b in _touching_pairs(grid[floor:floor + 1]):
            ya, xa = np.argwhere(grid[floor] == a)[0]
            yb, xb = np.argwhere(grid[floor] == b)[0]
            assert not np.allclose(rgb[ya, xa], rgb[yb, xb]), (floor, a, b)
    assert len(np.unique(labels)) > 12  # more blocks than the palette's colours


def test_map_colouring_is_proper_and_spreads_small_partitions():
    from adpart.plotting import block_adjacency, map_colouring

    rng = np.random.default_rng(3)
    grid = rng.integers(0, 30, size=(1, 12, 12))
    pairs = _touching_pairs(grid)
    assert {tuple(p) for p in block_adjacency(grid).tolist()} == pairs
    colour = map_colouring(30, block_adjacency(grid))
    assert all(colour[a] != colour[b] for a, b in pairs)
    few = map_colouring(5, np.array([[0, 1], [1, 2]]))
    assert len(set(few.tolist())) == 5  # up to the palette's size every block has its own


def test_every_marker_has_a_legend_entry():
    """Subgoal dots, the goal and start letters and the stairs arrows are named below the map;
    the colour bar names what the values are."""
    from adpart.envs.domains.three_floor import ThreeFloor

    d = ThreeFloor()
    marked = np.zeros(d.n_states, dtype=bool)
    marked[:3] = True
    fig = d.render(marked=marked, values=np.arange(d.n_states, dtype=float),
                   task="reach-top-west", value_label="count score", mark_label="subgoals")
    (legend,) = [lg for lg in fig.legends if lg.get_gid() == "map-legend"]
    names = [t.get_text() for t in legend.get_texts()]
    for name in ("subgoals", "goal of reach-top-west", "start of reach-top-west", "stairs up",
                 "stairs down"):
        assert name in names, names
    drawn = {t.get_text() for ax in fig.axes for t in ax.texts if t.get_gid() == "stairs"}
    assert drawn <= {"↑", "↓", "↕"} and drawn
    assert any(ax.get_ylabel() == "count score" for ax in fig.axes)  # the colour bar


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

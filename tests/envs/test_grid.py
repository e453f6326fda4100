"""The map language: parsing, errors, and compiled dynamics against a loop-by-loop oracle."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from adpart.envs.grid import MOVES_4, MOVES_8, GridMap, Slip, grid_dynamics
from adpart.errors import MapError
from adpart.mdp.model import FiniteMDP

TWO_FLOORS = """
--- floor 0 ---
#####
#S.H#
#0..#
#####
--- floor 1 ---
#####
#..H#
#.1G#
#####
"""


def oracle_P(chars: np.ndarray, moves: tuple, slip: Slip) -> np.ndarray:
    """Dense ``P[a, c, c']`` of the compass moves on one floor, built cell by cell."""
    H, W = chars.shape
    cells = [(y, x) for y in range(H) for x in range(W) if chars[y, x] != "#"]
    index = {c: i for i, c in enumerate(cells)}
    M, C = len(moves), len(cells)
    out = np.zeros((M, C, C))
    for a in range(M):
        for d in range(M):
            if slip.kind == "deterministic":
                q = 1.0 if d == a else 0.0
            elif slip.kind == "uniform":
                q = slip.p if d == a else (1 - slip.p) / (M - 1)
            elif d == a:
                q = slip.p
            else:
                side = (d - a) % M in (M // 4, 3 * M // 4)
                q = (1 - slip.p) / 2 if side else 0.0
            for (y, x), i in index.items():
                _, dx, dy = moves[d]
                j = index.get((y + dy, x + dx), i)
                out[a, i, j] += q
    return out


class TestParse:
    def test_cells_are_floor_major_row_major(self) -> None:
        g = GridMap.parse(TWO_FLOORS)
        assert g.shape == (2, 4, 5)
        assert g.n_cells == 12
        f, y, x = g.cell_coords
        assert list(zip(f[:3], y[:3], x[:3], strict=True)) == [(0, 1, 1), (0, 1, 2), (0, 1, 3)]
        assert g.cell_index[1, 2, 3] == 11
        assert g.object_sites.tolist() == [3, 10]

    def test_indented_text_and_blank_lines_are_accepted(self) -> None:
        g = GridMap.parse("\n    ###\n\n    #S#\n    ###\n")
        assert g.shape == (1, 3, 3)

    def test_stair_links(self) -> None:
        g = GridMap.parse(TWO_FLOORS)
        up, down = g.stair_links
        assert up[g.cell_index[0, 1, 3]] == g.cell_index[1, 1, 3]
        assert down[g.cell_index[1, 1, 3]] == g.cell_index[0, 1, 3]
        assert (up >= 0).sum() == 1 and (down >= 0).sum() == 1


class TestMapErrors:
    @pytest.mark.parametrize(
        ("text", "needle"),
        [
            ("###\n#x#\n###", "line 2, column 2: unknown character 'x'"),
            ("###\n#.##\n###", "ragged"),
            ("", "empty"),
            ("\n\n", "empty"),
            ("###\n###", "no free cell"),
            ("#####\n#S#G#\n#####", "cannot be reached from the start"),
            ("###\n#H#\n###\n---\n###\n#.#\n###", "stair H has no partner"),
            ("###\n#.#\n---\n###", "different heights"),
            ("#####\n#0.0#", "appears 2 times"),
            ("#####\n#0.2#", "site 1 is missing"),
            ("###\n#.#\n---\n---\n###\n#.#", "has no rows"),
        ],
    )
    def test_each_problem_is_named(self, text: str, needle: str) -> None:
        with pytest.raises(MapError) as err:
            grid_dynamics(GridMap.parse(text))
        assert needle in str(err.value)

    def test_unreachable_goal_names_its_cell(self) -> None:
        with pytest.raises(MapError, match=r"line 3, column 4 \(x=3, y=1, floor=0\): goal G"):
            grid_dynamics(GridMap.parse("\n#####\n#S#G#\n#####"))

    def test_unreachable_object_site(self) -> None:
        with pytest.raises(MapError, match="object site cannot be reached"):
            grid_dynamics(GridMap.parse("#####\n#S#0#\n#####"))

    def test_diagonal_moves_can_make_a_goal_reachable(self) -> None:
        text = "S#\n#G"
        with pytest.raises(MapError):
            grid_dynamics(GridMap.parse(text), connectivity=4)
        assert grid_dynamics(GridMap.parse(text), connectivity=8).n_states == 2

    def test_bad_options(self) -> None:
        g = GridMap.parse("S.")
        with pytest.raises(MapError, match="connectivity"):
            grid_dynamics(g, connectivity=6)
        with pytest.raises(MapError, match="unknown slip model"):
            grid_dynamics(g, slip=Slip("wobbly", 0.5))
        with pytest.raises(MapError, match="outside"):
            grid_dynamics(g, slip=Slip("uniform", 1.5))
        with pytest.raises(MapError, match="unknown action"):
            grid_dynamics(g, costs={"Jump": -2.0})


class TestSlip:
    def test_perpendicular_four(self) -> None:
        m = Slip("perpendicular", 0.8).outcome_matrix(4)  # N E S W
        assert np.allclose(m[0], [0.8, 0.1, 0.0, 0.1])

    def test_perpendicular_eight(self) -> None:
        m = Slip("perpendicular", 0.5).outcome_matrix(8)  # N NE E SE S SW W NW
        assert np.allclose(m[1], [0, 0.5, 0, 0.25, 0, 0, 0, 0.25])

    def test_uniform_four_rooms_noise(self) -> None:
        m = Slip("uniform", 2 / 3).outcome_matrix(4)
        assert np.allclose(np.diag(m), 2 / 3)
        assert np.allclose(m[~np.eye(4, dtype=bool)], 1 / 9)


free_masks = st.integers(2, 5).flatmap(
    lambda h: st.integers(2, 5).flatmap(
        lambda w: st.lists(st.booleans(), min_size=h * w, max_size=h * w).map(
            lambda cells: np.array(cells).reshape(h, w)
        )
    )
).filter(lambda m: m.any())


@given(
    free=free_masks,
    connectivity=st.sampled_from([4, 8]),
    slip=st.sampled_from(
        [Slip(), Slip("perpendicular", 0.8), Slip("uniform", 2 / 3), Slip("perpendicular", 0.5)]
    ),
)
def test_dynamics_match_cell_by_cell_oracle(free, connectivity, slip) -> None:
    chars = np.where(free, ".", "#")
    g = GridMap.parse("\n".join("".join(r) for r in chars))
    dyn = grid_dynamics(g, connectivity=connectivity, slip=slip)
    moves = MOVES_4 if connectivity == 4 else MOVES_8
    C = g.n_cells
    dense = dyn.P.toarray().reshape(len(moves), C, C)
    assert np.allclose(dense, oracle_P(chars, moves, slip))
    FiniteMDP(dyn.P, np.zeros((C, len(moves))), 0.9)  # validates row sums


class TestFactoredDynamics:
    def dyn(self):
        return grid_dynamics(GridMap.parse(TWO_FLOORS), arm=True)

    def test_state_count_and_action_names(self) -> None:
        dyn = self.dyn()
        assert dyn.n_states == 12 * 2 * 3
        assert dyn.action_names == (
            "GoNorth", "GoEast", "GoSouth", "GoWest", "GoUp", "GoDown",
            "OpenArm", "CloseArm", "Pickup", "Drop",
        )
        FiniteMDP(dyn.P, np.zeros((dyn.n_states, 10)), 0.9, admissible=dyn.admissible)

    def step(self, dyn, s: int, action: str) -> int:
        a = dyn.action_names.index(action)
        row = dyn.P[[a * dyn.n_states + s]].toarray().ravel()
        assert row.max() == 1.0
        return int(row.argmax())

    def state(self, dyn, *, x: int, y: int, floor: int, arm: int, obj: int) -> int:
        f = dyn.features
        match = (f["x"] == x) & (f["y"] == y) & (f["floor"] == floor) & (f["arm"] == arm)
        return int(np.flatnonzero(match & (f["object"] == obj))[0])

    def test_pickup_needs_an_open_arm_at_the_object(self) -> None:
        dyn = self.dyn()
        s = self.state(dyn, x=1, y=2, floor=0, arm=0, obj=0)
        assert self.step(dyn, s, "Pickup") == s  # arm closed
        opened = self.step(dyn, s, "OpenArm")
        held = self.step(dyn, opened, "Pickup")
        assert dyn.features["holding"][held] == 1 and dyn.features["arm"][held] == 1
        away = self.state(dyn, x=2, y=2, floor=0, arm=1, obj=0)
        assert self.step(dyn, away, "Pickup") == away  # not at the object

    def test_drop_only_on_a_site_and_stairs_carry_the_object(self) -> None:
        dyn = self.dyn()
        s = self.state(dyn, x=3, y=1, floor=0, arm=0, obj=2)
        assert self.step(dyn, s, "Drop") == s  # a stair, not a site
        up = self.step(dyn, s, "GoUp")
        assert (dyn.features["floor"][up], dyn.features["holding"][up]) == (1, 1)
        site = self.step(dyn, self.step(dyn, up, "GoSouth"), "GoWest")
        dropped = self.step(dyn, site, "Drop")
        assert dyn.features["object"][dropped] == 1

    def test_stair_actions_admissible_only_where_they_move(self) -> None:
        dyn = self.dyn()
        up, down = dyn.action_names.index("GoUp"), dyn.action_names.index("GoDown")
        stair, fl = dyn.features["stair"] == 1, dyn.features["floor"]
        assert np.array_equal(dyn.admissible[:, up], stair & (fl == 0))
        assert np.array_equal(dyn.admissible[:, down], stair & (fl == 1))
        assert dyn.admissible[:, :4].all() and dyn.admissible[:, 6:].all()

    def test_start_is_the_S_cell_with_object_at_site_0_and_arm_closed(self) -> None:
        dyn = self.dyn()
        (s,) = np.flatnonzero(dyn.start)
        f = dyn.features
        assert (f["x"][s], f["y"][s], f["floor"][s], f["arm"][s], f["object"][s]) == (1, 1, 0, 0, 0)

    def test_walls_and_map_edges_keep_the_agent_in_place(self) -> None:
        dyn = grid_dynamics(GridMap.parse("S."))
        P = dyn.P.toarray().reshape(4, 2, 2)
        assert P[0, 0, 0] == 1 and P[3, 0, 0] == 1 and P[1, 0, 1] == 1 and P[1, 1, 1] == 1

    def test_features_are_per_state(self) -> None:
        dyn = self.dyn()
        for key in ("x", "y", "floor", "door", "stair", "goal", "arm", "object", "holding"):
            assert dyn.features[key].shape == (dyn.n_states,)
        assert set(itertools.chain(dyn.features["object"].tolist())) == {0, 1, 2}

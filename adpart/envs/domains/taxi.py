"""Dietterich's Taxi domain (Dietterich 2000, JAIR 13; dissertation section 3.4.1, Fig. 3.7).

A taxi moves on a 5x5 grid with thin walls between some cells, picks up a passenger waiting at one
of four landmarks (R, G, Y, B) and puts them down at their destination, another landmark::

    +---------+
    |R: | : :G|
    | : | : : |
    | : : : : |
    | | : | : |
    |Y| : |B: |
    +---------+

``|`` is a wall between two cells, ``:`` a passable boundary. The 500 states use Gymnasium's
encoding ``((row * 5 + col) * 5 + passenger) * 4 + destination`` (passenger 0-3 = waiting at a
landmark, 4 = in the taxi) and the actions Gymnasium's order: South, North, East, West, Pickup,
Putdown. So a state or action index means the same here and in ``gymnasium.make("Taxi-v4")``.

Rewards (the ``deliver`` task): -1 per action, +20 (instead of -1) for the Putdown that delivers
the passenger - the episode ends on arrival in the delivered state - and -10 for an illegal
Pickup or Putdown. A move into a wall or off the grid is a no-op costing -1.

Two choices are parameters:

* ``putdown="dietterich"`` (default): a Putdown at a landmark that is not the destination is
  illegal (-10) and the passenger stays in the taxi, as in Dietterich's paper, whose MAXQ
  hierarchy (Root -> Get, Put) the dissertation uses: the Put subtask ends only at the
  destination, so the passenger can never be re-seated at another landmark mid-episode.
  ``putdown="gymnasium"`` puts the passenger down at that landmark for -1 (Gymnasium's ``P``).
* ``slip=True``: each move succeeds w.p. 0.8 and goes to each perpendicular side w.p. 0.1; each
  outcome blocked by a wall stays put (Dietterich's noisy moves). This is only the *move* half of
  Dietterich's fickle Taxi: the destination change after pickup needs a state flag ("has the taxi
  moved away from the source yet") that the 500-state encoding lacks, so it is not modelled here.
  Gymnasium's ``is_rainy`` differs in one point: when the intended move is blocked it keeps the
  taxi in place with probability 1 (no sideways slip).

The discount defaults to ``gamma = 0.95``. Dietterich used undiscounted returns (gamma = 1),
which FiniteMDP accepts too (``Taxi(gamma=1.0)``); 0.95 keeps every Bellman operator a
contraction so the solvers' epsilon-optimality bounds and the partition error bounds of chapter
4 are finite, and it matches the discount of the other built-in domains.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from adpart.envs.base import Domain, Dynamics, GoalSpec, Task, TaskFactory
from adpart.errors import TaskError

if TYPE_CHECKING:
    from matplotlib.axes import Axes

#: The standard map (Dietterich 2000, Fig. 1; Gymnasium's ``MAP``).
MAP: tuple[str, ...] = (
    "+---------+",
    "|R: | : :G|",
    "| : | : : |",
    "| : : : : |",
    "| | : | : |",
    "|Y| : |B: |",
    "+---------+",
)
N_ROWS = N_COLS = 5
#: Landmarks as (row, col), in passenger/destination index order.
LANDMARKS: tuple[tuple[int, int], ...] = ((0, 0), (0, 4), (4, 0), (4, 3))
LANDMARK_NAMES: tuple[str, ...] = ("R", "G", "Y", "B")
IN_TAXI = 4
N_PASSENGER = 5
N_DEST = 4
N_STATES = N_ROWS * N_COLS * N_PASSENGER * N_DEST
ACTION_NAMES: tuple[str, ...] = ("South", "North", "East", "West", "Pickup", "Putdown")
SOUTH, NORTH, EAST, WEST, PICKUP, PUTDOWN = range(6)
#: (d_row, d_col) of each move action.
MOVES: tuple[tuple[int, int], ...] = ((1, 0), (-1, 0), (0, 1), (0, -1))
#: The two perpendicular directions of each move action (indices into MOVES).
PERPENDICULAR: tuple[tuple[int, int], ...] = ((EAST, WEST), (WEST, EAST), (NORTH, SOUTH),
                                              (SOUTH, NORTH))
STEP_REWARD = -1.0
DELIVERY_REWARD = 20.0
ILLEGAL_REWARD = -10.0
PUTDOWN_RULES = ("dietterich", "gymnasium")


def encode(row: np.ndarray, col: np.ndarray, passenger: np.ndarray, dest: np.ndarray) -> (
    np.ndarray
):
    """Gymnasium's state index ``((row * 5 + col) * 5 + passenger) * 4 + destination``."""
    return ((row * N_COLS + col) * N_PASSENGER + passenger) * N_DEST + dest


def decode(state: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(row, col, passenger, destination)`` of state indices (inverse of :func:`encode`)."""
    s = np.asarray(state)
    return s // (N_COLS * N_PASSENGER * N_DEST), (s // (N_PASSENGER * N_DEST)) % N_COLS, (
        s // N_DEST) % N_PASSENGER, s % N_DEST


def _walls() -> tuple[np.ndarray, np.ndarray]:
    """``(east_open, west_open)`` (5, 5) bool: can the taxi leave a cell eastwards / westwards."""
    desc = np.array([list(line) for line in MAP])
    interior = desc[1:-1]
    east_open = interior[:, 2:2 * N_COLS + 1:2] == ":"
    west_open = interior[:, 0:2 * N_COLS - 1:2] == ":"
    return east_open, west_open


class Taxi(Domain):
    """Dietterich's Taxi: 500 states in Gymnasium's encoding, 6 actions, task ``deliver``.

    Args:
        putdown: ``"dietterich"`` (default; a Putdown at a wrong landmark is illegal, -10, the
            passenger stays in the taxi) or ``"gymnasium"`` (the passenger gets out there, -1).
        slip: noisy moves, 0.8 intended and 0.1 to each perpendicular side.
        slip_probability: probability of the intended move when ``slip`` is on.
        gamma: discount factor of the ``deliver`` task.
    """

    name = "taxi"
    description = "Dietterich's 5x5 Taxi: pick up a passenger at a landmark and deliver them"
    source = "Dietterich 2000, JAIR 13 (MAXQ); Gymnasium Taxi-v4; dissertation section 3.4.1"
    default_task = "deliver"

    def __init__(
        self,
        *,
        putdown: str = "dietterich",
        slip: bool = False,
        slip_probability: float = 0.8,
        gamma: float = 0.95,
    ) -> None:
        if putdown not in PUTDOWN_RULES:
            raise TaskError(
                f"taxi putdown rule {putdown!r} is unknown; use 'dietterich' (wrong-landmark "
                "putdown is illegal) or 'gymnasium' (the passenger gets out there)"
            )
        if not 0.0 <= slip_probability <= 1.0:
            raise TaskError(
                f"slip_probability = {slip_probability!r} is not a probability; give a value in "
                "[0, 1] (0.8 in Dietterich's noisy Taxi)"
            )
        if not 0.0 < gamma <= 1.0:
            raise TaskError(f"gamma = {gamma!r} is outside (0, 1]; Taxi uses 0.95 by default")
        self.putdown = putdown
        self.slip = bool(slip)
        self.slip_probability = float(slip_probability)
        self.gamma = float(gamma)

    # ----------------------------------------------------------------------------- dynamics
    @staticmethod
    def _move(row: np.ndarray, col: np.ndarray, move: int) -> tuple[np.ndarray, np.ndarray]:
        """Cells after one move in direction ``move`` (walls and the border block: stay put)."""
        east_open, west_open = _walls()
        dr, dc = MOVES[move]
        if move == EAST:
            ok = east_open[row, col]
        elif move == WEST:
            ok = west_open[row, col]
        else:
            ok = (row + dr >= 0) & (row + dr < N_ROWS)
        return np.where(ok, row + dr, row), np.where(ok, col + dc, col)

    def _pickup_putdown(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Successors and rewards of Pickup and Putdown: ``(next_pick, r_pick, next_put, r_put)``.

        Vectorised over all 500 states; shared by the dynamics and the ``deliver`` rewards.
        """
        s = np.arange(N_STATES)
        row, col, passenger, dest = decode(s)
        lm_row = np.array([r for r, _ in LANDMARKS])
        lm_col = np.array([c for _, c in LANDMARKS])
        # index of the landmark under the taxi, -1 elsewhere
        at = (row[:, None] == lm_row) & (col[:, None] == lm_col)
        landmark = np.where(at.any(axis=1), at.argmax(axis=1), -1)
        in_taxi = passenger == IN_TAXI

        can_pick = (~in_taxi) & (landmark == passenger)
        next_pick = np.where(can_pick, encode(row, col, IN_TAXI, dest), s)
        r_pick = np.where(can_pick, STEP_REWARD, ILLEGAL_REWARD)

        deliver = in_taxi & (landmark == dest)
        elsewhere = in_taxi & (landmark >= 0) & ~deliver
        next_put = np.where(deliver, encode(row, col, dest, dest), s)
        r_put = np.where(deliver, DELIVERY_REWARD, ILLEGAL_REWARD)
        if self.putdown == "gymnasium":
            next_put = np.where(elsewhere, encode(row, col, landmark, dest), next_put)
            r_put = np.where(elsewhere, STEP_REWARD, r_put)
        return next_pick, r_pick, next_put, r_put

    def _build_dynamics(self) -> Dynamics:
        S = N_STATES
        s = np.arange(S)
        row, col, passenger, dest = decode(s)
        rows: list[np.ndarray] = []
        cols: list[np.ndarray] = []
        probs: list[np.ndarray] = []
        p_side = (1.0 - self.slip_probability) / 2.0
        for a in range(4):
            outcomes = [(a, self.slip_probability), *((side, p_side) for side in PERPENDICULAR[a])]
            if not self.slip:
                outcomes = [(a, 1.0)]
            for move, p in outcomes:
                if p == 0.0:
                    continue
                r2, c2 = self._move(row, col, move)
                rows.append(a * S + s)
                cols.append(encode(r2, c2, passenger, dest))
                probs.append(np.full(S, p))
        next_pick, _, next_put, _ = self._pickup_putdown()
        rows += [PICKUP * S + s, PUTDOWN * S + s]
        cols += [next_pick, next_put]
        probs += [np.ones(S), np.ones(S)]
        P = sp.csr_array(
            (np.concatenate(probs), (np.concatenate(rows), np.concatenate(cols))),
            shape=(len(ACTION_NAMES) * S, S),
        )
        P.sum_duplicates()
        features = {
            "x": col.astype(np.int64),
            "y": row.astype(np.int64),
            "taxi_row": row.astype(np.int64),
            "taxi_col": col.astype(np.int64),
            "passenger": passenger.astype(np.int64),
            "destination": dest.astype(np.int64),
            "in_taxi": (passenger == IN_TAXI).astype(np.int64),
        }
        return Dynamics(
            P=P,
            action_names=ACTION_NAMES,
            action_costs=np.full(len(ACTION_NAMES), STEP_REWARD),
            features=features,
            admissible=None,
            start=self.start_distribution(),
        )

    @staticmethod
    def start_distribution() -> np.ndarray:
        """Gymnasium's start distribution: uniform over taxi cell x passenger at a landmark x a
        different destination (300 states)."""
        _, _, passenger, dest = decode(np.arange(N_STATES))
        start = ((passenger < IN_TAXI) & (passenger != dest)).astype(np.float64)
        return start / start.sum()

    @staticmethod
    def delivered() -> np.ndarray:
        """``(S,)`` bool: the passenger was just put down at their destination (terminal).

        These are the 4 states (taxi on landmark ``d``, passenger at ``d``, destination ``d``)
        that the delivering Putdown enters - exactly the states Gymnasium's ``P`` flags as
        terminated. The other 96 states with passenger = destination are unreachable.
        """
        row, col, passenger, dest = decode(np.arange(N_STATES))
        lm_row = np.array([r for r, _ in LANDMARKS])
        lm_col = np.array([c for _, c in LANDMARKS])
        return (passenger == dest) & (row == lm_row[dest]) & (col == lm_col[dest])

    # -------------------------------------------------------------------------------- tasks
    def deliver_rewards(self) -> np.ndarray:
        """``(S, A)`` rewards of the ``deliver`` task (deterministic given ``(s, a)``)."""
        _, r_pick, _, r_put = self._pickup_putdown()
        R = np.full((N_STATES, len(ACTION_NAMES)), STEP_REWARD)
        R[:, PICKUP] = r_pick
        R[:, PUTDOWN] = r_put
        return R

    def _deliver(self, domain: Domain) -> Task:
        return Task(
            name="deliver",
            reward=self.deliver_rewards(),
            terminal=self.delivered(),
            initial=self.start_distribution(),
            gamma=self.gamma,
            description="pick the passenger up and put them down at their destination",
            spec={"kind": "taxi-deliver", "putdown": self.putdown, "slip": self.slip,
                  "slip_probability": self.slip_probability, "gamma": self.gamma},
        )

    def tasks(self) -> Mapping[str, TaskFactory | GoalSpec]:
        return {"deliver": self._deliver}

    # ------------------------------------------------------------------------------ drawing
    def layout(self) -> np.ndarray:
        """``(1, 5, 5)`` bool: every cell of the taxi grid is free (walls are thin)."""
        return np.ones((1, N_ROWS, N_COLS), dtype=bool)

    def draw_extras(self, ax: Axes, floor: int) -> None:
        """Draw the thin walls and the R/G/Y/B landmarks (cell centres at integer x, y)."""
        east_open, _ = _walls()
        for k in range(1, N_COLS):
            ax.axvline(k - 0.5, color="lightgray", linewidth=0.8, zorder=1)
            ax.axhline(k - 0.5, color="lightgray", linewidth=0.8, zorder=1)
        for r, c in np.argwhere(~east_open[:, : N_COLS - 1]):
            ax.plot([c + 0.5, c + 0.5], [r - 0.5, r + 0.5], color="black", linewidth=4,
                    solid_capstyle="butt", zorder=5)
        colors = ("tab:red", "tab:green", "gold", "tab:blue")
        for (r, c), label, color in zip(LANDMARKS, LANDMARK_NAMES, colors, strict=True):
            ax.text(c - 0.3, r - 0.22, label, color=color, fontsize=14, fontweight="bold",
                    ha="center", va="center", zorder=6)

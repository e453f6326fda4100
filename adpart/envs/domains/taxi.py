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
  outcome blocked by a wall stays put (Dietterich's noisy moves). Gymnasium's ``is_rainy``
  differs in one point: when the intended move is blocked it keeps the taxi in place with
  probability 1 (no sideways slip).
* ``fickle=True`` (Dietterich 2000, sec. 7.1; also the environment ``taxi-fickle``): noisy moves
  *and* a fickle passenger - after the pickup, on the first step on which the taxi actually
  leaves the source cell, the passenger changes destination with probability
  ``fickle_probability = 0.3``, to one of the *other* three landmarks uniformly (0.1 each; the
  rule of Gymnasium's ``fickle_passenger``). This is encoded in the model, not in a simulator:
  the change depends on "picked up, has not moved yet", which the 500-state encoding cannot
  express, so fickle Taxi has **516 states**: the 500 above plus 16 *pending* states
  ``500 + 4 * landmark + destination`` (passenger just picked up at ``landmark``, taxi still on
  it, destination not yet re-drawn). A legal Pickup enters a pending state; a move that leaves
  the cell resolves it (destination kept w.p. 0.7, each other landmark w.p. 0.1); a blocked move
  keeps it. Under the ``dietterich`` putdown rule the passenger is picked up once per episode, so
  the change can happen at most once, as in the paper; the ``gymnasium`` rule (re-pickups) is
  refused with fickle. Gymnasium's ``P`` omits the change altogether (it happens in ``step()``),
  so a model built from it is silently wrong for fickle Taxi. Feature ``pending`` (0/1) marks
  the 16 states; ``passenger`` is 4 (in the taxi) there.

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
#: Fickle Taxi: the 500 states plus one "just picked up" state per (landmark, destination).
N_PENDING = len(LANDMARKS) * N_DEST
N_STATES_FICKLE = N_STATES + N_PENDING
FICKLE_PROBABILITY = 0.3
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



def _features(row: np.ndarray, col: np.ndarray, passenger: np.ndarray, dest: np.ndarray
              ) -> dict[str, np.ndarray]:
    """The state features both taxi models expose (``x``/``y`` for the grid renderer)."""
    return {
        "x": col.astype(np.int64),
        "y": row.astype(np.int64),
        "taxi_row": row.astype(np.int64),
        "taxi_col": col.astype(np.int64),
        "passenger": passenger.astype(np.int64),
        "destination": dest.astype(np.int64),
        "in_taxi": (passenger == IN_TAXI).astype(np.int64),
    }


def _assemble(rows: list, cols: list, probs: list, S: int) -> sp.csr_array:
    """The (A*S, S) transition matrix from lists of (row, column, probability) array chunks."""
    P = sp.csr_array(
        (np.concatenate(probs), (np.concatenate(rows), np.concatenate(cols))),
        shape=(len(ACTION_NAMES) * S, S),
    )
    P.sum_duplicates()
    P.eliminate_zeros()
    return P

class Taxi(Domain):
    """Dietterich's Taxi: 500 states in Gymnasium's encoding, 6 actions, task ``deliver``.

    Args:
        putdown: ``"dietterich"`` (default; a Putdown at a wrong landmark is illegal, -10, the
            passenger stays in the taxi) or ``"gymnasium"`` (the passenger gets out there, -1).
        slip: noisy moves, 0.8 intended and 0.1 to each perpendicular side.
        slip_probability: probability of the intended move when ``slip`` is on.
        gamma: discount factor of the ``deliver`` task.
        fickle: Dietterich's fickle Taxi (516 states; implies ``slip``; see the module docstring).
        fickle_probability: probability that the passenger changes destination on the first
            move away from the source.
    """

    name = "taxi"
    description = "Dietterich's 5x5 Taxi: pick up a passenger at a landmark and deliver them"
    source = "Dietterich 2000, JAIR 13 (MAXQ); Gymnasium Taxi-v4; dissertation section 3.4.1"
    default_task = "deliver"

    def __init__(
        self,
        *,
        putdown: str = "dietterich",
        slip: bool | None = None,
        slip_probability: float = 0.8,
        gamma: float = 0.95,
        fickle: bool = False,
        fickle_probability: float = FICKLE_PROBABILITY,
    ) -> None:
        fickle = bool(fickle)
        if slip is None:
            slip = fickle
        if fickle and not slip:
            raise TaskError(
                "fickle Taxi has noisy moves by definition (Dietterich 2000, sec. 7.1); drop "
                "slip=False, or use fickle=False for a deterministic taxi"
            )
        if fickle and putdown != "dietterich":
            raise TaskError(
                "fickle Taxi needs putdown='dietterich': with the 'gymnasium' rule the passenger "
                "can be re-picked up and the one-off destination change would need another flag"
            )
        if not 0.0 <= fickle_probability <= 1.0:
            raise TaskError(
                f"fickle_probability = {fickle_probability!r} is not a probability; give a value "
                "in [0, 1] (0.3 in Dietterich's fickle Taxi)"
            )
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
        self.fickle = fickle
        self.fickle_probability = float(fickle_probability)

    @property
    def state_count(self) -> int:
        """500, or 516 for fickle Taxi (the 16 pending states, see the module docstring)."""
        return N_STATES_FICKLE if self.fickle else N_STATES

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
        if self.fickle:
            return self._build_fickle_dynamics()
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
        P = _assemble(rows, cols, probs, S)
        features = _features(row, col, passenger, dest)
        return Dynamics(
            P=P,
            action_names=ACTION_NAMES,
            action_costs=np.full(len(ACTION_NAMES), STEP_REWARD),
            features=features,
            admissible=None,
            start=self.start_distribution(),
        )

    def _move_outcomes(self, a: int) -> list[tuple[int, float]]:
        """``(direction, probability)`` outcomes of move action ``a`` (slip noise if on)."""
        if not self.slip:
            return [(a, 1.0)]
        p_side = (1.0 - self.slip_probability) / 2.0
        return [(m, p) for m, p in ((a, self.slip_probability),
                                    *((side, p_side) for side in PERPENDICULAR[a])) if p > 0.0]

    @staticmethod
    def fickle_state_table() -> dict[str, np.ndarray]:
        """``(516,)`` arrays ``row, col, passenger, destination, pending`` of fickle Taxi's states.

        States ``0..499`` decode as in :func:`decode` (pending 0); state ``500 + 4 * l + d`` is
        the taxi on landmark ``l`` with the passenger just picked up there and destination ``d``.
        """
        row, col, passenger, dest = decode(np.arange(N_STATES))
        k = np.arange(N_PENDING)
        lm = np.asarray(LANDMARKS)
        return {
            "row": np.concatenate([row, lm[k // N_DEST, 0]]),
            "col": np.concatenate([col, lm[k // N_DEST, 1]]),
            "passenger": np.concatenate([passenger, np.full(N_PENDING, IN_TAXI)]),
            "destination": np.concatenate([dest, k % N_DEST]),
            "pending": np.concatenate([np.zeros(N_STATES, np.int64), np.ones(N_PENDING, np.int64)]),
        }

    def _fickle_pickup_putdown(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Fickle Taxi's ``(next_pick, r_pick, next_put, r_put)`` over all 516 states.

        A legal Pickup enters the pending state of (landmark, destination); in a pending state
        Pickup is illegal (the passenger is already in) and Putdown delivers only if the
        destination is that landmark (never reached from a start state, kept for completeness).
        """
        next_pick, r_pick, next_put, r_put = self._pickup_putdown()
        _, _, passenger, dest = decode(np.arange(N_STATES))
        lm = np.asarray(LANDMARKS)
        picked = next_pick != np.arange(N_STATES)
        # a legal pickup happens on landmark `passenger`; go to its pending state
        next_pick = np.where(picked, N_STATES + passenger.clip(0, N_DEST - 1) * N_DEST + dest,
                             next_pick)
        k = np.arange(N_PENDING)
        land, pdest = k // N_DEST, k % N_DEST
        pend = N_STATES + k
        deliver = land == pdest
        next_put_p = np.where(deliver, encode(lm[land, 0], lm[land, 1], pdest, pdest), pend)
        return (
            np.concatenate([next_pick, pend]),
            np.concatenate([r_pick, np.full(N_PENDING, ILLEGAL_REWARD)]),
            np.concatenate([next_put, next_put_p]),
            np.concatenate([r_put, np.where(deliver, DELIVERY_REWARD, ILLEGAL_REWARD)]),
        )

    def _build_fickle_dynamics(self) -> Dynamics:
        """Fickle Taxi's 516-state model (module docstring), vectorised over states."""
        table = self.fickle_state_table()
        S = N_STATES_FICKLE
        s = np.arange(S)
        row, col, passenger = table["row"], table["col"], table["passenger"]
        dest, pending = table["destination"], table["pending"].astype(bool)
        f = self.fickle_probability
        rows: list[np.ndarray] = []
        cols: list[np.ndarray] = []
        probs: list[np.ndarray] = []
        for a in range(4):
            for move, p in self._move_outcomes(a):
                r2, c2 = self._move(row, col, move)
                moved = (r2 != row) | (c2 != col)
                stay_pending = pending & ~moved
                resolves = pending & moved
                # ordinary outcome (and the "destination kept" share of a resolving move)
                target = np.where(stay_pending, s, encode(r2, c2, passenger, dest))
                rows.append(a * S + s)
                cols.append(target)
                probs.append(np.where(resolves, p * (1.0 - f), p))
                # the destination changes to each other landmark w.p. f / 3
                for shift in range(1, N_DEST):
                    idx = np.flatnonzero(resolves)
                    rows.append(a * S + idx)
                    cols.append(encode(r2[idx], c2[idx], IN_TAXI, (dest[idx] + shift) % N_DEST))
                    probs.append(np.full(idx.size, p * f / (N_DEST - 1)))
        next_pick, _, next_put, _ = self._fickle_pickup_putdown()
        rows += [PICKUP * S + s, PUTDOWN * S + s]
        cols += [next_pick, next_put]
        probs += [np.ones(S), np.ones(S)]
        P = _assemble(rows, cols, probs, S)
        features = {**_features(row, col, passenger, dest), "pending": pending.astype(np.int64)}
        return Dynamics(
            P=P,
            action_names=ACTION_NAMES,
            action_costs=np.full(len(ACTION_NAMES), STEP_REWARD),
            features=features,
            admissible=None,
            start=self._padded(self.start_distribution()),
        )

    def _padded(self, values: np.ndarray) -> np.ndarray:
        """Extend a 500-state array with zeros / False for the pending states of fickle Taxi."""
        if not self.fickle:
            return values
        return np.concatenate([values, np.zeros(N_PENDING, dtype=values.dtype)])

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
        if self.fickle:
            _, r_pick, _, r_put = self._fickle_pickup_putdown()
        else:
            _, r_pick, _, r_put = self._pickup_putdown()
        R = np.full((self.state_count, len(ACTION_NAMES)), STEP_REWARD)
        R[:, PICKUP] = r_pick
        R[:, PUTDOWN] = r_put
        return R

    def _deliver(self, domain: Domain) -> Task:
        return Task(
            name="deliver",
            reward=self.deliver_rewards(),
            terminal=self._padded(self.delivered()),
            initial=self._padded(self.start_distribution()),
            gamma=self.gamma,
            description="pick the passenger up and put them down at their destination",
            spec={"kind": "taxi-deliver", "putdown": self.putdown, "slip": self.slip,
                  "slip_probability": self.slip_probability, "gamma": self.gamma,
                  **({"fickle": True, "fickle_probability": self.fickle_probability}
                     if self.fickle else {})},
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


class FickleTaxi(Taxi):
    """Dietterich's fickle Taxi (516 states): ``Taxi(fickle=True)`` under its own name."""

    name = "taxi-fickle"
    description = (
        "Dietterich's fickle Taxi: noisy moves, the passenger may change destination after "
        "pickup (516 states)"
    )
    source = "Dietterich 2000, JAIR 13, sec. 7.1 (fickle Taxi); dissertation chapter 6"

    def __init__(self, **kwargs: object) -> None:
        kwargs.setdefault("fickle", True)
        super().__init__(**kwargs)  # type: ignore[arg-type]

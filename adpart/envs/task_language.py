"""Tasks that keep the environment's rewards: ``move-goal:``, ``set-reward:``, ``reward-table:``.

``goal:FEATURE=V,...`` (:class:`~adpart.envs.base.GoalSpec`) *replaces* a task's rewards,
terminal states and discount with a generic scheme. The three kinds of task string here start
from one of the environment's own tasks instead (its default task, or the one named by
``;from:TASKNAME``) and change only where arriving pays:

* ``move-goal:FEATURE=V,...[;from:TASKNAME]`` - the base task's goal moves to the matched states.
  The *goal states* of the base task are its terminal states whose arrival pays more than the
  step reward (a terminal state reached for at most the step reward - a FrozenLake hole, a lava
  cell - is a failure terminal and stays terminal). In a cost-to-go task, where no terminal state
  pays more than the step but the step reward is negative (CliffWalking: -1 a step, the goal
  pays -1 too), the terminal states reached for exactly the step reward are the goal states:
  arriving there ends the costs. Arriving at a matched state then pays what arriving at the old
  goal paid (the step reward plus the same bonus), the matched states are terminal, the old goal
  states are neither terminal nor rewarding (arriving there pays the step reward); every other
  reward, terminal state, the discount and the start distribution are the base task's (start mass
  on a new goal state is removed and the rest renormalised).
* ``set-reward:CLAUSE[;CLAUSE...][;from:TASKNAME]`` with ``CLAUSE = FEATURE=V,...=R`` optionally
  followed by ``;terminal`` or ``;nonterminal`` (which apply to the clause they follow) - arriving
  at a matched state pays ``R`` *instead of* what that transition paid (replaced, not added);
  ``terminal`` makes the clause's states terminal, ``nonterminal`` makes them non-terminal, and
  without either they keep the base task's status. ``R`` may be negative (a penalty) or the step
  reward (a reward removed).
* ``reward-table:PATH[;from:TASKNAME]`` - the clauses of ``set-reward:`` as the rows of a CSV or
  Parquet file: a ``state`` column (the state index) and/or feature columns, a ``reward`` column
  and an optional boolean ``terminal`` column (true: terminal, false: non-terminal, empty: as in
  the base task). The task's name carries the first 12 hex digits of the content hash
  (``reward-table:PATH;sha256:0123456789ab``) and its spec the rows themselves, so the knowledge
  base tells two files apart; resolving a name with a hash refuses a file whose content changed.

``state=N`` in any match means the state with index ``N``.

How "arriving pays" is read off a task's expected rewards ``R(s, a)``: the *step reward* of a
pair is the reward most admissible non-terminal pairs pay (the ``mode`` rule of
:func:`adpart.partition.layer.step_baseline`), or, when the domain's per-action costs explain
more pairs (two-rooms' -1 straight and -1.2 diagonal), that action's cost shifted by the most
common remainder. A transition certain to arrive at ``s'`` paid ``R(s, a)``; one that arrives with
probability ``p < 1`` paid the step reward plus ``s'``'s *arrival bonus*, the most common value of
``(R(s, a) - step) / p`` over the pairs an episode can take (from a start state on) that can
arrive at ``s'`` and at no other terminal or changed state. Replacing an arrival reward adds
``p (new - old)`` to ``R(s, a)``.

Every task gets a canonical name (features sorted, numbers written canonically, ``;from:`` kept
only when it is not the default task) and a JSON-able ``Task.spec`` (``{"kind": "move-goal",
...}``), so two spellings of one task are one task in the knowledge base, and resolving the name
again gives the same task.
"""

from __future__ import annotations

import difflib
import hashlib
import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp

from adpart.envs.base import Dynamics, Task
from adpart.errors import TaskError

if TYPE_CHECKING:
    from adpart.envs.base import Domain

#: The task kinds of this module, and the prefixes of their task strings.
KINDS = ("move-goal", "set-reward", "reward-table")
PREFIXES = tuple(f"{kind}:" for kind in KINDS)

#: Reward values closer than this (relative to the largest |R|) are the same value.
_REL_TOL = 1e-9
#: Digits an estimate is rounded to before its most common value is taken.
_DIGITS = 9
#: How many hex digits of a table's content hash its task name carries.
NAME_HASH_DIGITS = 12


def is_task_spec(text: str) -> bool:
    """Whether ``text`` is a task string of this module (``move-goal:``, ``set-reward:`` ...)."""
    return text.startswith(PREFIXES)


# ----------------------------------------------------------------------------------- parsing


@dataclass(frozen=True)
class Clause:
    """Arriving at the states matching ``match`` pays ``reward``; ``terminal``: True makes them
    terminal, False non-terminal, None keeps the base task's status."""

    match: tuple[tuple[str, int], ...]
    reward: float
    terminal: bool | None = None

    def as_json(self) -> dict[str, Any]:
        return {"match": dict(self.match), "reward": self.reward, "terminal": self.terminal}

    def text(self) -> str:
        flag = {True: ";terminal", False: ";nonterminal", None: ""}[self.terminal]
        return f"{_assignments_text(dict(self.match))}={_num(self.reward)}{flag}"


def _num(x: float) -> str:
    """A number written canonically: ``1.0`` and ``1`` as ``1``, ``-0.0`` as ``0``."""
    x = float(x)
    if x.is_integer() and abs(x) < 1e15:
        return str(int(x))
    return repr(x)


def _assignments_text(match: Mapping[str, int]) -> str:
    return ",".join(f"{k}={int(v)}" for k, v in sorted(match.items()))


def _integer(value: object, where: str) -> int:
    """``value`` (text or number) as an integer; ``1.0`` is 1, ``1.5`` an error."""
    try:
        number = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise TaskError(f"{where}: value {value!r} is not an integer") from None
    if not number.is_integer():
        raise TaskError(f"{where}: value {value!r} is not an integer")
    return int(number)


def _reward(value: object, where: str) -> float:
    try:
        number = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise TaskError(f"{where}: reward {value!r} is not a number") from None
    if not math.isfinite(number):
        raise TaskError(f"{where}: reward {value!r} is not a finite number")
    return number + 0.0  # -0.0 -> 0.0


def _parse_match(part: str, where: str, example: str) -> dict[str, int]:
    out: dict[str, int] = {}
    for item in filter(None, (p.strip() for p in part.split(","))):
        key, eq, value = item.partition("=")
        key = key.strip()
        if not eq or not key:
            raise TaskError(f"{where}: {item!r} is not FEATURE=VALUE (e.g. {example})")
        if key in out:
            raise TaskError(f"{where}: feature {key!r} is given twice")
        out[key] = _integer(value.strip(), f"{where}: {key}")
    if not out:
        raise TaskError(f"{where} names no feature; write e.g. {example}")
    return out


def _split_from(parts: list[str], where: str) -> tuple[list[str], str | None]:
    """The parts other than ``from:TASK``, and TASK (None when not given)."""
    rest, base = [], None
    for part in parts:
        if part.startswith("from:"):
            if base is not None:
                raise TaskError(f"{where}: from: is given twice")
            base = part.removeprefix("from:").strip()
            if not base:
                raise TaskError(f"{where}: from: names no task; write e.g. ;from:reward")
        else:
            rest.append(part)
    return rest, base


def parse_move_goal(text: str) -> tuple[dict[str, int], str | None]:
    """``move-goal:FEATURE=V,...[;from:TASK]`` -> (the goal's features, the base task)."""
    where = f"task {text!r}"
    parts, base = _split_from([p.strip() for p in text.removeprefix("move-goal:").split(";")],
                              where)
    if len(parts) != 1:
        raise TaskError(f"{where}: write move-goal:FEATURE=V,...[;from:TASKNAME] "
                        "(e.g. move-goal:row=0,col=3)")
    return _parse_match(parts[0], where, "move-goal:row=0,col=3"), base


def parse_set_reward(text: str) -> tuple[tuple[Clause, ...], str | None]:
    """``set-reward:CLAUSE[;terminal][;CLAUSE...][;from:TASK]`` -> (clauses, the base task)."""
    where = f"task {text!r}"
    parts, base = _split_from([p.strip() for p in text.removeprefix("set-reward:").split(";")],
                              where)
    clauses: list[Clause] = []
    for part in parts:
        if part in ("terminal", "nonterminal"):
            if not clauses or clauses[-1].terminal is not None:
                raise TaskError(f"{where}: ;{part} follows the clause it applies to, once "
                                "(e.g. set-reward:row=1,col=1=-1;terminal)")
            last = clauses.pop()
            clauses.append(Clause(last.match, last.reward, part == "terminal"))
            continue
        match_text, _, value = part.rpartition("=")
        if part.split(",")[-1].count("=") != 2:
            raise TaskError(f"{where}: {part!r} is not FEATURE=V,...=REWARD (e.g. "
                            "set-reward:row=1,col=1=-1)")
        match = _parse_match(match_text, where, "row=1,col=1=-1")
        clauses.append(Clause(tuple(sorted(match.items())), _reward(value, where)))
    if not clauses:
        raise TaskError(f"{where} sets no reward; write e.g. set-reward:row=1,col=1=-1")
    return tuple(clauses), base


def parse_reward_table(text: str) -> tuple[str, str | None, str | None]:
    """``reward-table:PATH[;from:TASK][;sha256:HEX]`` -> (path, base task, hash prefix)."""
    where = f"task {text!r}"
    path, *rest = (p.strip() for p in text.removeprefix("reward-table:").split(";"))
    parts, base = _split_from(rest, where)
    digest = None
    for part in parts:
        if part.startswith("sha256:") and digest is None:
            digest = part.removeprefix("sha256:").strip().lower()
            if len(digest) < 8 or any(c not in "0123456789abcdef" for c in digest):
                raise TaskError(f"{where}: sha256:{digest} is not (a prefix of at least 8 of) "
                                "the 64 hex digits of a content hash")
        else:
            raise TaskError(f"{where}: unknown part {part!r}; write "
                            "reward-table:PATH[;from:TASKNAME]")
    if not path:
        raise TaskError(f"{where} names no file; write reward-table:PATH (a .csv or .parquet)")
    return os.path.normpath(path), base, digest


# ----------------------------------------------------------------------------- reward tables

TABLE_COLUMNS = ("reward", "terminal")


def read_reward_table(path: str | Path, dyn: Dynamics) -> tuple[Clause, ...]:
    """The rows of a CSV or Parquet reward table as clauses (see the module docstring).

    Raises:
        TaskError: the file is missing or of another format, a column is missing or unknown, or
            a value is not of its column's type.
    """
    import pyarrow as pa

    path = Path(path)
    where = f"reward-table {path}"
    if not path.is_file():
        raise TaskError(f"{where}: no such file")
    name = path.name.lower()
    try:
        if name.endswith((".parquet", ".pq")):
            import pyarrow.parquet as pq

            table = pq.read_table(path)
        elif name.endswith((".csv", ".csv.gz", ".csv.bz2")):
            import pyarrow.csv as pacsv

            table = pacsv.read_csv(path)
        else:
            raise TaskError(f"{where}: write the table as .csv or .parquet")
    except (pa.ArrowInvalid, OSError) as exc:
        raise TaskError(f"{where}: cannot read it ({' '.join(str(exc).split())})") from None
    columns = list(table.column_names)
    keys = [c for c in columns if c not in TABLE_COLUMNS]
    if "reward" not in columns or not keys:
        raise TaskError(
            f"{where}: columns {', '.join(columns) or '(none)'}; the table needs a 'reward' column "
            "and a 'state' column or feature columns ("
            + ", ".join(sorted(dyn.features)) + "), and may have a boolean 'terminal' column")
    unknown = [c for c in keys if c != "state" and c not in dyn.features]
    if unknown:
        raise TaskError(f"{where}: column {unknown[0]!r} is neither state, reward, terminal nor a "
                        "feature of this environment (features: "
                        f"{', '.join(sorted(dyn.features))})")
    clauses = []
    for i, row in enumerate(table.to_pylist(), start=1):
        at = f"{where}: row {i}"
        if row["reward"] is None:
            raise TaskError(f"{at}: the reward is empty")
        match = {}
        for key in keys:
            if row[key] is None:
                raise TaskError(f"{at}: {key} is empty")
            match[key] = _integer(row[key], f"{at}: {key}")
        terminal = row.get("terminal")
        if terminal is not None:
            if isinstance(terminal, str) and terminal.strip().lower() in ("true", "false"):
                terminal = terminal.strip().lower() == "true"
            elif not isinstance(terminal, bool) and terminal in (0, 1):
                terminal = bool(terminal)
            if not isinstance(terminal, bool):
                raise TaskError(f"{at}: terminal {terminal!r} is not true, false or empty")
        clauses.append(Clause(tuple(sorted(match.items())), _reward(row["reward"], at), terminal))
    if not clauses:
        raise TaskError(f"{where}: the table has no rows")
    return tuple(clauses)


def _canonical_clauses(clauses: Sequence[Clause]) -> tuple[Clause, ...]:
    return tuple(sorted(set(clauses), key=lambda c: json.dumps(c.as_json(), sort_keys=True)))


def clauses_hash(clauses: Sequence[Clause]) -> str:
    """SHA-256 of the canonical JSON of the rows (sorted, duplicates dropped)."""
    rows = [c.as_json() for c in _canonical_clauses(clauses)]
    text = json.dumps(rows, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


# ---------------------------------------------------------------------------------- matching


def match_states(dyn: Dynamics, wanted: Mapping[str, int], *, where: str) -> np.ndarray:
    """``(S,)`` bool mask of the states matching ``wanted`` (``state`` is the state index).

    Raises:
        TaskError: an unknown feature (naming the features), or no state matches (naming the
            values the features take); the message starts with ``where``.
    """
    features = {k: v for k, v in wanted.items() if k != "state"}
    for key in features:
        if key not in dyn.features:
            hint = difflib.get_close_matches(key, list(dyn.features), n=1)
            raise TaskError(
                f"{where}: {key!r} is not a feature of this environment; "
                f"features: {', '.join(sorted(dyn.features))}"
                + (f". Did you mean {hint[0]!r}?" if hint else ""))
    mask = np.ones(dyn.n_states, dtype=bool)
    if "state" in wanted:
        mask[:] = False
        if 0 <= wanted["state"] < dyn.n_states:
            mask[wanted["state"]] = True
    for key, value in features.items():
        mask &= np.asarray(dyn.features[key]) == value
    if not mask.any():
        ranges = [f"{k} takes {int(dyn.features[k].min())}..{int(dyn.features[k].max())}"
                  for k in sorted(features)]
        if "state" in wanted:
            ranges.append(f"state takes 0..{dyn.n_states - 1}")
        raise TaskError(f"{where}: no state matches {_assignments_text(wanted)} "
                        f"({'; '.join(ranges)})")
    return mask


# -------------------------------------------------------------------------- reading rewards


def _mode(values: np.ndarray) -> float:
    """The most common value (ties to the smaller), as ``step_baseline(rule="mode")``."""
    vals, counts = np.unique(values, return_counts=True)
    return float(vals[np.argmax(counts)])


def _group_mode(groups: np.ndarray, values: np.ndarray, n_groups: int) -> np.ndarray:
    """``(n_groups,)``: per group the most common (rounded) value, ties to the smaller; NaN for a
    group without values."""
    out = np.full(n_groups, np.nan)
    if groups.size == 0:
        return out
    v = np.round(values, _DIGITS) + 0.0
    order = np.lexsort((v, groups))
    g, v = groups[order], v[order]
    starts = np.flatnonzero(np.r_[True, (g[1:] != g[:-1]) | (v[1:] != v[:-1])])
    lengths = np.diff(np.r_[starts, g.size])
    run_g, run_v = g[starts], v[starts]
    pick = np.lexsort((-lengths, run_g))  # by group, the longest run first (stable: smaller v)
    rg, rv = run_g[pick], run_v[pick]
    first = np.r_[True, rg[1:] != rg[:-1]]
    out[rg[first]] = rv[first]
    return out


@dataclass(frozen=True)
class RewardReading:
    """How a task's expected rewards read as arrival rewards (module docstring).

    Attributes:
        step: ``(A,)`` the step reward of each action.
        baseline: the reward most live pairs pay (``step_baseline(..., rule="mode")``).
        tol: rewards closer than this are equal.
    """

    step: np.ndarray
    baseline: float
    tol: float


def read_rewards(dyn: Dynamics, task: Task) -> RewardReading:
    """The step rewards of ``task`` (see :class:`RewardReading`)."""
    R = np.asarray(task.reward, dtype=np.float64)
    live = _admissible(dyn) & ~np.asarray(task.terminal, dtype=bool)[:, None]
    if not live.any():
        raise TaskError(f"task {task.name!r} has no admissible pair in a non-terminal state, so "
                        "no step reward")
    baseline = _mode(R[live])
    costs = np.asarray(dyn.action_costs, dtype=np.float64)
    shifted = costs + _mode((R - costs[None, :])[live])
    tol = _REL_TOL * max(1.0, float(np.abs(R).max()))
    flat = np.full(dyn.n_actions, baseline)
    explained = [int((np.abs(R - s[None, :]) <= tol)[live].sum()) for s in (flat, shifted)]
    step = shifted if explained[1] > explained[0] else flat
    return RewardReading(step=step, baseline=baseline, tol=tol)


def _reachable(dyn: Dynamics, task: Task) -> np.ndarray:
    """``(S,)`` bool: the states an episode of ``task`` can occupy (from its start states, by
    admissible actions, never leaving a terminal state)."""
    A = dyn.n_actions
    terminal = np.asarray(task.terminal, dtype=bool)
    go = (_admissible(dyn) & ~terminal[:, None]).T.reshape(-1).astype(np.float64)
    P = sp.csr_array(dyn.P)
    moves = sp.csr_array(sp.diags_array(go) @ P)  # rows a*S + s of the pairs that are taken
    seen = np.asarray(task.initial) > 0
    frontier = seen.copy()
    while frontier.any():
        weights = np.tile(frontier.astype(np.float64), A)
        step = (moves.T @ weights) > 0
        frontier = step & ~seen
        seen |= frontier
    return seen


def _live(dyn: Dynamics, task: Task) -> np.ndarray:
    """``(A*S,)`` bool, row ``a*S + s``: the admissible pairs of the non-terminal states an
    episode can occupy (the pairs whose rewards tell what arriving pays)."""
    terminal = np.asarray(task.terminal, dtype=bool)
    live = _admissible(dyn) & (_reachable(dyn, task) & ~terminal)[:, None]
    return live.T.reshape(-1)


def _admissible(dyn: Dynamics) -> np.ndarray:
    if dyn.admissible is None:
        return np.ones((dyn.n_states, dyn.n_actions), dtype=bool)
    return np.asarray(dyn.admissible, dtype=bool)


def arrival_bonuses(dyn: Dynamics, task: Task, reading: RewardReading,
                    states: np.ndarray, special: np.ndarray) -> np.ndarray:
    """``(len(states),)`` the arrival bonus of each state (module docstring); NaN for a state no
    live pair arrives at.

    Args:
        states: state indices, all in ``special``.
        special: ``(S,)`` bool, the terminal and changed states: a pair that can arrive at two of
            them estimates neither (unless no other pair does).
    """
    S, A = dyn.n_states, dyn.n_actions
    R = np.asarray(task.reward, dtype=np.float64)
    excess = (R - reading.step[None, :]).T.reshape(-1)
    live = _live(dyn, task)
    cols = np.flatnonzero(special)
    sub = sp.csr_array(dyn.P)[:, cols].tocoo()
    keep = live[sub.row] & (sub.data > 0)
    rows, j, p = sub.row[keep], sub.col[keep], sub.data[keep]
    per_row = np.bincount(rows, minlength=A * S)
    clean = per_row[rows] == 1
    bonus = _group_mode(j[clean], excess[rows[clean]] / p[clean], cols.size)
    unknown = np.isnan(bonus)
    if unknown.any():  # no pair arrives there alone: take the known others out first
        known = np.bincount(rows, weights=p * np.nan_to_num(bonus[j]), minlength=A * S)
        use = unknown[j]
        bonus[unknown] = _group_mode(j[use], (excess[rows[use]] - known[rows[use]]) / p[use],
                                     cols.size)[unknown]
    position = np.full(S, -1)
    position[cols] = np.arange(cols.size)
    return bonus[position[np.asarray(states, dtype=np.int64)]]


def replace_arrivals(dyn: Dynamics, task: Task, reading: RewardReading, states: np.ndarray,
                     new: np.ndarray, plus_step: np.ndarray, special: np.ndarray) -> np.ndarray:
    """``(S, A)``: ``task``'s rewards with the arrival reward at each of ``states`` replaced.

    Arriving at ``states[k]`` then pays ``new[k]``, plus the pair's step reward where
    ``plus_step[k]``; a pair certain to arrive paid ``R(s, a)``, one arriving with probability
    ``p < 1`` the step reward plus the state's arrival bonus (:func:`arrival_bonuses`).
    """
    S, A = dyn.n_states, dyn.n_actions
    states = np.asarray(states, dtype=np.int64)
    R = np.asarray(task.reward, dtype=np.float64)
    bonus = np.nan_to_num(arrival_bonuses(dyn, task, reading, states, special))
    sub = sp.csr_array(dyn.P)[:, states].tocoo()
    rows, k, p = sub.row, sub.col, sub.data
    adm = _admissible(dyn).T.reshape(-1)
    keep = adm[rows] & (p > 0)
    rows, k, p = rows[keep], k[keep], p[keep]
    step = reading.step[rows // S]
    flat_R = R.T.reshape(-1)
    old = np.where(p >= 1.0 - 1e-12, flat_R[rows], step + bonus[k])
    target = new[k] + np.where(plus_step[k], step, 0.0)
    delta = np.bincount(rows, weights=p * (target - old), minlength=A * S)
    return R + delta.reshape(A, S).T


@dataclass(frozen=True)
class Goals:
    """The goal states of a task (module docstring) and the bonus arriving at each pays."""

    states: np.ndarray
    bonuses: np.ndarray
    reading: RewardReading


def goal_states(dyn: Dynamics, task: Task) -> Goals:
    """The terminal states whose arrival pays more than the step reward (or, in a cost-to-go
    task, exactly the step reward), with their bonuses over the step reward."""
    reading = read_rewards(dyn, task)
    terminal = np.asarray(task.terminal, dtype=bool)
    states = np.flatnonzero(terminal)
    bonus = arrival_bonuses(dyn, task, reading, states, terminal)
    reached = ~np.isnan(bonus)
    chosen = reached & (bonus > reading.tol)
    if not chosen.any() and reading.baseline < 0:
        chosen = reached & (np.abs(bonus) <= reading.tol)
    return Goals(states[chosen], np.where(np.abs(bonus[chosen]) <= reading.tol, 0.0,
                                          bonus[chosen]), reading)


def goal_mask(domain: Domain, task: Task) -> np.ndarray:
    """``(S,)`` bool: the states a map letters as ``task``'s goal.

    A ``move-goal:`` task's matched states; a ``set-reward:`` or ``reward-table:`` task's goal
    states (:func:`goal_states`, all terminal states when it has none); any other task's
    terminal states.
    """
    terminal = np.asarray(task.terminal, dtype=bool)
    kind = task.spec.get("kind") if isinstance(task.spec, Mapping) else None
    if kind not in KINDS:
        return terminal
    dyn = domain.dynamics()
    if kind == "move-goal":
        return match_states(dyn, task.spec["goal"], where=task.name)  # type: ignore[arg-type]
    mask = np.zeros(dyn.n_states, dtype=bool)
    try:
        mask[goal_states(dyn, task).states] = True
    except TaskError:
        return terminal
    return mask if mask.any() else terminal


# ------------------------------------------------------------------------------- the tasks


def build_task(domain: Domain, text: str) -> Task:
    """The task of a ``move-goal:``, ``set-reward:`` or ``reward-table:`` string on ``domain``.

    Raises:
        TaskError: a malformed string, an unknown feature, an empty match, or (``move-goal:``) a
            base task without goal states or with goal states of different rewards.
    """
    if text.startswith("move-goal:"):
        goal, base = parse_move_goal(text)
        return move_goal(domain, goal, base)
    if text.startswith("set-reward:"):
        clauses, base = parse_set_reward(text)
        return set_reward(domain, clauses, base)
    if text.startswith("reward-table:"):
        path, base, digest = parse_reward_table(text)
        return reward_table(domain, path, base, digest)
    raise TaskError(f"task {text!r} is none of {', '.join(p + '...' for p in PREFIXES)}")


def _base(domain: Domain, name: str | None) -> tuple[Task, str]:
    """The base task and the ``;from:`` part of a canonical name (empty for the default)."""
    default = domain.default_task or next(iter(domain.tasks()), "")
    if name is not None and name not in domain.tasks():
        hint = difflib.get_close_matches(name, list(domain.tasks()), n=1)
        raise TaskError(f"from:{name}: environment {domain.name!r} has no task {name!r}; the base "
                        f"task is one of its named tasks: {', '.join(domain.tasks())}"
                        + (f". Did you mean {hint[0]!r}?" if hint else ""))
    task = domain.task(default if name is None else name)
    return task, ("" if name is None or name == default else f";from:{name}")


def _spec_json(spec: Mapping[str, object]) -> dict[str, object]:
    """``spec`` as plain JSON values (a base task's spec may hold numpy scalars)."""
    try:
        return json.loads(json.dumps(dict(spec), default=lambda o: o.tolist()))
    except (TypeError, ValueError, AttributeError):
        return {"unserialisable": True}


def _initial(base: Task, terminal: np.ndarray, name: str) -> np.ndarray:
    initial = np.where(terminal, 0.0, np.asarray(base.initial, dtype=np.float64))
    if initial.sum() <= 0:
        raise TaskError(f"every start state of task {name!r} is terminal; choose other states")
    return initial / initial.sum()


def move_goal(domain: Domain, goal: Mapping[str, int], base_name: str | None = None) -> Task:
    """``move-goal:``: the base task's goal moved to the states matching ``goal``."""
    dyn = domain.dynamics()
    base, from_part = _base(domain, base_name)
    name = f"move-goal:{_assignments_text(goal)}{from_part}"
    new = match_states(dyn, goal, where=name)
    found = goal_states(dyn, base)
    reading = found.reading
    if found.states.size == 0:
        raise TaskError(
            f"{name}: task {base.name!r} has no goal state (no terminal state whose arrival pays "
            f"more than its step reward {_num(reading.baseline)}), so there is no goal to move; "
            "give the new rewards with set-reward:FEATURE=V,...=R;terminal")
    values = np.unique(np.round(found.bonuses, _DIGITS))
    if values.size > 1:
        counts = [int((np.round(found.bonuses, _DIGITS) == v).sum()) for v in values]
        listed = ", ".join(f"{_num(reading.baseline + v)} at {n} state{'s' * (n > 1)}"
                           for v, n in zip(values, counts, strict=True))
        raise TaskError(
            f"{name}: the goal states of task {base.name!r} pay different rewards on arrival "
            f"({listed}), and move-goal moves one reward; give each with "
            "set-reward:FEATURE=V,...=R;terminal")
    bonus = float(values[0])
    old = np.zeros(dyn.n_states, dtype=bool)
    old[found.states] = True
    terminal = (np.asarray(base.terminal, dtype=bool) & ~old) | new
    changed = np.flatnonzero(old | new)
    reward = replace_arrivals(dyn, base, reading, changed,
                              new=np.where(new[changed], bonus, 0.0),
                              plus_step=np.ones(changed.size, dtype=bool),
                              special=np.asarray(base.terminal, dtype=bool) | new)
    arrivals = sp.csr_array(dyn.P) @ new.astype(np.float64)
    live = (_admissible(dyn) & ~terminal[:, None]).T.reshape(-1)
    if not (arrivals[live] > 0).any():
        raise TaskError(f"{name}: no action of a non-terminal state leads to "
                        f"{_assignments_text(goal)}; choose states an episode can reach")
    return Task(
        name=name,
        reward=reward,
        terminal=terminal,
        initial=_initial(base, new, name),
        gamma=base.gamma,
        description=(f"{base.name} with its goal (arrival pays "
                     f"{_num(reading.baseline + bonus)}) moved to {_assignments_text(goal)}"),
        spec={
            "kind": "move-goal",
            "goal": dict(sorted(goal.items())),
            "from": base.name,
            "goal_bonus": bonus,
            "step_reward": reading.baseline,
            "gamma": base.gamma,
            "base": _spec_json(base.spec),
        },
    )


def _apply_clauses(domain: Domain, base: Task, clauses: Sequence[Clause], name: str
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(reward, terminal, initial) of ``base`` with ``clauses`` applied."""
    dyn = domain.dynamics()
    S = dyn.n_states
    value = np.full(S, np.nan)
    flag = np.full(S, -1)  # -1 keep, 0 non-terminal, 1 terminal
    owner = np.full(S, -1)
    for i, clause in enumerate(clauses):
        mask = match_states(dyn, dict(clause.match), where=name)
        code = -1 if clause.terminal is None else int(clause.terminal)
        clash = mask & (owner >= 0) & ((value != clause.reward) | (flag != code))
        if clash.any():
            s = int(np.flatnonzero(clash)[0])
            raise TaskError(f"{name}: state {s} matches {clauses[owner[s]].text()!r} and "
                            f"{clause.text()!r}, which set it differently; make them disjoint")
        value[mask], flag[mask], owner[mask] = clause.reward, code, i
    changed = np.flatnonzero(owner >= 0)
    base_terminal = np.asarray(base.terminal, dtype=bool)
    terminal = np.where(flag == 1, True, np.where(flag == 0, False, base_terminal))
    reading = read_rewards(dyn, base)
    reward = replace_arrivals(dyn, base, reading, changed, new=value[changed],
                              plus_step=np.zeros(changed.size, dtype=bool),
                              special=base_terminal | (owner >= 0))
    return reward, terminal, _initial(base, terminal & ~base_terminal, name)


def set_reward(domain: Domain, clauses: Sequence[Clause], base_name: str | None = None) -> Task:
    """``set-reward:``: the base task with the clauses' arrival rewards (and terminal states)."""
    base, from_part = _base(domain, base_name)
    clauses = _canonical_clauses(clauses)
    name = "set-reward:" + ";".join(c.text() for c in clauses) + from_part
    return _clauses_task(domain, base, clauses, name,
                         f"{base.name} with arrival rewards set: "
                         + "; ".join(c.text() for c in clauses), {"kind": "set-reward"})


def _clauses_task(domain: Domain, base: Task, clauses: Sequence[Clause], name: str,
                  description: str, head: dict[str, object]) -> Task:
    """The base task with ``clauses`` applied, named ``name``; its spec ``head`` followed by the
    rows, the base task and the discount (the one spec of ``set-reward:`` and
    ``reward-table:``)."""
    reward, terminal, initial = _apply_clauses(domain, base, clauses, name)
    return Task(
        name=name,
        reward=reward,
        terminal=terminal,
        initial=initial,
        gamma=base.gamma,
        description=description,
        spec={**head, "rows": [c.as_json() for c in clauses], "from": base.name,
              "gamma": base.gamma, "base": _spec_json(base.spec)},
    )


def reward_table(domain: Domain, path: str, base_name: str | None = None,
                 digest: str | None = None) -> Task:
    """``reward-table:``: :func:`set_reward` with the rows of a CSV or Parquet file."""
    base, from_part = _base(domain, base_name)
    dyn = domain.dynamics()
    rows = read_reward_table(path, dyn)
    for i, row in enumerate(rows, start=1):
        match_states(dyn, dict(row.match), where=f"reward-table {path}: row {i}")
    clauses = _canonical_clauses(rows)
    content = clauses_hash(clauses)
    if digest is not None and not content.startswith(digest):
        raise TaskError(f"reward-table {path}: its content hash is {content[:NAME_HASH_DIGITS]}, "
                        f"not {digest}: the file changed since the task was named; write "
                        f"reward-table:{path} for what it holds now")
    name = f"reward-table:{path}{from_part};sha256:{content[:NAME_HASH_DIGITS]}"
    return _clauses_task(domain, base, clauses, name,
                         f"{base.name} with the arrival rewards of {path} ({len(clauses)} rows)",
                         {"kind": "reward-table", "sha256": content})

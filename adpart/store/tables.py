"""The knowledge base as tables: records, learning curves and partitions as ``pyarrow.Table``.

A mixin of :class:`adpart.store.kb.KnowledgeBase`, in the manner of mlflow's ``search_runs``:
every method returns a ``pyarrow.Table``, which ``.to_pandas()`` turns into a pandas DataFrame and
``polars.from_arrow`` into a polars one. ``adpart kb ls --json`` prints exactly the rows of
:meth:`Tables.records_table` (through :func:`json_rows`), so what a script reads and what the
command line shows are the same records.

Parameters are flattened for filtering and for the ``params.*`` columns: a record's provenance
parameters (the learner's validated parameters for a run or policy), then, for records written by
``adpart learn``, the fields of the learning request (runs, episodes, seed, eval_every, ...) and
the parameters as given. Nested values stay JSON text in their column.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Iterable, Mapping, Sequence
from datetime import datetime
from pathlib import PurePath
from typing import Any

import numpy as np
import pyarrow as pa
from sqlalchemy import select

from adpart.store import entities as E
from adpart.store.errors import StoreError
from adpart.store.integrity import (
    ROW_SHA,
    changed_message,
    row_text,
    text_digest,
    unhashed_message,
)
from adpart.store.models import SqlArtifact
from adpart.store.queries import UNREADABLE, gc_paused

#: the kinds listed when no kind is asked for (artifacts are listed only on request)
LISTED_KINDS: tuple[str, ...] = tuple(k for k in E.RECORD_TYPES if k != "artifact")

#: the columns every records table has, in order; ``params.*`` and ``metrics.*`` follow
BASE_COLUMNS: dict[str, pa.DataType] = {
    "ref": pa.string(),
    "kind": pa.string(),
    "id": pa.int64(),
    "env": pa.string(),
    "environment_id": pa.int64(),
    "task": pa.string(),
    "task_id": pa.int64(),
    "learner": pa.string(),
    "summary": pa.string(),
    "created": pa.timestamp("us", tz="UTC"),
    "size": pa.int64(),
}

#: the columns of :meth:`Tables.runs_table`, in order: one row per run of a run record
RUN_COLUMNS: dict[str, pa.DataType] = {
    "run": pa.string(),
    "run_id": pa.int64(),
    "replicate": pa.int64(),
    "env": pa.string(),
    "environment_id": pa.int64(),
    "task": pa.string(),
    "task_id": pa.int64(),
    "learner": pa.string(),
    "partition_id": pa.int64(),
    "seed": pa.int64(),
    "episodes": pa.int64(),
    "fraction": pa.float64(),
    "bound": pa.float64(),
    "episodes_to_bound": pa.int64(),
    "steps_to_bound": pa.int64(),
    "censored": pa.bool_(),
    "final_gap": pa.float64(),
    "created": pa.timestamp("us", tz="UTC"),
}
#: the run metrics key holding each run's figures (``per_run_to_bound``), kept out of the
#: ``metrics.*`` columns of records_table: runs_table has a row per run for them
PER_RUN = "per_run"
_PER_RUN_LISTS = ("episodes_to_bound", "steps_to_bound", "censored", "final_gap")

#: provenance parameters that are bookkeeping, not settings (kept out of ``params.*``)
_BOOKKEEPING = ("request", "policies", "q_columns")
#: the learning-request fields shown as parameters (env, task and learner have columns of their own)
_REQUEST_FIELDS = ("runs", "episodes", "seed", "eval_every", "runs_per_batch", "options",
                   "partition")
_REF = re.compile(r"^(?P<kind>[a-z][a-z_-]*):(?P<id>[0-9]{1,18})$")


def flat_params(record: E.Record) -> dict[str, Any]:
    """The parameters of a record that ``where=`` filters on and ``params.*`` columns show."""
    if isinstance(record, E.Artifact):
        return {}
    params = record.provenance.parameters
    out = _flatten({k: v for k, v in params.items() if k not in _BOOKKEEPING})
    request = params.get("request")
    if isinstance(request, Mapping):
        for key in _REQUEST_FIELDS:
            if key in request:
                out.setdefault(key, request[key])
        given = request.get("params")
        if isinstance(given, Mapping):
            for key, value in _flatten(given).items():
                out.setdefault(key, value)
    return out


def _key_params(record: E.Record) -> dict[str, Any]:
    """The few parameters that tell runs apart (the ``summary`` column): the request's size and
    seed, those given to the learner and the options or layer it ran on, or the record's own
    parameters when it has no request."""
    params = record.provenance.parameters if not isinstance(record, E.Artifact) else {}
    request = params.get("request")
    if not isinstance(request, Mapping):
        return _flatten({k: v for k, v in params.items() if k not in _BOOKKEEPING})
    # the request's size and seed first, so a cut cell still tells runs=10 from runs=20
    out = {key: request[key] for key in ("runs", "episodes", "seed")
           if request.get(key) is not None}
    for key, value in _flatten(dict(request.get("params") or {})).items():
        out.setdefault(key, value)
    for key in ("options", "partition"):
        if request.get(key) is not None:
            out[key] = request[key]
    return out


def _number(value: Any) -> float | None:
    """``value`` as a number if it is one or a numeric string (``"0.5"``), else None."""
    if isinstance(value, bool):
        return None
    if isinstance(value, int | float):
        return float(value)
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            return None
    return None


def _matches(actual: Any, wanted: Any) -> bool:
    """Does a parameter value match a ``where`` value?

    Numbers match by value, also when either is stored or given as text (``alpha`` is kept as
    the text a learner was given, so ``"1.0"``, ``1`` and ``"1"`` all match); booleans and
    ``null`` are read from JSON text (``true``, ``null``); everything else compares as is.
    """
    a, w = _number(actual), _number(wanted)
    if a is not None and w is not None:
        return a == w
    if isinstance(wanted, str) and not isinstance(actual, str):
        try:
            wanted = json.loads(wanted)
        except ValueError:
            return False
    if isinstance(actual, bool) or isinstance(wanted, bool):
        return isinstance(actual, bool) and isinstance(wanted, bool) and actual == wanted
    return actual == wanted


def _flatten(values: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested mappings as dotted keys: ``{"gap": {"mean": 1}}`` -> ``{"gap.mean": 1}``."""
    out: dict[str, Any] = {}
    for key, value in values.items():
        if isinstance(value, Mapping) and value:
            out.update(_flatten(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def _column(values: list[Any]) -> pa.Array:
    """One Arrow column from plain values: bool, int64, float64 or string (JSON for the rest)."""
    present = [v for v in values if v is not None]
    if present and all(isinstance(v, bool) for v in present):
        return pa.array(values, pa.bool_())
    if present and all(isinstance(v, int) and not isinstance(v, bool) and -(2**63) <= v < 2**63
                       for v in present):
        return pa.array(values, pa.int64())
    if present and all(isinstance(v, int | float) and not isinstance(v, bool) for v in present):
        return pa.array([None if v is None else float(v) for v in values], pa.float64())
    return pa.array([v if v is None or isinstance(v, str) else _strict_dumps(v, sort_keys=True)
                     for v in values], pa.string())


def strict(value: Any) -> Any:
    """``value`` made strict-JSON-ready: NaN and infinities become ``None``, datetimes ISO text,
    numpy scalars and arrays plain numbers and lists, tuples lists, paths text."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {str(k): strict(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [strict(v) for v in value]
    if isinstance(value, datetime):
        return value.isoformat()
    if isinstance(value, np.ndarray):
        return strict(value.tolist())
    if isinstance(value, np.generic):
        return strict(value.item())
    if isinstance(value, PurePath):
        return str(value)
    return value


def _strict_dumps(value: Any, **kwargs: Any) -> str:
    return json.dumps(strict(value), allow_nan=False, **kwargs)


def strict_json(value: Any, *, indent: int | None = 2) -> str:
    """JSON any strict parser reads: no ``NaN``/``Infinity`` (they become ``null``)."""
    return _strict_dumps(value, indent=indent)


def json_rows(table: pa.Table) -> list[dict[str, Any]]:
    """The rows of a table as strict-JSON-ready objects (what ``kb ls --json`` prints)."""
    return [strict(row) for row in table.to_pylist()]


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, str):
        return value
    return json.dumps(value, separators=(",", ":"))


def _summary(record: E.Record) -> str:
    """A short line saying what the record is (the ``summary`` column)."""
    shown = " ".join(f"{k}={_fmt(v)}" for k, v in _key_params(record).items()
                     if v is not None and not isinstance(v, Mapping | list))
    if isinstance(record, E.Environment):
        return f"{record.name} S={record.n_states} A={record.n_actions}"
    if isinstance(record, E.Task):
        return f"{record.name} gamma={record.gamma:g}"
    if isinstance(record, E.Policy):
        parts = [record.learner, f"seed={record.seed}", f"episodes={record.episodes}"]
        return " ".join(parts)
    if isinstance(record, E.Run):
        on = ""
        if record.partition_id is not None and "partition" not in _key_params(record):
            on = f" partition=partition:{record.partition_id}"
        return " ".join(p for p in (record.learner, shown, on.strip()) if p)
    if isinstance(record, E.SubgoalSet):
        return f"{record.detector} states={len(record.states)}"
    if isinstance(record, E.Option):
        gamma = f" gamma={record.gamma:g}" if record.gamma is not None else ""
        return f"{record.name}{gamma}"
    if isinstance(record, E.Partition):
        return (f"{record.kind} blocks={record.n_blocks} options={len(record.option_ids)} "
                f"epsilon={record.epsilon:g} delta={record.delta:g}")
    if isinstance(record, E.Artifact):
        shape = "x".join(str(n) for n in record.shape) if record.shape is not None else ""
        return " ".join(p for p in (record.kind, record.format, record.dtype or "", shape) if p)
    return shown


def _whole(value: Any) -> int | None:
    return value if isinstance(value, int) and not isinstance(value, bool) else None


def _per_run(run: E.Run) -> dict[str, Any] | None:
    """A run record's stored per-run figures, or None when it has none (or they are not the
    shape ``per_run_to_bound`` writes: lists of one length, a finite bound)."""
    data = run.metrics.get(PER_RUN)
    if not isinstance(data, Mapping):
        return None
    lists = [data.get(name) for name in _PER_RUN_LISTS]
    if not all(isinstance(v, list) for v in lists) or len({len(v) for v in lists}) != 1:  # type: ignore[arg-type]
        return None
    if _number(data.get("bound")) is None or _number(data.get("fraction")) is None:
        return None
    return data


def _parse_ref(value: str, kind: str) -> int | None:
    match = _REF.match(value)
    if match is None:
        return None
    if match.group("kind") != kind:
        raise StoreError(f"{value!r} is not a {kind}; give {kind}:N")
    return int(match.group("id"))


class Tables:
    """``records_table``, ``runs_table``, ``curves_table`` and ``partition_table``: the
    knowledge base as ``pyarrow.Table`` objects (``.to_pandas()``, ``polars.from_arrow``)."""

    # ------------------------------------------------------------------ selection
    def _environment_ids(self, env: Any) -> set[int]:
        if isinstance(env, E.Environment):
            return {env.id}
        if isinstance(env, int | np.integer):
            return {int(env)}
        text = str(env)
        record_id = int(text) if text.isdigit() else _parse_ref(text, "environment")
        envs = self.records("environment")
        if record_id is not None:
            found = {e.id for e in envs if e.id == record_id}
        else:
            found = {e.id for e in envs if e.name == text or e.model_hash == text}
        if not found:
            names = sorted({e.name for e in envs})
            raise StoreError(f"no environment {text!r} in {self.label}; it has "
                             f"{', '.join(names) or 'none'} (`adpart kb ls environment`)")
        return found

    def _task_ids(self, task: Any, env_ids: set[int] | None) -> set[int]:
        if isinstance(task, E.Task):
            return {task.id}
        if isinstance(task, int | np.integer):
            return {int(task)}
        text = str(task)
        record_id = int(text) if text.isdigit() else _parse_ref(text, "task")
        tasks = [t for t in self.records("task")
                 if env_ids is None or t.environment_id in env_ids]
        if record_id is not None:
            found = {t.id for t in tasks if t.id == record_id}
        else:
            found = {t.id for t in tasks if t.name == text}
        if not found:
            names = sorted({t.name for t in tasks})
            raise StoreError(f"no task {text!r} in {self.label}"
                             + (" for that environment" if env_ids is not None else "")
                             + f"; it has {', '.join(names) or 'none'} (`adpart kb ls task`)")
        return found

    def select_records(self, kind: str | Sequence[str] | None = None, *, env: Any = None,
                       task: Any = None, learner: str | None = None,
                       where: Mapping[str, Any] | None = None, limit: int | None = None,
                       damaged: list[str] | None = None) -> list[E.Record]:
        """The records :meth:`records_table` shows, as frozen records (same filters)."""
        if damaged is not None:
            with self.tolerating_damage(damaged):
                return self.select_records(kind, env=env, task=task, learner=learner,
                                           where=where, limit=limit)
        kinds = self._kinds(kind)
        if limit is not None and (not isinstance(limit, int) or limit < 1):
            raise StoreError(f"limit must be a positive whole number, not {limit!r}")
        if "artifact" in kinds and (env is not None or task is not None):
            raise StoreError("artifacts belong to no environment or task; drop the env/task "
                             "filter to list them")
        env_ids = self._environment_ids(env) if env is not None else None
        task_ids = self._task_ids(task, env_ids) if task is not None else None
        tasks = {t.id: t for t in self.records("task")}
        out: list[E.Record] = []
        for k in kinds:
            for record in self.records(k):
                env_id, task_id = self._owner(record, tasks)
                if env_ids is not None and env_id not in env_ids:
                    continue
                if task_ids is not None and task_id not in task_ids:
                    continue
                if learner is not None and getattr(record, "learner", None) != learner:
                    continue
                out.append(record)
        if where:
            out = self._where(out, where)
        return out[:limit] if limit is not None else out

    @staticmethod
    def _kinds(kind: str | Sequence[str] | None) -> list[str]:
        if kind is None:
            return list(LISTED_KINDS)
        kinds = [kind] if isinstance(kind, str) else list(kind)
        for k in kinds:
            if k not in E.RECORD_TYPES:
                raise StoreError(f"unknown record kind {k!r}; use one of "
                                 f"{', '.join(E.RECORD_TYPES)}")
        return list(dict.fromkeys(kinds))

    @staticmethod
    def _owner(record: E.Record, tasks: Mapping[int, E.Task]) -> tuple[int | None, int | None]:
        """(environment id, task id) of a record; either may be None."""
        if isinstance(record, E.Environment):
            return record.id, None
        if isinstance(record, E.Task):
            return record.environment_id, record.id
        task_id = getattr(record, "task_id", None)
        env_id = getattr(record, "environment_id", None)
        if env_id is None and task_id is not None and task_id in tasks:
            env_id = tasks[task_id].environment_id
        return env_id, task_id

    @staticmethod
    def _where(records: list[E.Record], where: Mapping[str, Any]) -> list[E.Record]:
        flat = [flat_params(r) for r in records]
        known = set().union(*flat) if flat else set()
        out = list(zip(records, flat, strict=True))
        for key, wanted in where.items():
            name = key.removeprefix("params.")
            if records and name not in known:
                raise StoreError(f"no listed record has a parameter {name!r}; their parameters "
                                 f"are {', '.join(sorted(known)) or 'none'}")
            out = [(r, p) for r, p in out if name in p and _matches(p[name], wanted)]
        return [r for r, _ in out]

    # ------------------------------------------------------------------ tables
    def records_table(self, kind: str | Sequence[str] | None = None, *, env: Any = None,
                      task: Any = None, learner: str | None = None,
                      where: Mapping[str, Any] | None = None, limit: int | None = None,
                      damaged: list[str] | None = None) -> pa.Table:
        """Records as a table, one row each, oldest first within each kind.

        Args:
            kind: a record kind (``"run"``, ``"policy"``, ...), several, or None for every kind
                but artifacts.
            env: an environment name, id, ``environment:N`` or record: only its records.
            task: a task name, id, ``task:N`` or record: only its records (runs, policies,
                partitions of that task).
            learner: a learner plugin's name: only the runs and policies it made.
            where: ``{parameter: value}``, all of which must hold (numbers compare by value,
                strings from the command line are read as JSON first: ``"1"`` matches 1). Names
                are those of the ``params.*`` columns (:func:`flat_params`).
            limit: at most this many rows.
            damaged: a list to collect damaged records in: each is left out and named there
                (table, id and, where one is at fault, column). Without it the first damaged
                record raises :class:`StoreError`.

        Columns: :data:`BASE_COLUMNS` (``size`` is the bytes of the record's artifacts,
        ``created`` its creation time in UTC), then ``params.NAME`` for each parameter and, for
        runs, ``metrics.NAME`` for each final metric.
        """
        if damaged is not None:
            with self.tolerating_damage(damaged):
                return self.records_table(kind, env=env, task=task, learner=learner,
                                          where=where, limit=limit)
        with gc_paused():
            records = self.select_records(kind, env=env, task=task, learner=learner,
                                          where=where, limit=limit)
            return self._records_to_table(records)

    def records_page(self, kind: str | Sequence[str] | None = None, *, limit: int,
                     damaged: list[str] | None = None, **filters: Any) -> tuple[pa.Table, int]:
        """The first ``limit`` rows of :meth:`records_table` (same filters) and how many records
        match in all: what ``adpart kb ls`` prints a page of. Every matching record is read and
        verified (a damaged one is named even off the page); only the page becomes a table."""
        if damaged is not None:
            with self.tolerating_damage(damaged):
                return self.records_page(kind, limit=limit, **filters)
        with gc_paused():
            records = self.select_records(kind, **filters)
            return self._records_to_table(records[:limit]), len(records)

    def runs_table(self, *, env: Any = None, task: Any = None, learner: str | None = None,
                   where: Mapping[str, Any] | None = None, limit: int | None = None,
                   damaged: list[str] | None = None) -> pa.Table:
        """Every run of the selected run records as a row: its time to the success bound.

        A run record holds ``K`` runs (replicates) of one learning request; each is a row, with
        the figures the run stored when it was learned (``metrics["per_run"]``, from
        :func:`adpart.learning.comparison.per_run_to_bound`: the pipeline's and the
        comparisons' own definition of episodes to the bound). Filters as
        :meth:`records_table` (``learner``: the learner plugin's name); ``limit``: at most this
        many rows.

        Columns: :data:`RUN_COLUMNS`. ``episodes_to_bound`` and ``steps_to_bound`` are the first
        evaluated episode from which the run's value gap stays within ``bound`` (``fraction``
        of ``|V*(start)|``) and the primitive steps up to its end; where ``censored`` is true
        the run never stayed within it and they are where it was last seen outside (the
        budget): pass ``(episodes_to_bound, censored)`` to a survival estimator, or drop the
        censored rows before a mean. A run record written before these figures were stored
        (or on a task with no ``V*``) is one row with ``replicate`` and the figures null.
        """
        if damaged is not None:
            with self.tolerating_damage(damaged):
                return self.runs_table(env=env, task=task, learner=learner, where=where,
                                       limit=limit)
        if limit is not None and (not isinstance(limit, int) or limit < 1):
            raise StoreError(f"limit must be a positive whole number, not {limit!r}")
        records = self.select_records("run", env=env, task=task, learner=learner, where=where)
        envs = {e.id: e for e in self.records("environment")}
        tasks = {t.id: t for t in self.records("task")}
        rows: list[dict[str, Any]] = []
        for run in records:
            env_id, task_id = self._owner(run, tasks)
            base = {"run": run.ref, "run_id": run.id,
                    "env": envs[env_id].name if env_id in envs else None,
                    "environment_id": env_id,
                    "task": tasks[task_id].name if task_id in tasks else None,
                    "task_id": task_id, "learner": run.learner, "partition_id": run.partition_id,
                    "seed": run.seed, "episodes": _whole(run.metrics.get("episodes")),
                    "created": run.provenance.created_at}
            per_run = _per_run(run)
            if per_run is None:
                rows.append({**base, "replicate": None})
                continue
            for k in range(len(per_run["censored"])):
                rows.append({**base, "replicate": k, "fraction": per_run["fraction"],
                             "bound": per_run["bound"],
                             **{name: per_run[name][k] for name in _PER_RUN_LISTS}})
            if limit is not None and len(rows) >= limit:
                break
        rows = rows[:limit] if limit is not None else rows
        return pa.table({name: pa.array([r.get(name) for r in rows], type)
                         for name, type in RUN_COLUMNS.items()})

    def _records_to_table(self, records: list[E.Record]) -> pa.Table:
        envs = {e.id: e for e in self.records("environment")}
        tasks = {t.id: t for t in self.records("task")}
        sizes = self._artifact_sizes()
        rows: list[dict[str, Any]] = []
        param_keys: dict[str, None] = {}
        metric_keys: dict[str, None] = {}
        for record in records:
            env_id, task_id = self._owner(record, tasks)
            params = flat_params(record)
            metrics = (_flatten({k: v for k, v in record.metrics.items() if k != PER_RUN})
                       if isinstance(record, E.Run) else {})
            param_keys.update(dict.fromkeys(params))
            metric_keys.update(dict.fromkeys(metrics))
            if isinstance(record, E.Artifact):
                size, created = record.bytes, record.created_at
            else:
                shas = [getattr(record, f) for f in type(record).ARTIFACTS if getattr(record, f)]
                # unknown (None) when one of its artifact rows is damaged
                size = (sum(int(sizes[sha]) for sha in shas)
                        if all(sha in sizes for sha in shas) else None)
                created = record.provenance.created_at
            rows.append({
                "ref": record.ref, "kind": record.KIND, "id": record.id,
                "env": envs[env_id].name if env_id in envs else None,
                "environment_id": env_id,
                "task": tasks[task_id].name if task_id in tasks else None,
                "task_id": task_id, "learner": getattr(record, "learner", None),
                "summary": _summary(record), "created": created, "size": size,
                "params": params, "metrics": metrics,
            })
        columns: dict[str, pa.Array] = {
            name: pa.array([r[name] for r in rows], type) for name, type in BASE_COLUMNS.items()}
        for key in param_keys:
            columns[f"params.{key}"] = _column([r["params"].get(key) for r in rows])
        for key in metric_keys:
            columns[f"metrics.{key}"] = _column([r["metrics"].get(key) for r in rows])
        return pa.table(columns)

    def _artifact_sizes(self) -> dict[str, int]:
        """sha256 -> bytes of every artifact row whose row hash holds (the ``size`` column).

        Read as plain tuples (no ORM objects or mappings: a listing touches every artifact
        row), each with its :func:`~adpart.store.integrity.row_text` when rows are verified,
        and verified in one pass; a damaged row is reported like any other and its size left
        out.
        """
        table = SqlArtifact.__table__
        verify = self._verify_rows
        checked = (row_text(table), table.c[ROW_SHA]) if verify else ()
        query = select(table.c.sha256, table.c.bytes, *checked)
        try:
            with self._session() as s:
                rows = s.execute(query).all()
        except (StoreError, *UNREADABLE):  # a row the driver cannot decode: one by one
            with self.tolerating_damage(self._damage if self._damage is not None else []):
                return {a.sha256: a.bytes for a in self.records("artifact")}
        sizes: dict[str, int] = {}
        if not verify:
            return {sha: size for sha, size in rows}
        for sha, size, text, stored in rows:
            if text_digest(table, text) != stored:
                self._damaged(changed_message(f"artifact:{str(sha)[:16]}", table.name)
                              if stored is not None else
                              unhashed_message(f"artifact:{str(sha)[:16]}", table.name))
                continue
            sizes[sha] = size
        return sizes

    def curves_table(self, runs: Any = None, *, env: Any = None, task: Any = None,
                     where: Mapping[str, Any] | None = None, limit: int | None = None,
                     ) -> pa.Table:
        """Learning curves of runs in long format: one row per (run record, replicate, episode).

        ``runs`` is a run record, id, ``"run:N"``, a list of them, or a table from
        :meth:`records_table` (its rows of kind ``run``); None selects runs with the filters of
        :meth:`records_table`. Columns: ``run_id`` (the run record's id), then the stored
        curve's columns as written (for ``adpart learn``: ``run`` (replicate 0..K-1),
        ``episode``, ``steps``, ``decisions``, ``return``, ``discounted_return``,
        ``eval_value``, ``value_gap``). Runs without a curve are left out; curves with different
        columns are combined with nulls where a column is missing.
        """
        if runs is None:
            chosen = self.select_records("run", env=env, task=task, where=where, limit=limit)
        else:
            if any(x is not None for x in (env, task, where, limit)):
                raise StoreError("pass either runs or the env/task/where/limit filters, not both")
            chosen = [self.get("run", i) for i in self._run_ids(runs)]
        parts = []
        for run in chosen:
            curve = self.load(run, "curve")
            if curve is None:
                continue
            curve = curve.replace_schema_metadata(None)
            ids = pa.array(np.full(curve.num_rows, run.id, dtype=np.int64))
            parts.append(curve.add_column(0, "run_id", ids))
        if not parts:
            return pa.table({"run_id": pa.array([], pa.int64())})
        return pa.concat_tables(parts, promote_options="permissive")

    @staticmethod
    def _run_ids(runs: Any) -> list[int]:
        if isinstance(runs, pa.Table):
            if "kind" not in runs.column_names or "id" not in runs.column_names:
                raise StoreError("a table of runs needs the kind and id columns of "
                                 "records_table")
            return [int(i) for k, i in zip(runs.column("kind").to_pylist(),
                                           runs.column("id").to_pylist(), strict=True)
                    if k == "run"]
        items: Iterable[Any] = ([runs] if isinstance(runs, str | int | np.integer | E.Record)
                                else runs)
        out = []
        for item in items:
            if isinstance(item, E.Run):
                out.append(item.id)
            elif isinstance(item, E.Record):
                raise StoreError(f"{item.ref} is not a run")
            elif isinstance(item, int | np.integer):
                out.append(int(item))
            else:
                record_id = _parse_ref(str(item), "run")
                if record_id is None:
                    raise StoreError(f"{item!r} is not a run id; give run:N")
                out.append(record_id)
        return out

    def partition_table(self, partition: Any) -> pa.Table:
        """A partition's blocks: one row per state, columns ``state`` and ``block`` (int64).

        ``partition`` is a partition record, id or ``"partition:N"``.
        """
        if isinstance(partition, E.Partition):
            record = partition
        else:
            if isinstance(partition, int | np.integer):
                record_id: int | None = int(partition)
            else:
                record_id = _parse_ref(str(partition), "partition")
            if record_id is None:
                raise StoreError(f"{partition!r} is not a partition id; give partition:N")
            record = self.get("partition", record_id)
        labels = np.asarray(self.load(record, "labels"), dtype=np.int64)
        return pa.table({"state": np.arange(labels.size, dtype=np.int64), "block": labels})

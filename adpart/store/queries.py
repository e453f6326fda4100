"""Knowledge-base reads: records by id and kind, the queries, and verified artifact payloads.

A mixin of :class:`adpart.store.kb.KnowledgeBase` (which writes): the methods use its session
and artifact store. ORM rows become the frozen records of :mod:`adpart.store.entities` here.

Every row a read returns is verified first: its row hash (:func:`~adpart.store.integrity.
row_problem`) and those of the subgoal and option-set rows that make up the record. A row that
fails, or that the database driver cannot even decode (a ``parameters`` that is not JSON, a
``created_at`` that is not a time), is **damaged**: the read raises :class:`StoreError` naming
the record, the table and, where one column is at fault, the column. Inside
:meth:`Queries.tolerating_damage` the readers instead leave such records out and note each one,
which is how ``adpart kb ls`` lists the rest of a damaged knowledge base.
"""

from __future__ import annotations

import gc
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from datetime import datetime, timezone
from typing import Any

import numpy as np
import scipy.sparse as sp
from sqlalchemy import Table, bindparam, select
from sqlalchemy.exc import SQLAlchemyError
from sqlalchemy.orm import Session, selectinload, undefer

from adpart.store import entities as E
from adpart.store.artifacts import ARRAY_FORMAT
from adpart.store.errors import StoreError
from adpart.store.integrity import KIND_OF_TABLE, row_problem
from adpart.store.models import (
    Base,
    SqlArtifact,
    SqlEnvironment,
    SqlOption,
    SqlPartition,
    SqlPartitionOption,
    SqlPolicy,
    SqlRun,
    SqlSubgoal,
    SqlSubgoalSet,
    SqlTask,
    partition_parents,
)


def _loader_options(model: type[Base], verify: bool) -> tuple[Any, ...]:
    if model is SqlSubgoalSet:
        parts = selectinload(SqlSubgoalSet.subgoals)
        loaders = [parts.undefer(SqlSubgoal.row_text) if verify else parts]
    elif model is SqlPartition:
        parts = selectinload(SqlPartition.options)
        loaders = [parts.undefer(SqlPartitionOption.row_text) if verify else parts,
                   selectinload(SqlPartition.parents)]
    else:
        loaders = []
    if verify:  # last: the option a verifying read of any query of the model adds
        loaders.append(undefer(model.row_text))
    return tuple(loaders)


def _one_statement(model: type[Base], verify: bool) -> Any:
    """``select(model)`` of the row with id ``:record_id``, made once per model (a statement
    built per read costs SQLAlchemy more than the read of its row)."""
    return select(model).where(model.id == bindparam("record_id")).options(
        *_LOADERS[model, verify])


_SQL_OF: dict[str, type[Base]] = {
    "environment": SqlEnvironment, "task": SqlTask, "policy": SqlPolicy,
    "subgoal-set": SqlSubgoalSet, "option": SqlOption, "partition": SqlPartition, "run": SqlRun,
    "artifact": SqlArtifact,
}

#: (model, verifying) -> the loader options of its reads, made once (an option made per read
#: costs SQLAlchemy about as much again as the read of one row)
_LOADERS: dict[tuple[type[Base], bool], tuple[Any, ...]] = {
    (model, verify): _loader_options(model, verify)
    for model in _SQL_OF.values() for verify in (False, True)}
_ONE: dict[tuple[type[Base], bool], Any] = {
    key: _one_statement(*key) for key in _LOADERS}
#: an artifact's row by its hash ``:sha`` (verifying or not), and its id
_ARTIFACT_BY_SHA = {verify: select(SqlArtifact).where(SqlArtifact.sha256 == bindparam("sha"))
                    .options(*_LOADERS[SqlArtifact, verify]) for verify in (False, True)}
_ARTIFACT_ID_BY_SHA = select(SqlArtifact.id).where(SqlArtifact.sha256 == bindparam("sha"))


#: what a driver raises when a stored value cannot be decoded (bad JSON, bad time, bad text)
UNREADABLE = (SQLAlchemyError, ValueError, TypeError, AttributeError, OverflowError)


def _utc(moment: datetime) -> datetime:
    if not isinstance(moment, datetime):
        raise TypeError(f"created_at is {type(moment).__name__}, not a time")
    if moment.tzinfo is None:
        return moment.replace(tzinfo=timezone.utc)
    return moment.astimezone(timezone.utc)


def _first_line(exc: BaseException) -> str:
    orig = getattr(exc, "orig", None) or exc
    text = str(orig).splitlines()[0] if str(orig) else ""
    return f"{type(orig).__name__}: {text[:200]}"


def recover(session: Session, exc: BaseException, *, keep: bool) -> None:
    """Make ``session`` usable again after a read that could not decode a row.

    A value the driver cannot decode (SQLite text that is not JSON or not a time) leaves the
    transaction intact. A database error does not on PostgreSQL: a read-only session is rolled
    back; a transaction that must be kept (``keep``: a write in progress) cannot go on.
    """
    if not isinstance(exc, SQLAlchemyError) or session.get_bind().dialect.name == "sqlite":
        return
    if keep:
        raise StoreError(f"a row cannot be read inside this write ({_first_line(exc)}); the "
                         "write was abandoned: run `adpart kb check`") from exc
    session.rollback()


def _raise(message: str) -> None:
    raise StoreError(message)


def _fix(ref: str) -> str:
    return (f"re-create the record (`adpart kb rm {ref} --yes`, then run it again) or restore "
            "the database from a backup; `adpart kb check` lists all damage")


#: the rows a record is made of besides its own: (table, column holding the record's id)
_PARTS: dict[str, tuple[tuple[Table, str], ...]] = {
    "subgoal_sets": ((SqlSubgoal.__table__, "subgoal_set_id"),),
    "partitions": ((SqlPartitionOption.__table__, "partition_id"),
                   (partition_parents, "child_id")),
}


def unreadable_message(session: Session, table: Table, record_id: Any,
                       exc: BaseException) -> str:
    """Name the column of row ``record_id`` of ``table`` (or of its part rows) that cannot be
    decoded; ``exc`` is what reading the whole row raised."""
    ref = f"{KIND_OF_TABLE.get(table.name, table.name)}:{record_id}"
    for part, key in ((table, "id"), *_PARTS.get(table.name, ())):
        for column in part.columns:
            try:
                session.execute(select(column).where(part.c[key] == record_id)).all()
            except UNREADABLE as col_exc:
                recover(session, col_exc, keep=False)
                return (f"{ref} is damaged: {part.name}.{column.name} cannot be read "
                        f"({_first_line(col_exc)}); {_fix(ref)}")
    return f"{ref} is damaged: its row cannot be read ({_first_line(exc)}); {_fix(ref)}"


def _id(value: E.Record | int | None) -> int | None:
    if value is None or isinstance(value, int | np.integer):
        return None if value is None else int(value)
    return value.id


@contextmanager
def gc_paused() -> Iterator[None]:
    """Pause the cyclic garbage collector for one bulk read, and resume it as it was.

    A listing builds an ORM object and a record per row, all alive until the read ends, and
    none of them can be garbage before it does; the allocations trigger collections that scan
    every one of them again (a quarter of ``kb ls``'s CPU time over 10^4 records). Reference
    counting still frees what a read drops.
    """
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


class Queries:
    """``get``, ``artifact``, ``records``, ``find_environment``, ``options_for``,
    ``partitions_using``, ``runs_for``, ``learned_tasks``, ``lineage``, ``load``,
    ``option_transitions`` and ``read_artifact``."""

    # ------------------------------------------------------------------ conversion
    @staticmethod
    def _provenance(row: Any) -> E.Provenance:
        return E.Provenance(row.adpart_version, row.plugin, row.plugin_version,
                            dict(row.parameters or {}), _utc(row.created_at), row.schema_version)

    def _entity(self, row: Base) -> Any:
        if isinstance(row, SqlArtifact):
            return E.Artifact(row.id, row.sha256, row.uri, row.format, row.bytes,
                              row.file_sha256, row.kind,
                              row.dtype, tuple(row.shape) if row.shape is not None else None,
                              _utc(row.created_at))
        p = self._provenance(row)
        if isinstance(row, SqlEnvironment):
            return E.Environment(row.id, row.name, dict(row.spec), row.model_hash,
                                 int(row.n_states), int(row.n_actions), p)
        if isinstance(row, SqlTask):
            return E.Task(row.id, row.environment_id, row.name, dict(row.spec), row.spec_hash,
                          float(row.gamma), p)
        if isinstance(row, SqlPolicy):
            return E.Policy(row.id, row.task_id, row.learner, row.seed, row.episodes, row.steps,
                            row.q_sha, row.pi_sha, p)
        if isinstance(row, SqlSubgoalSet):
            return E.SubgoalSet(row.id, row.environment_id, row.policy_id, row.detector,
                                row.scores_sha, tuple(int(g.state) for g in row.subgoals),
                                tuple(g.id for g in row.subgoals), p)
        if isinstance(row, SqlOption):
            return E.Option(row.id, row.environment_id, row.subgoal_id, row.name, row.gamma,
                            row.initiation_sha, row.policy_sha, row.termination_sha,
                            row.reward_sha, row.transitions_sha, p)
        if isinstance(row, SqlPartition):
            return E.Partition(row.id, row.environment_id, row.task_id, row.kind,
                               tuple(o.option_id for o in row.options),
                               bool(row.includes_primitives), float(row.epsilon),
                               float(row.delta), int(row.n_blocks), row.labels_sha,
                               row.block_actions_sha, tuple(r.id for r in row.parents), p)
        if isinstance(row, SqlRun):
            return E.Run(row.id, row.task_id, row.partition_id, row.learner, row.seed,
                         row.curve_sha, row.experience_sha, dict(row.metrics or {}), p)
        raise TypeError(type(row).__name__)

    #: verify the row hash of every row read (the benchmark turns it off to measure its cost)
    _verify_rows: bool = True
    _damage: list[str] | None = None

    @contextmanager
    def tolerating_damage(self, damaged: list[str]) -> Iterator[list[str]]:
        """Inside this block readers leave damaged records out, appending a line naming each to
        ``damaged`` (once), instead of raising :class:`StoreError`: a listing of what is
        readable. ``get`` of a damaged record still raises."""
        outer = self._damage
        self._damage = damaged
        try:
            yield damaged
        finally:
            self._damage = outer

    def _damaged(self, message: str) -> None:
        """Report one damaged record: raise, or note it inside :meth:`tolerating_damage`."""
        if self._damage is None:
            raise StoreError(message)
        if message not in self._damage:
            self._damage.append(message)

    def _verified(self, row: Base) -> Any:
        """The record of a row read from the database, its row hashes checked first."""
        if self._verify_rows:
            parts: list[Base] = [row]
            if isinstance(row, SqlSubgoalSet):
                parts += row.subgoals
            elif isinstance(row, SqlPartition):
                parts += row.options
            for part in parts:
                problem = row_problem(part)
                if problem is not None:
                    if part is not row:
                        problem = (f"{KIND_OF_TABLE[row.__tablename__]}:{row.id} is damaged "
                                   f"(one of its rows): {problem}")
                    raise StoreError(problem)
        try:
            return self._entity(row)
        except UNREADABLE as exc:
            ref = f"{KIND_OF_TABLE.get(row.__tablename__, row.__tablename__)}:{row.id}"
            raise StoreError(f"{ref} is damaged: its row holds a value of the wrong kind "
                             f"({_first_line(exc)}); {_fix(ref)}") from exc

    def _read_records(self, session: Session, model: type[Base], query: Any, ids: Any, *,
                      strict: bool = False, params: dict[str, Any] | None = None) -> list[Any]:
        """:meth:`_read_verified` with the garbage collector paused (:func:`gc_paused`)."""
        with gc_paused():
            return self._read_verified(session, model, query, ids, strict=strict, params=params)

    def _read_verified(self, session: Session, model: type[Base], query: Any, ids: Any, *,
                       strict: bool = False, params: dict[str, Any] | None = None) -> list[Any]:
        """The verified records of ``query`` (ORM rows of ``model``, read with
        :meth:`_loaders`' options); ``ids`` selects the same rows' ids, read when the whole result
        cannot be decoded, to read row by row; both take ``params``.

        A damaged row raises :class:`StoreError`, or inside :meth:`tolerating_damage` is noted
        and left out; ``strict`` (a lookup of one record) always raises.
        """
        damaged = self._damaged if not strict else _raise
        keep = session is self._tx
        try:
            rows = list(session.scalars(query, params).all())
        except UNREADABLE as exc:
            recover(session, exc, keep=keep)
            rows = None
        out = []
        if rows is not None:
            for row in rows:
                try:
                    out.append(self._verified(row))
                except StoreError as exc:
                    damaged(str(exc))
            return out
        for (record_id,) in session.execute(ids, params).all():
            try:
                row = session.scalars(_ONE[model, self._verify_rows]
                                      .execution_options(populate_existing=True),
                                      {"record_id": record_id}).one()
            except UNREADABLE as exc:
                recover(session, exc, keep=keep)
                damaged(unreadable_message(session, model.__table__, record_id, exc))
                continue
            try:
                out.append(self._verified(row))
            except StoreError as exc:
                damaged(str(exc))
        return out

    def _loaders(self, model: type[Base]) -> tuple[Any, ...]:
        """The loader options of a read of ``model``: its parts loaded with it, and when rows
        are verified, each row's :class:`~adpart.store.integrity.RowText` read with it."""
        return _LOADERS[model, self._verify_rows]

    # ------------------------------------------------------------------ gets and queries
    def get(self, kind: str, record_id: int) -> Any:
        """The record of ``kind`` (``"policy"``, ...) with id ``record_id``."""
        model = self._model(kind)
        record_id = int(record_id)
        with self._session() as s:
            try:
                row = s.scalars(_ONE[model, self._verify_rows],
                                {"record_id": record_id}).first()
            except UNREADABLE as exc:
                recover(s, exc, keep=s is self._tx)
                raise StoreError(unreadable_message(s, model.__table__, record_id, exc)) from exc
            if row is None:
                raise StoreError(f"no {kind}:{record_id} in {self.label}; list them with "
                                 f"`adpart kb ls {kind}`")
            return self._verified(row)

    def artifact(self, sha_prefix: str) -> E.Artifact:
        """The artifact whose hash starts with ``sha_prefix`` (unique prefix required)."""
        if not sha_prefix or any(c not in "0123456789abcdef" for c in sha_prefix):
            raise StoreError(f"{sha_prefix!r} is not a hexadecimal artifact hash prefix")
        where = SqlArtifact.sha256.startswith(sha_prefix, autoescape=True)
        with self._session() as s:
            rows = self._read_records(s, SqlArtifact, select(SqlArtifact).where(where).limit(2)
                                      .options(*self._loaders(SqlArtifact)),
                                      select(SqlArtifact.id).where(where).limit(2), strict=True)
        if not rows:
            raise StoreError(f"no artifact with hash {sha_prefix}...; list them with "
                             "`adpart kb ls artifact`")
        if len(rows) > 1:
            raise StoreError(f"artifact hash prefix {sha_prefix} is ambiguous; give more digits")
        return rows[0]

    @staticmethod
    def _model(kind: str) -> type[Base]:
        try:
            return _SQL_OF[kind]
        except KeyError:
            raise StoreError(f"unknown record kind {kind!r}; use one of "
                             f"{', '.join(_SQL_OF)}") from None

    def records(self, kind: str, *, environment: E.Environment | int | None = None,
                limit: int | None = None) -> list[Any]:
        """All records of ``kind`` (oldest first), optionally only those of one environment."""
        model = self._model(kind)

        def chosen(query: Any) -> Any:
            env_id = _id(environment)
            if env_id is not None:
                if hasattr(model, "environment_id"):
                    query = query.where(model.environment_id == env_id)
                elif hasattr(model, "task_id"):
                    query = query.join(SqlTask, SqlTask.id == model.task_id).where(
                        SqlTask.environment_id == env_id)
                elif kind == "environment":
                    query = query.where(model.id == env_id)
            query = query.order_by(model.id)
            return query.limit(limit) if limit is not None else query

        with self._session() as s:
            return self._read_records(s, model,
                                      chosen(select(model).options(*self._loaders(model))),
                                      chosen(select(model.id)))

    def find_environment(self, name_or_hash: str) -> E.Environment:
        """The environment with this name (most recent) or model hash."""
        where = ((SqlEnvironment.name == name_or_hash)
                 | (SqlEnvironment.model_hash == name_or_hash))
        with self._session() as s:
            rows = self._read_records(s, SqlEnvironment, select(SqlEnvironment).where(where)
                              .order_by(SqlEnvironment.id.desc()).limit(1)
                              .options(*self._loaders(SqlEnvironment)),
                              select(SqlEnvironment.id).where(where)
                              .order_by(SqlEnvironment.id.desc()).limit(1), strict=True)
            if not rows:
                raise StoreError(f"no environment named {name_or_hash!r} in {self.label}; list "
                                 "them with `adpart kb ls environment`")
            return rows[0]

    def options_for(self, environment: E.Environment | int) -> list[E.Option]:
        """Every option stored for an environment."""
        return self.records("option", environment=environment)

    def partitions_using(self, options: Iterable[E.Option | int], *, exact: bool = True,
                         includes_primitives: bool | None = None) -> list[E.Partition]:
        """Partitions built from exactly this option set (``exact``) or from a superset of it."""
        wanted = {_id(o) for o in options}
        def chosen(query: Any) -> Any:
            if wanted:
                query = query.where(SqlPartition.id.in_(
                    select(SqlPartitionOption.partition_id).where(
                        SqlPartitionOption.option_id.in_(wanted))))
            if includes_primitives is not None:
                query = query.where(SqlPartition.includes_primitives == includes_primitives)
            return query.order_by(SqlPartition.id)

        with self._session() as s:
            records = self._read_records(s, SqlPartition, chosen(select(SqlPartition).options(
                *self._loaders(SqlPartition))), chosen(select(SqlPartition.id)))
        return [p for p in records
                if ((set(p.option_ids) == wanted) if exact else wanted <= set(p.option_ids))]

    def runs_for(self, task: E.Task | int) -> list[E.Run]:
        """Every run of a task, oldest first."""
        where = SqlRun.task_id == _id(task)
        with self._session() as s:
            return self._read_records(s, SqlRun, select(SqlRun).where(where).order_by(SqlRun.id)
                                      .options(*self._loaders(SqlRun)),
                                      select(SqlRun.id).where(where).order_by(SqlRun.id))

    def learned_tasks(self, environment: E.Environment | int | None = None,
                      ) -> list[tuple[E.Task, list[E.Run]]]:
        """Tasks that have runs, with their runs (a run's curve: ``load(run, "curve")``)."""
        tasks = self.records("task", environment=environment)
        runs = self.records("run", environment=environment)
        by_task: dict[int, list[E.Run]] = {}
        for run in runs:
            by_task.setdefault(run.task_id, []).append(run)
        return [(t, by_task[t.id]) for t in tasks if t.id in by_task]

    def lineage(self, partition: E.Partition | int) -> list[E.Partition]:
        """The ancestors of a partition, nearest first (breadth-first over parent links)."""
        start = self.get("partition", _id(partition))
        seen: set[int] = {start.id}
        frontier = list(start.parent_ids)
        out: list[E.Partition] = []
        while frontier:
            nxt: list[int] = []
            for pid in frontier:
                if pid in seen:
                    continue
                seen.add(pid)
                parent = self.get("partition", pid)
                out.append(parent)
                nxt.extend(parent.parent_ids)
            frontier = nxt
        return out

    # ------------------------------------------------------------------ payloads
    def load(self, record: E.Record, field_name: str) -> Any:
        """The payload of one artifact field of a record, verified against its hash.

        Arrays come back as numpy arrays, tables as pyarrow Tables; ``None`` if the field is empty.
        A damaged artifact raises :class:`StoreError` naming the artifact and ``record.ref``.
        """
        fmt = type(record).ARTIFACTS.get(field_name)
        if fmt is None:
            raise StoreError(f"{record.ref} has no artifact field {field_name!r}; it has "
                             f"{', '.join(type(record).ARTIFACTS) or 'none'}")
        sha = getattr(record, field_name)
        if sha is None:
            return None
        context = f"{record.ref} ({field_name})"
        try:
            art = self._artifact_row(sha)
        except StoreError as exc:
            raise StoreError(f"{context}: {exc}") from exc
        read = self.artifacts.get_array if fmt == "array" else self.artifacts.get_table
        return read(sha, art.uri, context=context, file_sha256=art.file_sha256)

    def option_transitions(self, option: E.Option) -> sp.csr_array | None:
        """An option's discounted transition model F_o as a CSR array of shape (S, S)."""
        table = self.load(option, "transitions")
        if table is None:
            return None
        S, _ = self._env_shape(option.environment_id)
        cols = {name: table.column(name).to_numpy() for name in ("row", "col", "value")}
        return sp.csr_array((cols["value"], (cols["row"], cols["col"])), shape=(S, S))

    def read_artifact(self, artifact: E.Artifact | str) -> Any:
        """The payload of an artifact (by record or full hash), naming its referrers on damage."""
        art = artifact if isinstance(artifact, E.Artifact) else self._artifact_row(artifact)
        context = ", ".join(self.referrers().get(art.sha256, [])) or "no record"
        read = self.artifacts.get_array if art.format == ARRAY_FORMAT else self.artifacts.get_table
        return read(art.sha256, art.uri, context=context, file_sha256=art.file_sha256)

    def _artifact_row(self, sha: str) -> E.Artifact:
        with self._session() as s:
            rows = self._read_records(s, SqlArtifact, _ARTIFACT_BY_SHA[self._verify_rows],
                                      _ARTIFACT_ID_BY_SHA, strict=True, params={"sha": sha})
            if not rows:
                raise StoreError(f"artifact {sha[:12]} has no row in {self.label}; run "
                                 "`adpart kb check`")
            return rows[0]

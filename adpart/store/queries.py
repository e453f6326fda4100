"""Knowledge-base reads: records by id and kind, the queries, and verified artifact payloads.

A mixin of :class:`adpart.store.kb.KnowledgeBase` (which writes): the methods use its session
and artifact store. ORM rows become the frozen records of :mod:`adpart.store.entities` here.
"""

from __future__ import annotations

from collections.abc import Iterable
from datetime import datetime, timezone
from typing import Any

import numpy as np
import scipy.sparse as sp
from sqlalchemy import select
from sqlalchemy.orm import selectinload

from adpart.store import entities as E
from adpart.store.artifacts import ARRAY_FORMAT
from adpart.store.errors import StoreError
from adpart.store.models import (
    Base,
    SqlArtifact,
    SqlEnvironment,
    SqlOption,
    SqlPartition,
    SqlPartitionOption,
    SqlPolicy,
    SqlRun,
    SqlSubgoalSet,
    SqlTask,
)

_SQL_OF: dict[str, type[Base]] = {
    "environment": SqlEnvironment, "task": SqlTask, "policy": SqlPolicy,
    "subgoal-set": SqlSubgoalSet, "option": SqlOption, "partition": SqlPartition, "run": SqlRun,
    "artifact": SqlArtifact,
}


def _utc(moment: datetime) -> datetime:
    return moment if moment.tzinfo is not None else moment.replace(tzinfo=timezone.utc)


def _id(value: E.Record | int | None) -> int | None:
    if value is None or isinstance(value, int | np.integer):
        return None if value is None else int(value)
    return value.id


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

    @staticmethod
    def _loaders(model: type[Base]) -> list[Any]:
        if model is SqlSubgoalSet:
            return [selectinload(SqlSubgoalSet.subgoals)]
        if model is SqlPartition:
            return [selectinload(SqlPartition.options), selectinload(SqlPartition.parents)]
        return []

    # ------------------------------------------------------------------ gets and queries
    def get(self, kind: str, record_id: int) -> Any:
        """The record of ``kind`` (``"policy"``, ...) with id ``record_id``."""
        model = self._model(kind)
        with self._session() as s:
            row = s.scalars(select(model).where(model.id == int(record_id))
                            .options(*self._loaders(model))).first()
            if row is None:
                raise StoreError(f"no {kind}:{record_id} in {self.label}; list them with "
                                 f"`adpart kb ls {kind}`")
            return self._entity(row)

    def artifact(self, sha_prefix: str) -> E.Artifact:
        """The artifact whose hash starts with ``sha_prefix`` (unique prefix required)."""
        if not sha_prefix or any(c not in "0123456789abcdef" for c in sha_prefix):
            raise StoreError(f"{sha_prefix!r} is not a hexadecimal artifact hash prefix")
        with self._session() as s:
            rows = s.scalars(select(SqlArtifact).where(
                SqlArtifact.sha256.startswith(sha_prefix, autoescape=True)).limit(2)).all()
        if not rows:
            raise StoreError(f"no artifact with hash {sha_prefix}...; list them with "
                             "`adpart kb ls artifact`")
        if len(rows) > 1:
            raise StoreError(f"artifact hash prefix {sha_prefix} is ambiguous; give more digits")
        return self._entity(rows[0])

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
        query = select(model).options(*self._loaders(model)).order_by(model.id)
        env_id = _id(environment)
        if env_id is not None:
            if hasattr(model, "environment_id"):
                query = query.where(model.environment_id == env_id)
            elif hasattr(model, "task_id"):
                query = query.join(SqlTask, SqlTask.id == model.task_id).where(
                    SqlTask.environment_id == env_id)
            elif kind == "environment":
                query = query.where(model.id == env_id)
        if limit is not None:
            query = query.limit(limit)
        with self._session() as s:
            return [self._entity(r) for r in s.scalars(query).all()]

    def find_environment(self, name_or_hash: str) -> E.Environment:
        """The environment with this name (most recent) or model hash."""
        with self._session() as s:
            row = s.scalars(select(SqlEnvironment).where(
                (SqlEnvironment.name == name_or_hash) | (SqlEnvironment.model_hash == name_or_hash)
            ).order_by(SqlEnvironment.id.desc())).first()
            if row is None:
                raise StoreError(f"no environment named {name_or_hash!r} in {self.label}; list "
                                 "them with `adpart kb ls environment`")
            return self._entity(row)

    def options_for(self, environment: E.Environment | int) -> list[E.Option]:
        """Every option stored for an environment."""
        return self.records("option", environment=environment)

    def partitions_using(self, options: Iterable[E.Option | int], *, exact: bool = True,
                         includes_primitives: bool | None = None) -> list[E.Partition]:
        """Partitions built from exactly this option set (``exact``) or from a superset of it."""
        wanted = {_id(o) for o in options}
        with self._session() as s:
            query = select(SqlPartition).options(*self._loaders(SqlPartition)).order_by(
                SqlPartition.id)
            if wanted:
                query = query.where(SqlPartition.id.in_(
                    select(SqlPartitionOption.partition_id).where(
                        SqlPartitionOption.option_id.in_(wanted))))
            if includes_primitives is not None:
                query = query.where(SqlPartition.includes_primitives == includes_primitives)
            rows = s.scalars(query).all()
            out = []
            for row in rows:
                have = {o.option_id for o in row.options}
                if (have == wanted) if exact else wanted <= have:
                    out.append(self._entity(row))
            return out

    def runs_for(self, task: E.Task | int) -> list[E.Run]:
        """Every run of a task, oldest first."""
        with self._session() as s:
            rows = s.scalars(select(SqlRun).where(SqlRun.task_id == _id(task))
                             .order_by(SqlRun.id)).all()
            return [self._entity(r) for r in rows]

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
        art = self._artifact_row(sha)
        context = f"{record.ref} ({field_name})"
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
            row = s.scalars(select(SqlArtifact).where(SqlArtifact.sha256 == sha)).first()
            if row is None:
                raise StoreError(f"artifact {sha[:12]} has no row in {self.label}; run "
                                 "`adpart kb check`")
            return self._entity(row)

"""Knowledge-base maintenance: record counts, the full audit (``kb check``), removal of a record
(``kb rm``) and garbage collection (``kb gc``).

A mixin of :class:`adpart.store.kb.KnowledgeBase`: the methods use its session, artifact store and
entity conversion, and add nothing to the record API itself.

The audit sees everything: the engine's own integrity check, every row of every table against its
content hash (:mod:`adpart.store.integrity`), every reference, every artifact's hashes and every
file under the artifact root. Garbage collection is mark and sweep under the exclusive store lock,
rows first and files only after that commit; it never follows a symlink and never deletes a file
adpart did not write. docs/reliability.md states the guarantees and the tests that pin them.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

from sqlalchemy import Table, func, select
from sqlalchemy.exc import SQLAlchemyError
from sqlalchemy.orm import Session

from adpart.store.errors import StoreError
from adpart.store.integrity import ROW_SHA, row_digest
from adpart.store.models import (
    ARTIFACT_COLUMNS,
    HASHED_TABLES,
    SqlArtifact,
    SqlPolicy,
    SqlRun,
    SqlSubgoalSet,
    partition_parents,
)


@dataclass(frozen=True)
class CheckReport:
    """What :meth:`KnowledgeBase.check` found. ``problems`` are damage; the rest is housekeeping.

    ``orphan_records`` are records nothing refers to that only exist as part of another (a
    policy no run or subgoal set lists: a write interrupted before whole-record transactions);
    ``stray_files`` are files under the artifact root that adpart did not write and never
    touches; ``skipped`` are symlinks under the root, never followed.
    """

    artifacts_checked: int
    problems: list[str] = field(default_factory=list)
    orphan_files: list[str] = field(default_factory=list)
    temporary_files: list[str] = field(default_factory=list)
    orphan_records: list[str] = field(default_factory=list)
    stray_files: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    rows_checked: int = 0

    @property
    def ok(self) -> bool:
        return not self.problems


@dataclass(frozen=True)
class GcReport:
    """Unreferenced artifacts (sha256, bytes) and files (path, bytes) found or removed.

    ``records`` are orphan records (``policy:3``) found (removed with ``orphans=True``);
    ``strays`` and ``skipped`` are reported only: gc never deletes a file it did not write, and
    never follows a symlink.
    """

    artifacts: list[tuple[str, int]]
    files: list[tuple[str, int]]
    deleted: bool
    records: list[str] = field(default_factory=list)
    strays: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)

    @property
    def bytes(self) -> int:
        return sum(b for _, b in self.artifacts) + sum(b for _, b in self.files)


def _referrers(session: Session) -> dict[str, list[str]]:
    from adpart.store.queries import _SQL_OF

    kinds = {model: kind for kind, model in _SQL_OF.items()}
    out: dict[str, list[str]] = {}
    for model, columns in ARTIFACT_COLUMNS.items():
        for column in columns:
            col = getattr(model, column)
            for rid, sha in session.execute(select(model.id, col).where(col.is_not(None))):
                out.setdefault(sha, []).append(
                    f"{kinds[model]}:{rid} ({column.removesuffix('_sha')})")
    return out


def _orphan_policies(session: Session) -> list[int]:
    """Policies that no run lists (``parameters["policies"]``) and no subgoal set was found from.

    adpart stores a policy only as part of a learning run (``record_learning``, one transaction
    since schema 2), so such a policy is what a write killed between the two left behind.
    """
    listed: set[int] = set()
    for (params,) in session.execute(select(SqlRun.parameters)):
        for pid in (params or {}).get("policies", []) or []:
            if isinstance(pid, int):
                listed.add(pid)
    used = {pid for (pid,) in session.execute(select(SqlSubgoalSet.policy_id)
                                             .where(SqlSubgoalSet.policy_id.is_not(None)))}
    return [pid for (pid,) in session.execute(select(SqlPolicy.id).order_by(SqlPolicy.id))
            if pid not in listed and pid not in used]


_KIND_OF_TABLE = {"environments": "environment", "tasks": "task", "policies": "policy",
                  "subgoal_sets": "subgoal-set", "subgoals": "subgoal", "options": "option",
                  "partitions": "partition", "partition_options": "partition-option",
                  "runs": "run", "artifacts": "artifact"}


def _row_name(table: Table, row: Any) -> str:
    kind = _KIND_OF_TABLE.get(table.name, table.name)
    if table.name == "artifacts":
        return f"artifact:{str(row['sha256'])[:16]}"
    if table.name == "partition_options":
        return f"partition:{row['partition_id']}'s option link to option:{row['option_id']}"
    if table.name == "subgoals":
        return f"subgoal:{row['id']} (of subgoal-set:{row['subgoal_set_id']})"
    return f"{kind}:{row['id']}"


class Maintenance:
    """``referrers``, ``counts``, ``artifact_bytes``, ``info``, ``check`` and ``gc``."""

    def referrers(self) -> dict[str, list[str]]:
        """sha256 -> the records referencing it, as ``"policy:3 (q)"``."""
        with self._session() as s:
            return _referrers(s)

    def counts(self) -> dict[str, int]:
        """Number of records of each kind."""
        from adpart.store.queries import _SQL_OF

        with self._session() as s:
            return {kind: int(s.scalar(select(func.count()).select_from(model)) or 0)
                    for kind, model in _SQL_OF.items()}

    def artifact_bytes(self) -> int:
        with self._session() as s:
            return int(s.scalar(select(func.coalesce(func.sum(SqlArtifact.bytes), 0))) or 0)

    def info(self) -> dict[str, Any]:
        """Location, schema version, record counts and artifact bytes (for ``adpart kb info``)."""
        return {"location": self.label, "database": self.engine.url.render_as_string(True),
                "artifacts": self.artifact_uri, "schema_version": self.schema_version,
                "counts": self.counts(), "artifact_bytes": self.artifact_bytes()}

    # ------------------------------------------------------------------ check
    def _engine_integrity(self) -> list[str]:
        """The engine's own check: SQLite ``PRAGMA integrity_check`` (other engines: none)."""
        if self.engine.dialect.name != "sqlite":
            return []
        try:
            with self.engine.connect() as conn:
                lines = [str(r[0]) for r in conn.exec_driver_sql("PRAGMA integrity_check")]
        except SQLAlchemyError as exc:
            orig = getattr(exc, "orig", None) or exc
            return [(f"the database file fails SQLite's integrity check ({orig}); restore "
                     "kb.sqlite from a backup")]
        if lines == ["ok"]:
            return []
        return [f"the database file fails SQLite's integrity check: {'; '.join(lines[:5])}"
                + (f" (and {len(lines) - 5} more)" if len(lines) > 5 else "")
                + "; restore kb.sqlite from a backup"]

    def _read_rows(self, conn: Any, table: Table) -> tuple[list[Any], list[str]]:
        """Every row of ``table``; a row that cannot be read is named instead of returned."""
        try:
            return list(conn.execute(select(table)).mappings().all()), []
        except (SQLAlchemyError, ValueError) as exc:
            whole = exc
        try:  # find the rows at fault, one by one
            ids = [r[0] for r in conn.execute(select(*table.primary_key.columns))]
        except SQLAlchemyError as exc:
            orig = getattr(exc, "orig", None) or exc
            return [], [(f"table {table.name} cannot be read ({orig}); the database is "
                         "damaged: restore it from a backup")]
        rows, bad = [], []
        key = table.primary_key.columns[0]
        for rid in ids:
            try:
                rows.extend(conn.execute(select(table).where(key == rid)).mappings().all())
            except (SQLAlchemyError, ValueError) as exc:
                orig = getattr(exc, "orig", None) or exc
                bad.append(f"{_KIND_OF_TABLE.get(table.name, table.name)}:{rid} cannot be read "
                           f"({type(orig).__name__}: {str(orig).splitlines()[0]}); its row is "
                           "damaged: re-create the record (`adpart kb rm`, then run it again)")
        if not bad:
            bad.append(f"table {table.name} cannot be read ({whole})")
        return rows, bad

    def _row_problems(self) -> tuple[int, list[str]]:
        """Read every table and compare each row with its stored content hash."""
        problems: list[str] = []
        checked = 0
        with self.engine.connect() as conn:
            try:
                links: dict[int, list[int]] = {}
                for child, parent in conn.execute(select(partition_parents.c.child_id,
                                                         partition_parents.c.parent_id)):
                    links.setdefault(int(child), []).append(int(parent))
            except SQLAlchemyError as exc:
                orig = getattr(exc, "orig", None) or exc
                problems.append(f"table partition_parents cannot be read ({orig}); restore the "
                                "database from a backup")
            for table in HASHED_TABLES:
                rows, bad = self._read_rows(conn, table)
                problems.extend(bad)
                for row in rows:
                    checked += 1
                    parents = links.get(int(row["id"]), []) if table.name == "partitions" else None
                    stored = row[ROW_SHA]
                    if stored is None:
                        problems.append(f"{_row_name(table, row)} has no row hash; run "
                                        "`adpart kb upgrade`, or re-create the record")
                    elif row_digest(table, row, parents) != stored:
                        problems.append(
                            f"{_row_name(table, row)} is damaged: its metadata row changed "
                            "since it was written (row hash mismatch); re-create the record "
                            "(`adpart kb rm`, then run it again) or restore from a backup")
        return checked, problems

    def check(self) -> CheckReport:
        """The full audit: the engine's integrity check, every row against its hash, every
        reference, every artifact's hashes and every file under the root."""
        problems = self._engine_integrity()
        rows_checked, row_problems = self._row_problems()
        problems += row_problems
        try:
            with self._session() as s:
                refs = _referrers(s)
                rows = [self._entity(r) for r in s.scalars(select(SqlArtifact)).all()]
                orphan_records = [f"policy:{pid}" for pid in _orphan_policies(s)]
        except StoreError as exc:
            return CheckReport(0, [*problems, str(exc)], rows_checked=rows_checked)
        known = {a.sha256 for a in rows}
        for sha, who in sorted(refs.items()):
            if sha not in known:
                problems.append(f"{', '.join(who)} reference artifact {sha[:12]}, which has no row")
        uris = set()
        for art in rows:
            context = ", ".join(refs.get(art.sha256, [])) or "no record"
            try:
                uris.add(art.uri)
                self.artifacts.verify(art.sha256, art.uri, art.format, context=context,
                                      file_sha256=art.file_sha256)
            except StoreError as exc:
                problems.append(str(exc))
        scan = self.artifacts.scan()
        orphans = [rel for rel, _, _ in scan.files if rel not in uris]
        temps = [rel for rel, _, _ in scan.temporary]
        return CheckReport(len(rows), problems, orphans, temps, orphan_records, scan.strays,
                           scan.skipped, rows_checked)

    # ------------------------------------------------------------------ rm
    def remove(self, kind: str, record_id: int, *, dry_run: bool = False) -> list[str]:
        """Delete one record (a run with the policies it lists) in one transaction.

        Returns the refs removed. A record that another still refers to is refused with a
        :class:`StoreError` naming the fix; its artifacts stay until ``gc`` finds them unused.
        """
        from sqlalchemy.exc import IntegrityError

        from adpart.store.queries import _SQL_OF

        model = _SQL_OF[kind]
        removed = [f"{kind}:{record_id}"]
        try:
            with self._session(write=True) as s:
                row = s.get(model, int(record_id))
                if row is None:
                    raise StoreError(f"no {kind}:{record_id} in {self.label}; list them with "
                                     f"`adpart kb ls {kind}`")
                rows = [row]
                if model is SqlRun:
                    for pid in (row.parameters or {}).get("policies", []) or []:
                        policy = s.get(SqlPolicy, pid) if isinstance(pid, int) else None
                        if policy is not None:
                            rows.append(policy)
                            removed.append(f"policy:{pid}")
                if dry_run:
                    return removed
                for item in rows:
                    s.delete(item)
                s.flush()
        except StoreError as exc:
            if isinstance(exc.__cause__, IntegrityError):
                raise StoreError(f"{kind}:{record_id} is still referred to by other records "
                                 "(e.g. a partition, option or run built from it); remove "
                                 "those first") from exc
            raise
        return removed

    # ------------------------------------------------------------------ gc
    def gc(self, *, delete: bool = False, temporary_age_s: float = 3600.0,
           grace_s: float = 3600.0, orphans: bool = False) -> GcReport:
        """Find (and with ``delete=True`` remove) what no record references.

        Mark and sweep, in two steps, each holding the store lock exclusively (SQLite's write
        lock; on PostgreSQL an advisory lock every writer holds shared until it commits):

        1. in one transaction, drop the artifact rows no record references (and, with
           ``orphans``, the orphan records :meth:`check` lists), then commit;
        2. in a second locked step, re-read the rows and delete the files that have none: the
           files of the rows just dropped, other artifact files with no row that are older
           than ``grace_s`` (younger ones may belong to a write about to commit) and ``.tmp-*``
           files older than ``temporary_age_s``.

        Files go only after the commit that drops their rows, so a failure part-way leaves at
        most files without rows (reported by ``check``, removed by the next gc), never a row
        without its file. Nothing outside the artifact root is touched: symlinks are never
        followed (``skipped``) and files adpart did not write are only reported (``strays``).
        """
        from sqlalchemy import delete as sql_delete

        records: list[str] = []
        with self._session(write=delete, exclusive=True) as s:
            found = _orphan_policies(s)
            records = [f"policy:{pid}" for pid in found]
            if delete and orphans and found:
                s.execute(sql_delete(SqlPolicy).where(SqlPolicy.id.in_(found)))
            refs = _referrers(s)
            rows = s.execute(select(SqlArtifact.sha256, SqlArtifact.bytes,
                                    SqlArtifact.uri)).all()
            dead = [(sha, int(size), uri) for sha, size, uri in rows if sha not in refs]
            if delete and dead:
                s.execute(sql_delete(SqlArtifact).where(
                    SqlArtifact.sha256.in_([sha for sha, _, _ in dead])))
        dead_uris = {uri for _, _, uri in dead}
        with self._session(write=delete, exclusive=True) as s:
            live = {uri for (uri,) in s.execute(select(SqlArtifact.uri))}
            now = time.time()
            scan = self.artifacts.scan()
            files = [(rel, size) for rel, size, mtime in scan.files
                     if rel not in live and rel not in dead_uris and now - mtime > grace_s]
            files += [(rel, size) for rel, size, mtime in scan.temporary
                      if now - mtime > temporary_age_s]
            if delete:
                for rel in [*(u for u in dead_uris if u not in live), *(r for r, _ in files)]:
                    try:
                        self.artifacts.delete(rel)
                    except (StoreError, OSError) as exc:
                        raise StoreError(
                            f"gc stopped while deleting {rel}: {exc}; the rows were already "
                            "dropped, so nothing is damaged: run `adpart kb gc --yes` again to "
                            "remove the remaining files") from exc
        return GcReport([(sha, b) for sha, b, _ in dead], files, delete, records,
                        scan.strays, scan.skipped)

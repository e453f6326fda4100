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
from adpart.store.integrity import (
    KIND_OF_TABLE,
    ROW_SHA,
    ROW_TEXT,
    changed_message,
    row_name,
    row_text,
    text_digest,
    unhashed_message,
)
from adpart.store.models import (
    ARTIFACT_COLUMNS,
    HASHED_TABLES,
    SqlArtifact,
    SqlPolicy,
    SqlRun,
    SqlSubgoalSet,
    partition_parents,
)
from adpart.store.queries import UNREADABLE, recover, unreadable_message


def _unreadable_database(label: str, exc: BaseException) -> str:
    orig = getattr(exc, "orig", None) or exc
    return (f"the database of {label} cannot be read ({type(orig).__name__}: "
            f"{str(orig).splitlines()[0] if str(orig) else ''}); restore it from a backup")


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
    #: what gc could not do and left in place, one line each (a file it was refused deleting,
    #: a damaged row that hides what is referenced); the rest of the round was done
    failures: list[str] = field(default_factory=list)

    @property
    def bytes(self) -> int:
        return sum(b for _, b in self.artifacts) + sum(b for _, b in self.files)


def _column_rows(session: Any, table: Table, *columns: Any,
                 keep: bool = False) -> tuple[list[Any], list[str]]:
    """``(id, *columns)`` of every row of ``table``; a row whose values cannot be decoded is
    named (record, table, column) instead of returned, and the others are still read."""
    query = select(table.c.id, *columns).order_by(table.c.id)
    try:
        return list(session.execute(query).all()), []
    except UNREADABLE as exc:
        recover(session, exc, keep=keep)
    rows: list[Any] = []
    problems: list[str] = []
    for (rid,) in session.execute(select(table.c.id).order_by(table.c.id)).all():
        try:
            rows.extend(session.execute(query.where(table.c.id == rid)).all())
        except UNREADABLE as exc:
            recover(session, exc, keep=keep)
            problems.append(unreadable_message(session, table, rid, exc))
    return rows, problems


def _references(session: Any, keep: bool = False) -> tuple[dict[str, list[str]], list[str]]:
    """sha256 -> the records referencing it (``"policy:3 (q)"``), and the rows whose references
    cannot be read (then the map may miss what they reference)."""
    from adpart.store.queries import _SQL_OF

    kinds = {model: kind for kind, model in _SQL_OF.items()}
    out: dict[str, list[str]] = {}
    problems: list[str] = []
    for model, columns in ARTIFACT_COLUMNS.items():
        rows, bad = _column_rows(session, model.__table__,
                                 *(getattr(model, c) for c in columns), keep=keep)
        problems.extend(bad)
        for rid, *shas in rows:
            for column, sha in zip(columns, shas, strict=True):
                if sha is not None:
                    out.setdefault(str(sha), []).append(
                        f"{kinds[model]}:{rid} ({column.removesuffix('_sha')})")
    return out, problems


def _referrers(session: Session) -> dict[str, list[str]]:
    return _references(session)[0]


def _orphan_policies(session: Any, keep: bool = False) -> tuple[list[int], list[str]]:
    """Policies that no run lists (``parameters["policies"]``) and no subgoal set was found from.

    adpart stores a policy only as part of a learning run (``record_learning``, one transaction
    since schema 2), so such a policy is what a write killed between the two left behind. When a
    run's parameters or a subgoal set cannot be read, which policies they list is unknown: no
    policy is called an orphan, and the second value names the rows at fault.
    """
    runs, bad = _column_rows(session, SqlRun.__table__, SqlRun.parameters, keep=keep)
    sets, bad_sets = _column_rows(session, SqlSubgoalSet.__table__, SqlSubgoalSet.policy_id,
                                  keep=keep)
    policies, bad_policies = _column_rows(session, SqlPolicy.__table__, keep=keep)
    problems = bad + bad_sets + bad_policies
    if problems:
        return [], problems
    listed: set[int] = set()
    for _, params in runs:
        listing = params.get("policies", []) if isinstance(params, dict) else []
        for pid in listing if isinstance(listing, list) else []:
            if isinstance(pid, int):
                listed.add(pid)
    used = {pid for _, pid in sets if pid is not None}
    return [pid for (pid,) in policies if pid not in listed and pid not in used], []


def _remove_by_id(session: Session, table: Table, record_id: int) -> None:
    """Delete a row that cannot be loaded, and the rows that are part of it. A damaged run's
    policies cannot be read from it: they stay, as orphans ``kb gc --orphans`` removes."""
    from sqlalchemy import delete as sql_delete

    from adpart.store.queries import _PARTS

    for part, key in _PARTS.get(table.name, ()):
        session.execute(sql_delete(part).where(part.c[key] == record_id))
    session.execute(sql_delete(table).where(table.c.id == record_id))


def _with_referrers(problem: str, refs: dict[str, list[str]]) -> str:
    """A damaged artifact row's problem, with the records that reference the artifact."""
    if not problem.startswith("artifact:"):
        return problem
    prefix = problem.split(" ", 1)[0].removeprefix("artifact:")
    who = [r for sha, rs in refs.items() if sha.startswith(prefix) for r in rs]
    return f"{problem} (referenced by {', '.join(who)})" if who else problem


def _dedupe(lines: list[str]) -> list[str]:
    return list(dict.fromkeys(lines))


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
        except (SQLAlchemyError, UnicodeDecodeError) as exc:
            orig = getattr(exc, "orig", None) or exc
            return [(f"the database file fails SQLite's integrity check ({orig}); restore "
                     "kb.sqlite from a backup")]
        if lines == ["ok"]:
            return []
        return [f"the database file fails SQLite's integrity check: {'; '.join(lines[:5])}"
                + (f" (and {len(lines) - 5} more)" if len(lines) > 5 else "")
                + "; restore kb.sqlite from a backup"]

    def _read_rows(self, conn: Any, table: Table) -> tuple[list[Any], list[str]]:
        """Every row of ``table`` with its :func:`~adpart.store.integrity.row_text`; a row that
        cannot be read is named instead of returned."""
        whole_table = select(table, row_text(table))
        try:
            return list(conn.execute(whole_table).mappings().all()), []
        except UNREADABLE as exc:
            recover(conn, exc, keep=False)
            whole = exc
        try:  # find the rows at fault, one by one
            ids = [r[0] for r in conn.execute(select(*table.primary_key.columns))]
        except UNREADABLE as exc:
            recover(conn, exc, keep=False)
            orig = getattr(exc, "orig", None) or exc
            return [], [(f"table {table.name} cannot be read ({orig}); the database is "
                         "damaged: restore it from a backup")]
        rows, bad = [], []
        key = table.primary_key.columns[0]
        for rid in ids:
            try:
                rows.extend(conn.execute(whole_table.where(key == rid)).mappings().all())
            except UNREADABLE as exc:
                recover(conn, exc, keep=False)
                if "id" in table.c:
                    bad.append(unreadable_message(conn, table, rid, exc))
                else:
                    orig = getattr(exc, "orig", None) or exc
                    bad.append(f"{KIND_OF_TABLE.get(table.name, table.name)}:{rid} cannot be "
                               f"read ({type(orig).__name__}: {str(orig).splitlines()[0]}); its "
                               "row is damaged: re-create the record (`adpart kb rm`, then run "
                               "it again)")
        if not bad:
            bad.append(f"table {table.name} cannot be read ({whole})")
        return rows, bad

    def _row_problems(self) -> tuple[int, list[str]]:
        """Read every table and compare each row with its stored content hash."""
        problems: list[str] = []
        checked = 0
        with self.engine.connect() as conn:
            links: dict[int, list[int]] = {}
            try:
                for child, parent in conn.execute(select(partition_parents.c.child_id,
                                                         partition_parents.c.parent_id)):
                    links.setdefault(int(child), []).append(int(parent))
            except (*UNREADABLE, ValueError) as exc:
                recover(conn, exc, keep=False)
                orig = getattr(exc, "orig", None) or exc
                problems.append(f"table partition_parents cannot be read ({orig}); restore the "
                                "database from a backup")
            for table in HASHED_TABLES:
                rows, bad = self._read_rows(conn, table)
                problems.extend(bad)
                for row in rows:
                    checked += 1
                    parents = None
                    if table.name == "partitions":
                        parents = links.get(row["id"], []) if isinstance(row["id"], int) else []
                    stored = row[ROW_SHA]
                    if stored is None:
                        problems.append(unhashed_message(row_name(table, row), table.name))
                    elif text_digest(table, row[ROW_TEXT], parents) != stored:
                        problems.append(changed_message(row_name(table, row), table.name))
        return checked, problems

    def check(self) -> CheckReport:
        """The full audit: the engine's integrity check, every row against its hash, every
        reference, every artifact's hashes and every file under the root."""
        problems = self._engine_integrity()
        try:
            rows_checked, row_problems = self._row_problems()
        except (*UNREADABLE, StoreError) as exc:  # the database itself cannot be read
            return CheckReport(0, [*problems, _unreadable_database(self.label, exc)])
        problems += row_problems
        try:
            with self._session() as s:
                refs, bad_refs = _references(s)
                with self.tolerating_damage(problems):
                    rows = self.records("artifact")
                found, bad_lists = _orphan_policies(s)
                orphan_records = [f"policy:{pid}" for pid in found]
                problems += bad_refs + bad_lists
        except (*UNREADABLE, StoreError) as exc:
            return CheckReport(0, _dedupe([*problems, _unreadable_database(self.label, exc)]),
                               rows_checked=rows_checked)
        problems = [_with_referrers(p, refs) for p in _dedupe(problems)]
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
        return CheckReport(len(rows), _dedupe(problems), orphans, temps, orphan_records,
                           scan.strays, scan.skipped, rows_checked)

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
                try:
                    row = s.get(model, int(record_id))
                except UNREADABLE as exc:  # a damaged row: removed by id, its parts with it
                    recover(s, exc, keep=True)
                    if not dry_run:
                        _remove_by_id(s, model.__table__, int(record_id))
                    return removed
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

        What gc cannot do it skips, names in ``failures`` and goes on with the rest of the
        round: a file it is refused deleting stays for the next gc; a damaged row that hides
        what is referenced (or which policies a run lists) means no artifact row (or orphan
        record) is dropped in this round, since gc cannot tell what that row still needs.
        """
        from sqlalchemy import delete as sql_delete

        failures: list[str] = []
        kept: set[str] = set()
        # a row whose hash fails may hide a reference (a changed *_sha) or misname a file (a
        # changed uri): then nothing is dropped on the strength of the rows
        try:
            _, damaged = self._row_problems()
        except (*UNREADABLE, StoreError) as exc:
            damaged = [_unreadable_database(self.label, exc)]
        with self._session(write=delete, exclusive=True) as s:
            found, bad_lists = _orphan_policies(s, keep=delete)
            failures += [f"orphan records not looked for: {p}" for p in bad_lists]
            records = [f"policy:{pid}" for pid in found]
            if delete and orphans and found:
                s.execute(sql_delete(SqlPolicy).where(SqlPolicy.id.in_(found)))
            refs, bad_refs = _references(s, keep=delete)
            rows, bad_rows = _column_rows(s, SqlArtifact.__table__, SqlArtifact.sha256,
                                          SqlArtifact.bytes, SqlArtifact.uri, keep=delete)
            unknown = _dedupe(damaged + bad_refs + bad_rows)
            if unknown:  # what the unreadable rows reference is unknown: drop no artifact row
                failures += [f"no artifact row dropped: {p}" for p in unknown]
                dead = []
            else:
                dead = [(str(sha), int(size or 0), str(uri)) for _, sha, size, uri in rows
                        if sha not in refs]
            if delete and dead:
                s.execute(sql_delete(SqlArtifact).where(
                    SqlArtifact.sha256.in_([sha for sha, _, _ in dead])))
        dead_uris = {uri for _, _, uri in dead}
        with self._session(write=delete, exclusive=True) as s:
            uris, bad_uris = _column_rows(s, SqlArtifact.__table__, SqlArtifact.uri, keep=delete)
            live = {str(uri) for _, uri in uris}
            now = time.time()
            scan = self.artifacts.scan()
            if unknown or bad_uris:  # a file may belong to a damaged row: keep them all
                failures += [f"no file without a row deleted: {p}"
                             for p in _dedupe(unknown + bad_uris)]
                files = []
            else:
                files = [(rel, size) for rel, size, mtime in scan.files
                         if rel not in live and rel not in dead_uris and now - mtime > grace_s]
            files += [(rel, size) for rel, size, mtime in scan.temporary
                      if now - mtime > temporary_age_s]
            if delete:
                for rel in [*(u for u in dead_uris if u not in live), *(r for r, _ in files)]:
                    try:
                        self.artifacts.delete(rel)
                    except (StoreError, OSError) as exc:
                        # the row is already gone, so nothing is damaged; the file stays (the
                        # next gc tries again) and the round goes on with the others
                        failures.append(f"kept {rel}: {exc}")
                        kept.add(rel)
            files = [(rel, size) for rel, size in files if rel not in kept]
        return GcReport([(sha, b) for sha, b, _ in dead], files, delete, records,
                        scan.strays, scan.skipped, failures)

"""Knowledge-base maintenance: record counts, the full audit (``kb check``) and garbage collection.

A mixin of :class:`adpart.store.kb.KnowledgeBase`: the methods use its session, artifact store and
entity conversion, and add nothing to the record API itself.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from sqlalchemy import func, select

from adpart.store.errors import StoreError
from adpart.store.models import ARTIFACT_COLUMNS, SqlArtifact


@dataclass(frozen=True)
class CheckReport:
    """What :meth:`KnowledgeBase.check` found. ``problems`` are damage; the rest is housekeeping."""

    artifacts_checked: int
    problems: list[str] = field(default_factory=list)
    orphan_files: list[str] = field(default_factory=list)
    temporary_files: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems


@dataclass(frozen=True)
class GcReport:
    """Unreferenced artifacts (sha256, bytes) and stray files (path, bytes) found or removed."""

    artifacts: list[tuple[str, int]]
    files: list[tuple[str, int]]
    deleted: bool

    @property
    def bytes(self) -> int:
        return sum(b for _, b in self.artifacts) + sum(b for _, b in self.files)


class Maintenance:
    """``referrers``, ``counts``, ``artifact_bytes``, ``info``, ``check`` and ``gc``."""

    def referrers(self) -> dict[str, list[str]]:
        """sha256 -> the records referencing it, as ``"policy:3 (q)"``."""
        from adpart.store.queries import _SQL_OF

        kinds = {model: kind for kind, model in _SQL_OF.items()}
        out: dict[str, list[str]] = {}
        with self._session() as s:
            for model, columns in ARTIFACT_COLUMNS.items():
                for column in columns:
                    col = getattr(model, column)
                    for rid, sha in s.execute(select(model.id, col).where(col.is_not(None))):
                        out.setdefault(sha, []).append(
                            f"{kinds[model]}:{rid} ({column.removesuffix('_sha')})")
        return out

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

    def check(self) -> CheckReport:
        """Verify every artifact's hashes, every reference and every file under the root."""
        refs = self.referrers()
        with self._session() as s:
            rows = [self._entity(r) for r in s.scalars(select(SqlArtifact)).all()]
        known = {a.sha256 for a in rows}
        problems: list[str] = []
        for sha, who in sorted(refs.items()):
            if sha not in known:
                problems.append(f"{', '.join(who)} reference artifact {sha[:12]}, which has no row")
        uris = set()
        for art in rows:
            context = ", ".join(refs.get(art.sha256, [])) or "no record"
            try:
                uris.add(self.artifacts.path(art.uri))
                self.artifacts.verify(art.sha256, art.uri, art.format, context=context,
                                      file_sha256=art.file_sha256)
            except StoreError as exc:
                problems.append(str(exc))
        orphans, temps = [], []
        for rel, _size, _mtime in self.artifacts.files():
            if self.artifacts.is_temporary(rel):
                temps.append(rel)
            elif f"{self.artifacts.base}/{rel}" not in uris:
                orphans.append(rel)
        return CheckReport(len(rows), problems, orphans, temps)

    def gc(self, *, delete: bool = False, temporary_age_s: float = 3600.0) -> GcReport:
        """Find (and with ``delete=True`` remove) artifacts no record references.

        Also finds files under the root that have no row, and ``.tmp-*`` files older than
        ``temporary_age_s`` (younger ones may belong to a write in progress).
        """
        import time

        refs = self.referrers()
        now = time.time()
        with self._session(write=delete) as s:
            rows = s.scalars(select(SqlArtifact)).all()
            dead = [(r.sha256, int(r.bytes), r.uri) for r in rows if r.sha256 not in refs]
            live_uris = {r.uri for r in rows if r.sha256 in refs}
            dead_uris = {uri for _, _, uri in dead}
            files = [(rel, size) for rel, size, mtime in self.artifacts.files()
                     if (self.artifacts.is_temporary(rel) and now - mtime > temporary_age_s)
                     or (not self.artifacts.is_temporary(rel) and rel not in live_uris
                         and rel not in dead_uris)]
            if delete:
                for sha, _, _ in dead:
                    s.execute(SqlArtifact.__table__.delete().where(SqlArtifact.sha256 == sha))
                s.flush()
                for _, _, uri in dead:
                    self.artifacts.delete(uri)
                for rel, _ in files:
                    self.artifacts.delete(rel)
        return GcReport([(sha, b) for sha, b, _ in dead], files, delete)

"""``adpart kb``: inspect and maintain the knowledge base; ``kb_option`` for other commands.

Record ids on the command line are ``KIND:N`` (``policy:12``, ``subgoal-set:3``) or
``artifact:HEX`` with a unique prefix (at least 4 hex digits) of the artifact's SHA-256.
"""

from __future__ import annotations

import functools
import json
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click
import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from adpart.cli.common import FiniteFloat, kb_location_options
from adpart.errors import AdpartError
from adpart.store.entities import RECORD_TYPES
from adpart.store.kb import KnowledgeBase
from adpart.store.location import KBLocation

_KIND_ALIASES = {
    "env": "environment",
    "environments": "environment",
    "tasks": "task",
    "policies": "policy",
    "subgoals": "subgoal-set",
    "subgoal-sets": "subgoal-set",
    "subgoal_set": "subgoal-set",
    "options": "option",
    "partitions": "partition",
    "runs": "run",
    "artifacts": "artifact",
}
FINITE_SECONDS = FiniteFloat(min=0.0, what="seconds")
_REF = re.compile(r"^(?P<kind>[a-z][a-z_-]*):(?P<id>[0-9]{1,18})$")
_ART = re.compile(r"^artifact:(?P<hex>[0-9a-f]{4,64})$")


class KBError(click.ClickException):
    """A knowledge-base error on the command line: one line, exit status 2."""

    exit_code = 2


def _kind(name: str) -> str:
    kind = _KIND_ALIASES.get(name, name)
    if kind not in RECORD_TYPES:
        raise KBError(f"unknown record kind {name!r}; use one of {', '.join(RECORD_TYPES)}")
    return kind


def kb_option(func: Callable[..., Any] | None = None, *,
              read_only: bool = False) -> Any:
    """``--kb``/``--kb-artifacts`` (shared with every command) resolved before the command runs.

    The decorated command receives ``kb_location``, a :class:`~adpart.store.KBLocation`; call
    ``KnowledgeBase.open(kb_location)`` when the command needs the knowledge base. With
    ``read_only`` (the reading commands) nothing is created: a location that holds no
    knowledge base is an error, and a read-only one can be inspected.
    """

    def decorate(func: Callable[..., Any]) -> Callable[..., Any]:
        @kb_location_options
        @functools.wraps(func)
        def wrapper(*args: Any, kb_path: str | None, kb_artifacts: str | None,
                    **kwargs: Any) -> Any:
            try:
                location = KBLocation.resolve(kb_path, kb_artifacts, create=not read_only)
            except AdpartError as exc:
                raise KBError(str(exc)) from exc
            return func(*args, kb_location=location, **kwargs)

        return wrapper

    return decorate(func) if func is not None else decorate


def _open(location: KBLocation, *, verify: bool = True, read_only: bool = False
          ) -> KnowledgeBase:
    try:
        return KnowledgeBase.open(location, verify=verify, read_only=read_only)
    except AdpartError as exc:
        raise KBError(str(exc)) from exc


def _guard(func: Callable[..., Any]) -> Callable[..., Any]:
    """Turn AdpartError raised by a command into a one-line exit-2 error."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return func(*args, **kwargs)
        except AdpartError as exc:
            raise KBError(str(exc)) from exc

    return wrapper


def _plain(value: Any) -> Any:
    """A record (dataclass) as JSON-ready data."""
    if hasattr(value, "__dataclass_fields__"):
        out = {name: _plain(getattr(value, name)) for name in value.__dataclass_fields__}
        if hasattr(value, "ref"):
            out = {"ref": value.ref, **out}
        return out
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if hasattr(value, "isoformat"):
        return value.isoformat()
    return value


def _resolve(kb: KnowledgeBase, ref: str) -> Any:
    art = _ART.match(ref)
    if art:
        return kb.artifact(art.group("hex"))
    match = _REF.match(ref)
    if not match:
        raise KBError(
            f"{ref!r} is not a record id; write KIND:N (e.g. policy:12) or "
            "artifact:HEX (a hash prefix of at least 4 digits)"
        )
    return kb.get(_kind(match.group("kind")), int(match.group("id")))


def _summary(record: Any) -> str:
    fields = {k: v for k, v in _plain(record).items() if k not in ("ref", "id", "provenance")}
    shown = ", ".join(
        f"{k}={v if not isinstance(v, str) or len(v) < 20 else v[:12]}"
        for k, v in fields.items()
        if v not in (None, {}, [])
    )
    return f"{record.ref:<22} {shown}"


@click.group(name="kb")
def kb() -> None:
    """Inspect and maintain the knowledge base.

    \b
    Ids are KIND:N (policy:12) or artifact:HEX (hash prefix).
    Examples:
      adpart kb info
      adpart kb ls option --env two-rooms
      adpart kb show partition:3 --json
      adpart kb export policy:5 --field q --out q.csv
      adpart kb check
      adpart kb gc --yes
    """


@kb.command("info")
@kb_option(read_only=True)
@click.option("--json", "as_json", is_flag=True, help="Print JSON")
@_guard
def info(kb_location: KBLocation, as_json: bool) -> None:
    """Location, schema version, record counts and artifact bytes."""
    with _open(kb_location, read_only=True) as base:
        data = base.info()
    if as_json:
        click.echo(json.dumps(data, indent=2))
        return
    click.echo(f"location:       {data['location']}")
    click.echo(f"database:       {data['database']}")
    click.echo(f"artifacts:      {data['artifacts']}")
    click.echo(f"schema version: {data['schema_version']}")
    for kind, count in data["counts"].items():
        plural = kind[:-1] + "ies" if kind.endswith("y") else kind + "s"
        click.echo(f"{plural + ':':<15} {count}")
    click.echo(f"artifact bytes: {data['artifact_bytes']}")


@kb.command("ls")
@click.argument("kind", required=False, default=None)
@click.option("--env", "env", metavar="NAME|ID", help="Only records of this environment")
@click.option("--json", "as_json", is_flag=True, help="Print JSON")
@kb_option(read_only=True)
@_guard
def ls(kb_location: KBLocation, kind: str | None, env: str | None, as_json: bool) -> None:
    """List records of KIND (all kinds when omitted)."""
    kinds = [_kind(kind)] if kind else [k for k in RECORD_TYPES if k != "artifact"]
    with _open(kb_location, read_only=True) as base:
        env_id = None
        if env is not None:
            env_id = int(env) if env.isdigit() else base.find_environment(env).id
        records = [r for k in kinds for r in base.records(k, environment=env_id)]
    if as_json:
        click.echo(json.dumps([_plain(r) for r in records], indent=2))
        return
    for record in records:
        click.echo(_summary(record))


@kb.command("show")
@click.argument("ref")
@click.option("--json", "as_json", is_flag=True, help="Print JSON")
@kb_option(read_only=True)
@_guard
def show(kb_location: KBLocation, ref: str, as_json: bool) -> None:
    """Show one record (KIND:N or artifact:HEX) with its provenance."""
    with _open(kb_location, read_only=True) as base:
        record = _resolve(base, ref)
        data = _plain(record)
        if record.KIND == "artifact":
            data["referenced_by"] = base.referrers().get(record.sha256, [])
    if as_json:
        click.echo(json.dumps(data, indent=2))
        return
    for key, value in data.items():
        if isinstance(value, dict):
            click.echo(f"{key}:")
            for k, v in value.items():
                click.echo(f"  {k}: {json.dumps(v) if isinstance(v, dict | list) else v}")
        else:
            click.echo(f"{key}: {value}")


def _as_table(value: Any) -> pa.Table:
    if isinstance(value, pa.Table):
        return value
    array = np.asarray(value)
    if array.ndim == 2:  # one row per state: the state id, then a column per action/option
        return pa.table(
            {
                "state": np.arange(array.shape[0], dtype=np.int64),
                **{f"c{j}": array[:, j] for j in range(array.shape[1])},
            }
        )
    if array.ndim == 1:  # e.g. partition labels: a column indexed by state
        return pa.table({"state": np.arange(array.size, dtype=np.int64), "value": array})
    return pa.table({"value": array.reshape(-1)})


@kb.command("export")
@click.argument("ref")
@click.option(
    "--out",
    "out",
    required=True,
    type=click.Path(dir_okay=False, path_type=Path),
    help="Output file: .parquet, .csv or .json",
)
@click.option(
    "--field",
    "field_name",
    default=None,
    help="Artifact field of a record (e.g. q, pi, labels, curve)",
)
@kb_option(read_only=True)
@_guard
def export(kb_location: KBLocation, ref: str, out: Path, field_name: str | None) -> None:
    """Write an artifact (artifact:HEX, or a record's --field) as Parquet, CSV or JSON."""
    suffix = out.suffix.lower()
    if suffix not in (".parquet", ".csv", ".json"):
        raise click.BadParameter("the file must end in .parquet, .csv or .json", param_hint="--out")
    with _open(kb_location, read_only=True) as base:
        record = _resolve(base, ref)
        if record.KIND == "artifact":
            value = base.read_artifact(record)
        else:
            fields = list(type(record).ARTIFACTS)
            if field_name is None and len(fields) == 1:
                field_name = fields[0]
            if field_name not in fields:
                raise KBError(
                    f"{record.ref} has artifact fields {', '.join(fields) or 'none'}; "
                    "choose one with --field"
                )
            value = base.load(record, field_name)
            if value is None:
                raise KBError(f"{record.ref} has no {field_name} artifact")
    table = _as_table(value)
    try:
        if suffix == ".parquet":
            pq.write_table(table, out, compression="zstd")
        elif suffix == ".csv":
            pacsv.write_csv(table, out)
        else:
            if isinstance(value, pa.Table):
                payload: Any = table.to_pydict()
            else:
                array = np.asarray(value)
                payload = {
                    "dtype": array.dtype.str,
                    "shape": list(array.shape),
                    "values": array.tolist(),
                }
            out.write_text(json.dumps(payload))
    except OSError as exc:
        raise KBError(f"cannot write {out}: {exc.strerror or exc}; choose a writable path") from exc
    click.echo(f"wrote {out}")


@kb.command("check")
@click.option("--json", "as_json", is_flag=True, help="Print JSON")
@kb_option(read_only=True)
@_guard
def check(kb_location: KBLocation, as_json: bool) -> None:
    """Verify every artifact's hash and every reference; exit 1 if anything is damaged."""
    with _open(kb_location, read_only=True) as base:
        report = base.check()
    if as_json:
        click.echo(
            json.dumps(
                {
                    "ok": report.ok,
                    "artifacts_checked": report.artifacts_checked,
                    "problems": report.problems,
                    "orphan_files": report.orphan_files,
                    "temporary_files": report.temporary_files,
                    "orphan_records": report.orphan_records,
                    "stray_files": report.stray_files,
                    "skipped_symlinks": report.skipped,
                    "rows_checked": report.rows_checked,
                },
                indent=2,
            )
        )
    else:
        for problem in report.problems:
            click.echo(f"DAMAGED: {problem}")
        for rel in report.orphan_files:
            click.echo(f"orphan file (no row; `adpart kb gc` removes it): {rel}")
        for rel in report.temporary_files:
            click.echo(f"leftover temporary file (`adpart kb gc` removes it): {rel}")
        for ref in report.orphan_records:
            click.echo(f"orphan record {ref} (nothing refers to it; `adpart kb gc --yes "
                       "--orphans` removes it)")
        for rel in report.stray_files:
            click.echo(f"stray file (not adpart's; left alone): {rel}")
        for rel in report.skipped:
            click.echo(f"symlink under the artifact root (not followed): {rel}")
        status = "ok" if report.ok else f"{len(report.problems)} problem(s)"
        click.echo(f"checked {report.rows_checked} rows and {report.artifacts_checked} "
                   f"artifacts: {status}")
    if not report.ok:
        raise SystemExit(1)


@kb.command("gc")
@click.option("--yes", is_flag=True, help="Delete (default: only list what would be deleted)")
@click.option(
    "--tmp-age",
    type=FINITE_SECONDS,
    default=3600.0,
    show_default=True,
    help="Seconds after which a .tmp-* file counts as abandoned",
)
@click.option(
    "--grace",
    type=FINITE_SECONDS,
    default=3600.0,
    show_default=True,
    help="Seconds an artifact file without a row is kept (a write may be about to commit it)",
)
@click.option("--orphans", is_flag=True,
              help="Also delete orphan records (policies no run or subgoal set refers to)")
@kb_option
@_guard
def gc(kb_location: KBLocation, yes: bool, tmp_age: float, grace: float, orphans: bool) -> None:
    """Remove artifacts no record references (dry run unless --yes).

    Safe while other processes write: files are deleted only after the rows that referenced
    them are gone, files without rows only after --grace seconds, symlinks are never followed
    and files adpart did not write are reported, never deleted.
    """
    with _open(kb_location) as base:
        report = base.gc(delete=yes, temporary_age_s=tmp_age, grace_s=grace, orphans=orphans)
    verb = "deleted" if yes else "would delete"
    for sha, size in report.artifacts:
        click.echo(f"{verb} artifact {sha[:16]} ({size} bytes)")
    for rel, size in report.files:
        click.echo(f"{verb} file {rel} ({size} bytes)")
    for ref in report.records:
        if orphans:
            click.echo(f"{verb} orphan record {ref}")
        else:
            click.echo(f"orphan record {ref} (kept; pass --orphans to delete it)")
    for rel in report.strays:
        click.echo(f"stray file {rel} (not written by adpart; not touched)")
    for rel in report.skipped:
        click.echo(f"symlink {rel} (never followed; not touched)")
    n = len(report.artifacts) + len(report.files) + (len(report.records) if orphans else 0)
    hint = "" if yes else "; pass --yes to delete"
    click.echo(f"{verb} {n} item(s), {report.bytes} bytes{hint}")


@kb.command("rm")
@click.argument("ref")
@click.option("--yes", is_flag=True, help="Remove (default: only say what would be removed)")
@kb_option
@_guard
def rm(kb_location: KBLocation, ref: str, yes: bool) -> None:
    """Remove one record (KIND:N) so it can be re-created; a run takes its policies with it.

    A record another record still refers to is refused (remove the referrer first). The
    artifacts it leaves unreferenced are removed by `adpart kb gc --yes`.
    """
    with _open(kb_location) as base:
        record = _resolve(base, ref)
        if record.KIND == "artifact":
            raise KBError("artifacts are removed by `adpart kb gc` once no record refers to "
                          "them; remove the records instead")
        removed = base.remove(record.KIND, record.id, dry_run=not yes)
    verb = "removed" if yes else "would remove"
    click.echo(f"{verb} {', '.join(removed)}" + ("" if yes else "; pass --yes to remove"))


@kb.command("upgrade")
@kb_option
@_guard
def upgrade(kb_location: KBLocation) -> None:
    """Migrate the knowledge base to this adpart's schema version."""
    with _open(kb_location, verify=False) as base:
        start, end = base.upgrade()
    click.echo(
        f"schema version {start} -> {end}"
        if start != end
        else f"schema version {end}: already current"
    )

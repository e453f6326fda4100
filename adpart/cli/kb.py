"""``adpart kb``: inspect and maintain the knowledge base; ``kb_option`` for other commands.

Record ids on the command line are ``KIND:N`` (``policy:12``, ``subgoal-set:3``) or
``artifact:HEX`` with a unique prefix (at least 4 hex digits) of the artifact's SHA-256.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import re
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from adpart.cli.common import FiniteFloat, kb_location_options
from adpart.errors import AdpartError
from adpart.store.entities import RECORD_TYPES
from adpart.store.location import KBLocation

if TYPE_CHECKING:
    import pyarrow as pa

    from adpart.store.kb import KnowledgeBase


# The store's table helpers, imported when a command runs (numpy, pyarrow and SQLAlchemy), so
# that ``adpart kb ... --help`` imports none of them.
def json_rows(table: pa.Table) -> list[dict[str, Any]]:
    from adpart.store.tables import json_rows

    return json_rows(table)


def strict(value: Any) -> Any:
    from adpart.store.tables import strict

    return strict(value)


def strict_json(data: Any, **kwargs: Any) -> str:
    from adpart.store.tables import strict_json

    return strict_json(data, **kwargs)

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
    from adpart.store.kb import KnowledgeBase

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
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        out = {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
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


@click.group(name="kb")
def kb() -> None:
    """Inspect and maintain the knowledge base.

    \b
    Ids are KIND:N (policy:12) or artifact:HEX (hash prefix).
    Examples:
      adpart kb info
      adpart kb ls option --env two-rooms
      adpart kb ls run --where alpha=0.5 --json
      adpart kb runs --env three-floor
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
        click.echo(strict_json(data))
        return
    click.echo(f"location:       {data['location']}")
    click.echo(f"database:       {data['database']}")
    click.echo(f"artifacts:      {data['artifacts']}")
    click.echo(f"schema version: {data['schema_version']}")
    for kind, count in data["counts"].items():
        plural = kind[:-1] + "ies" if kind.endswith("y") else kind + "s"
        click.echo(f"{plural + ':':<15} {count}")
    click.echo(f"artifact bytes: {data['artifact_bytes']}")


def _where_items(items: tuple[str, ...]) -> dict[str, Any]:
    """``--where KEY=VALUE`` options as a mapping (VALUE read as JSON when it is, else text)."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise KBError(f"--where {item!r} is not KEY=VALUE; write e.g. --where alpha=0.5")
        try:
            out[key.strip()] = json.loads(value)
        except ValueError:
            out[key.strip()] = value
    return out


def _size(n: int | None) -> str:
    if not n:
        return "-"
    for unit in ("B", "kB", "MB", "GB"):
        if n < 1000 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000
    return str(n)  # pragma: no cover


def _cell(value: Any, width: int) -> str:
    text = "-" if value is None else str(value)
    return text if len(text) <= width else text[: width - 3] + "..."


#: the columns of `kb ls`: (header, records-table column, widest cell)
_LS_COLUMNS = (("ID", "ref", 22), ("KIND", "kind", 11), ("ENV", "env", 20), ("TASK", "task", 20),
               ("SUMMARY", "summary", 60), ("CREATED", "created", 16), ("SIZE", "size", 9))


def _shared_settings(records: list[dict[str, Any]]) -> list[str]:
    """The ``KEY=VALUE`` words every listed run's summary has (none for fewer than two runs):
    left out of the table's cells, so what is left tells the runs apart."""
    words = [rec["summary"].split()[1:] for rec in records
             if rec["kind"] == "run" and rec["summary"]]
    if len(words) < 2:
        return []
    common = set(words[0]).intersection(*words[1:])
    return [w for w in words[0] if w in common and "=" in w]


def _ls_rows(table: pa.Table) -> tuple[list[list[str]], list[str]]:
    """The cells of `kb ls`, and the settings every run shares (left out of their cells)."""
    records = table.select([c for _, c, _ in _LS_COLUMNS]).to_pylist()
    shared = set(_shared_settings(records))
    rows = []
    for rec in records:
        created = rec["created"].strftime("%Y-%m-%d %H:%M") if rec["created"] else None
        summary = rec["summary"]
        if rec["kind"] == "run" and shared and summary:
            first, *rest = summary.split()
            summary = " ".join([first, *(w for w in rest if w not in shared)])
        rows.append([_cell(rec["ref"], 22), rec["kind"], _cell(rec["env"], 20),
                     _cell(rec["task"], 20), _cell(summary, 60), _cell(created, 16),
                     _size(rec["size"])])
    return rows, _shared_settings(records)


def _print_table(headers: list[str], rows: list[list[str]], right: set[int]) -> None:
    widths = [max([len(h)] + [len(r[i]) for r in rows]) for i, h in enumerate(headers)]

    def line(cells: list[str]) -> str:
        return "  ".join(c.rjust(w) if i in right else c.ljust(w)
                         for i, (c, w) in enumerate(zip(cells, widths, strict=True))).rstrip()

    click.echo(line(headers))
    for row in rows:
        click.echo(line(row))


#: how many records `kb ls` prints unless --limit or --all says otherwise
LS_PAGE = 50


@kb.command("ls")
@click.argument("kind_arg", metavar="[KIND]", required=False, default=None)
@click.option("--kind", "kind_opt", metavar="KIND",
              help="Only records of this kind (run, policy, partition, ...; also the argument)")
@click.option("--env", "env", metavar="NAME|ID", help="Only records of this environment")
@click.option("--task", "task", metavar="NAME|ID", help="Only records of this task")
@click.option("--learner", metavar="NAME", help="Only runs and policies of this learner")
@click.option("--where", "where", metavar="KEY=VALUE", multiple=True,
              help="Only records whose parameter KEY equals VALUE (repeatable; e.g. alpha=0.5, "
                   "episodes=300)")
@click.option("--limit", type=click.IntRange(min=1), default=None,
              help=f"At most this many records (the table: {LS_PAGE} unless --all; --json: all "
                   "unless --limit)")
@click.option("--all", "show_all", is_flag=True, help="Print every matching record")
@click.option("--json", "as_json", is_flag=True,
              help="Print the records as a JSON list of objects (the columns of records_table)")
@kb_option(read_only=True)
@_guard
def ls(kb_location: KBLocation, kind_arg: str | None, kind_opt: str | None, env: str | None,
       task: str | None, learner: str | None, where: tuple[str, ...], limit: int | None,
       show_all: bool, as_json: bool) -> None:
    """List records as a table (every kind but artifacts when no KIND is given).

    The table shows the first 50 matching records and a line saying how many more there are
    (--limit N for another page size, --all for every one). A run's SUMMARY shows its learner and
    the settings that differ between the listed runs; those they all share are on one line
    below the table (--json has every record's whole summary).

    \b
    Examples:
      adpart kb ls run --env two-rooms --where alpha=0.5
      adpart kb ls --kind partition --limit 5
      adpart kb ls run --learner hierarchical --all
      adpart kb ls run --json > runs.json
    """
    if kind_arg and kind_opt and _kind(kind_arg) != _kind(kind_opt):
        raise KBError(f"KIND {kind_arg!r} and --kind {kind_opt!r} disagree; give one of them")
    if show_all and limit is not None:
        raise KBError("--all and --limit disagree; give one of them")
    name = kind_opt or kind_arg
    damaged: list[str] = []
    page = None if show_all or (as_json and limit is None) else (limit or LS_PAGE)
    with _open(kb_location, read_only=True) as base:
        try:
            filters = {"env": env, "task": task, "learner": learner,
                       "where": _where_items(where)}
            kind = _kind(name) if name else None
            if page is None:
                table = base.records_table(kind, damaged=damaged, **filters)
                total = table.num_rows
            else:
                table, total = base.records_page(kind, limit=page, damaged=damaged, **filters)
        except AdpartError as exc:
            hint = ""
            if where and "parameter" in str(exc):
                hint = " (check --where)"
            raise KBError(f"{exc}{hint}") from exc
    if as_json:
        click.echo(strict_json(json_rows(table)))
    elif table.num_rows == 0:
        click.echo("no records match" if (env or task or learner or where) else "no records")
    else:
        rows, shared = _ls_rows(table)
        _print_table([h for h, _, _ in _LS_COLUMNS], rows, right={6})
        if shared:
            click.echo(f"every run above also has: {' '.join(shared)}")
        if total > table.num_rows:
            click.echo(f"... {total - table.num_rows} more of {total} records (--limit N or "
                       "--all to see them, filters to narrow them)")
    _report_damage(damaged)


#: the columns of `kb runs`: (header, runs_table column)
_RUNS_COLUMNS = (("RUN", "run"), ("#", "replicate"), ("ENV", "env"), ("TASK", "task"),
                 ("LEARNER", "learner"), ("EPISODES", "episodes"),
                 ("TO BOUND", "episodes_to_bound"), ("STEPS", "steps_to_bound"),
                 ("BOUND", "bound"), ("FINAL GAP", "final_gap"))


def _runs_rows(table: pa.Table) -> list[list[str]]:
    rows = []
    for rec in table.to_pylist():
        if rec["replicate"] is None:
            to_bound, steps = "not stored", "-"
        elif rec["censored"]:  # never within the bound: where it was last seen outside
            to_bound, steps = f">{rec['episodes_to_bound']}", f">{rec['steps_to_bound']}"
        else:
            to_bound, steps = str(rec["episodes_to_bound"]), str(rec["steps_to_bound"])
        bound, gap = rec["bound"], rec["final_gap"]
        rows.append([rec["run"], _cell(rec["replicate"], 4), _cell(rec["env"], 20),
                     _cell(rec["task"], 20), _cell(rec["learner"], 20),
                     _cell(rec["episodes"], 9), to_bound, steps,
                     "-" if bound is None else f"{bound:.4g}",
                     "-" if gap is None else f"{gap:.3g}"])
    return rows


@kb.command("runs")
@click.option("--env", "env", metavar="NAME|ID", help="Only runs of this environment")
@click.option("--task", "task", metavar="NAME|ID", help="Only runs of this task")
@click.option("--learner", metavar="NAME", help="Only runs of this learner")
@click.option("--where", "where", metavar="KEY=VALUE", multiple=True,
              help="Only run records whose parameter KEY equals VALUE (repeatable)")
@click.option("--limit", type=click.IntRange(min=1), default=None,
              help=f"At most this many rows (the table: {LS_PAGE} unless --all; --json: all "
                   "unless --limit)")
@click.option("--all", "show_all", is_flag=True, help="Print every matching run")
@click.option("--json", "as_json", is_flag=True,
              help="Print the rows as a JSON list of objects (the columns of runs_table)")
@kb_option(read_only=True)
@_guard
def runs(kb_location: KBLocation, env: str | None, task: str | None, learner: str | None,
         where: tuple[str, ...], limit: int | None, show_all: bool, as_json: bool) -> None:
    """Each learning run's episodes and steps to the success bound, one line per run.

    A run record of K runs prints K lines (# is the run's index). TO BOUND is the first
    evaluated episode from which the run's value gap stays within BOUND (5 % of |V*| at the
    start); >N: the run never stayed within it up to its last evaluation, N (censored).

    \b
    Examples:
      adpart kb runs --env three-floor
      adpart kb runs --task reach-top-west --learner hierarchical --json
    """
    if show_all and limit is not None:
        raise KBError("--all and --limit disagree; give one of them")
    damaged: list[str] = []
    page = None if show_all or (as_json and limit is None) else (limit or LS_PAGE)
    with _open(kb_location, read_only=True) as base:
        try:
            table = base.runs_table(env=env, task=task, learner=learner,
                                    where=_where_items(where), damaged=damaged)
        except AdpartError as exc:
            raise KBError(str(exc)) from exc
    total = table.num_rows
    if page is not None:
        table = table.slice(0, page)
    if as_json:
        click.echo(strict_json(json_rows(table)))
    elif table.num_rows == 0:
        click.echo("no runs match" if (env or task or learner or where) else "no runs")
    else:
        _print_table([h for h, _ in _RUNS_COLUMNS], _runs_rows(table),
                     right={1, 5, 6, 7, 8, 9})
        if total > table.num_rows:
            click.echo(f"... {total - table.num_rows} more of {total} runs (--limit N or --all "
                       "to see them, filters to narrow them)")
    _report_damage(damaged)


def _report_damage(damaged: list[str]) -> None:
    """Name each damaged record left out of a listing on stderr; exit 1 if there was any."""
    for line in damaged:
        click.echo(f"DAMAGED (left out): {line}", err=True)
    if damaged:
        raise SystemExit(1)


def _short(value: Any) -> str:
    if isinstance(value, list | tuple):
        items = [_short(v) for v in value[:20]]
        more = f", ... ({len(value)} in all)" if len(value) > 20 else ""
        return "[" + ", ".join(items) + more + "]"
    if value is None or value == "":
        return "-"
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def _nested(data: dict[str, Any], indent: int) -> list[str]:
    """A mapping as indented ``key: value`` lines, nested mappings one level deeper."""
    if not data:
        return [" " * indent + "(none)"]
    width = max(len(str(k)) for k in data) + 1
    lines = []
    for key, value in data.items():
        if isinstance(value, dict) and value:
            lines.append(" " * indent + f"{key}:")
            lines.extend(_nested(value, indent + 2))
        else:
            lines.append(" " * indent + f"{str(key) + ':':<{width}} {_short(value)}")
    return lines


def _run_layers(base: KnowledgeBase, run: Any) -> dict[str, str]:
    """A layer learner's run: the stored layer it started on and those its runs ended on, each
    with its block count (``partition:19 (48 blocks)``)."""
    out: dict[str, str] = {}

    def named(pid: int) -> str:
        return f"partition:{pid} ({base.get('partition', pid).n_blocks} blocks)"

    if run.partition_id is not None:
        out["partition_id"] = named(run.partition_id)
    final = run.metrics.get("final_partitions") or []
    if final:
        distinct = list(dict.fromkeys(final))
        out["final_layers"] = (", ".join(named(p) for p in distinct[:3])
                               + (f", ... ({len(distinct)} distinct over {len(final)} runs)"
                                  if len(distinct) > 3 else ""))
    knowledge = run.metrics.get("knowledge")
    if knowledge:
        from adpart.learning.knowledge import Knowledge

        out["knowledge"] = Knowledge.from_dict(knowledge).label
    return out


def _show_lines(base: KnowledgeBase, record: Any) -> list[str]:
    """``kb show``: the record's fields, its nested specs/metrics, artifacts and provenance."""
    data = _plain(record)
    data.pop("ref", None)
    prov = data.pop("provenance", None)
    artifact_fields = list(getattr(type(record), "ARTIFACTS", {}))
    fields = {k: v for k, v in data.items()
              if k not in artifact_fields and not isinstance(v, dict)}
    owner: dict[str, Any] = {}
    task_id = getattr(record, "task_id", None)
    env_id = getattr(record, "environment_id", None)
    if task_id is not None:
        task = base.get("task", task_id)
        owner["task"] = f"{task.name} (task:{task.id})"
        env_id = task.environment_id
    if env_id is not None:
        owner = {"environment": f"{base.get('environment', env_id).name} "
                                f"(environment:{env_id})", **owner}
    shown = {k: v for k, v in fields.items()
             if k != "id" and not (owner and k in ("environment_id", "task_id"))}
    if record.KIND == "run":
        shown.update(_run_layers(base, record))
    lines = [f"{record.ref}", *_nested({**owner, **shown}, 2)]
    for key, value in data.items():
        if isinstance(value, dict) and key not in artifact_fields:
            lines += ["", f"{key}:", *_nested(value, 2)]
    if artifact_fields:
        arts: dict[str, Any] = {}
        for name in artifact_fields:
            sha = getattr(record, name)
            if sha is None:
                arts[name] = None
                continue
            art = base.artifact(sha)
            shape = "x".join(map(str, art.shape)) if art.shape is not None else ""
            arts[name] = " ".join(p for p in (f"artifact:{sha[:16]}", art.format,
                                              art.dtype or "", shape, _size(art.bytes)) if p)
        lines += ["", "artifacts:", *_nested(arts, 2)]
    if record.KIND == "artifact":
        referrers = base.referrers().get(record.sha256, [])
        lines += ["", "referenced by:", *([f"  {r}" for r in referrers] or ["  (nothing)"])]
    if prov:
        params = prov.pop("parameters", {})
        lines += ["", "provenance:", *_nested(prov, 2), "", "parameters:", *_nested(params, 2)]
    return lines


@kb.command("show")
@click.argument("ref")
@click.option("--json", "as_json", is_flag=True, help="Print JSON")
@kb_option(read_only=True)
@_guard
def show(kb_location: KBLocation, ref: str, as_json: bool) -> None:
    """Show one record (KIND:N or artifact:HEX) with its artifacts and provenance."""
    with _open(kb_location, read_only=True) as base:
        record = _resolve(base, ref)
        if as_json:
            data = _plain(record)
            if record.KIND == "artifact":
                data["referenced_by"] = base.referrers().get(record.sha256, [])
            click.echo(strict_json(data))
            return
        lines = _show_lines(base, record)
    click.echo("\n".join(lines))


def _as_table(value: Any) -> pa.Table:
    import numpy as np
    import pyarrow as pa

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
    import numpy as np
    import pyarrow as pa
    import pyarrow.csv as pacsv
    import pyarrow.parquet as pq

    suffix = out.suffix.lower()
    if suffix not in (".parquet", ".csv", ".json"):
        raise click.BadParameter("the file must end in .parquet, .csv or .json", param_hint="--out")
    if out.is_symlink():  # an export replaces its file; it never writes through a link
        raise KBError(f"--out {out} is a symbolic link (to {out.readlink()}); an export does not "
                      "write through it: give the path of a regular file, or remove the link")
    with _open(kb_location, read_only=True) as base:
        record = _resolve(base, ref)
        if record.KIND == "artifact":
            value = base.read_artifact(record)
        else:
            fields = list(type(record).ARTIFACTS)
            present = [f for f in fields if getattr(record, f) is not None]
            if field_name is None and len(present) == 1:  # the record's only artifact
                field_name = present[0]
            elif field_name is None and record.KIND == "run" and "curve" in present:
                field_name = "curve"  # a run's own artifact (its experience: --field)
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
                payload: Any = strict(table.to_pydict())  # NaN and infinities as null
            else:
                array = np.asarray(value)
                payload = {
                    "dtype": array.dtype.str,
                    "shape": list(array.shape),
                    "values": array.tolist(),
                }
            out.write_text(strict_json(payload, indent=None))
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
            strict_json(
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
                }
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
    for line in report.failures:
        click.echo(f"skipped: {line}")
    n = len(report.artifacts) + len(report.files) + (len(report.records) if orphans else 0)
    hint = "" if yes else "; pass --yes to delete"
    skipped = f"; {len(report.failures)} skipped (listed above)" if report.failures else ""
    click.echo(f"{verb} {n} item(s), {report.bytes} bytes{hint}{skipped}")
    if report.failures:
        raise SystemExit(1)


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
        match = _REF.match(ref)
        if _ART.match(ref) or (match and _kind(match.group("kind")) == "artifact"):
            raise KBError("artifacts are removed by `adpart kb gc` once no record refers to "
                          "them; remove the records instead")
        if not match:
            _resolve(base, ref)  # the message for a malformed id
        # by id, without reading the record first: a damaged record can be removed too
        removed = base.remove(_kind(match.group("kind")), int(match.group("id")),
                              dry_run=not yes)
    verb = "removed" if yes else "would remove"
    click.echo(f"{verb} {', '.join(removed)}" + ("" if yes else "; pass --yes to remove"))


@kb.command("upgrade")
@kb_option
@_guard
def upgrade(kb_location: KBLocation) -> None:
    """Migrate the knowledge base to this adpart's schema version."""
    with _open(kb_location, verify=False) as base:
        start, end = base.upgrade()
        damaged = base.upgrade_damaged
    click.echo(
        f"schema version {start} -> {end}"
        if start != end
        else f"schema version {end}: already current"
    )
    if damaged:
        shown = ", ".join(damaged[:5]) + (f", ... ({len(damaged)} in all)"
                                          if len(damaged) > 5 else "")
        click.echo(f"{len(damaged)} row(s) were damaged before the upgrade and stay named as "
                   f"damaged: {shown}; `adpart kb check` lists them")

"""Content hashes of metadata rows: a flipped bit in any row is named by ``adpart kb check``.

Artifacts carry their own hashes; this module gives every metadata row one too. Each table of
the schema has a ``row_sha`` column holding the SHA-256 of a canonical encoding of the row's other
columns *as the database returns them* (floats by ``repr``, datetimes in UTC ISO form, JSON as
sorted-key compact JSON). Hashing the read-back values rather than the Python values handed to
the ORM makes the hash independent of driver conversions: the audit re-reads the row the same way
and must get the same bytes.

The hash is set by an ``after_insert``/``after_update`` mapper event inside the writing
transaction, so no committed row is ever without one. A partition's hash also covers its parent
links (the ``partition_parents`` association, which has no row hash of its own): a changed link
is named as a change of the child partition.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Iterable, Mapping
from datetime import datetime, timezone
from typing import Any

from sqlalchemy import Connection, Table, event, select, update
from sqlalchemy.orm import Mapper

ROW_SHA = "row_sha"


def _plain(value: Any) -> Any:
    if isinstance(value, datetime):
        moment = value if value.tzinfo is not None else value.replace(tzinfo=timezone.utc)
        return {"datetime": moment.astimezone(timezone.utc).isoformat()}
    if isinstance(value, float):
        return {"float": repr(value) if math.isfinite(value) else str(value)}
    if isinstance(value, bool | int | str) or value is None:
        return value
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return {"other": str(value)}


def row_digest(table: Table, row: Mapping[str, Any], parents: Iterable[int] | None = None) -> str:
    """SHA-256 of ``row`` (column name -> value as read back), all columns but ``row_sha``."""
    payload = {"table": table.name,
               "columns": {c.name: _plain(row[c.name]) for c in table.columns
                           if c.name != ROW_SHA}}
    if parents is not None:
        payload["parents"] = sorted(int(p) for p in parents)
    encoded = json.dumps(payload, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(encoded.encode()).hexdigest()


def _key_clause(table: Table, mapper: Mapper, target: Any) -> Any:
    clause = None
    for column, value in zip(mapper.primary_key, mapper.primary_key_from_instance(target),
                             strict=True):
        term = table.c[column.name] == value
        clause = term if clause is None else clause & term
    return clause


def _stamp(mapper: Mapper, connection: Connection, target: Any) -> None:
    table = mapper.local_table
    if ROW_SHA not in table.c:
        return
    where = _key_clause(table, mapper, target)
    row = connection.execute(select(table).where(where)).mappings().one()
    parents = None
    if table.name == "partitions":
        parents = [p.id for p in target.parents]
    digest = row_digest(table, row, parents)
    connection.execute(update(table).where(where).values({ROW_SHA: digest}))
    target.__dict__[ROW_SHA] = digest  # keep the identity map in step without another flush


def install(base: type) -> None:
    """Stamp every row of ``base``'s mapped classes with its hash as it is inserted or updated."""
    event.listen(base, "after_insert", _stamp, propagate=True)
    event.listen(base, "after_update", _stamp, propagate=True)

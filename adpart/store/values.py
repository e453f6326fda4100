"""The checks of the values a put stores: names, whole numbers, discounts, thresholds, JSON.

Every put of :class:`~adpart.store.kb.KnowledgeBase` passes its arguments through these before
anything is written, so an impossible value is refused with :class:`StoreError` naming the field
and its range, and nothing is created.
"""

from __future__ import annotations

import hashlib
import json
import math
from typing import Any

import numpy as np

from adpart.store.errors import StoreError


def canonical_json_hash(value: Any) -> str:
    """SHA-256 of ``value`` as canonical JSON (sorted keys, no spaces): the task spec hash."""
    return hashlib.sha256(json_text(value, "spec").encode()).hexdigest()


_INT64 = (-(2**63), 2**63 - 1)
_MAX_TEXT = 255  # the width of the name columns


def name_text(value: Any, field: str, *, longest: int = _MAX_TEXT, empty: bool = False) -> str:
    """A name as stored: a string of at most ``longest`` characters, without NUL characters."""
    if not isinstance(value, str):
        raise StoreError(f"{field} must be a string, got {type(value).__name__}")
    if not value and not empty:
        raise StoreError(f"{field} must not be empty")
    if len(value) > longest:
        raise StoreError(f"{field} has {len(value)} characters; at most {longest} are stored")
    if "\x00" in value:
        raise StoreError(f"{field} contains a NUL character; names are text without NUL")
    return value


def whole_number(value: Any, field: str, low: int = _INT64[0], high: int = _INT64[1],
           *, optional: bool = False) -> int | None:
    """A count, seed or size as stored: a whole number in ``[low, high]`` (64-bit columns)."""
    if value is None and optional:
        return None
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise StoreError(f"{field} must be a whole number, got {value!r}")
    if not low <= int(value) <= high:
        raise StoreError(f"{field} = {int(value)} is outside [{low}, {high}]")
    return int(value)


def discount(value: Any, field: str, *, optional: bool = False) -> float | None:
    """A discount factor: a finite number in [0, 1]."""
    if value is None and optional:
        return None
    try:
        gamma = float(value)
    except (TypeError, ValueError):
        raise StoreError(f"{field} must be a number in [0, 1], got {value!r}") from None
    if not math.isfinite(gamma) or not 0.0 <= gamma <= 1.0:
        raise StoreError(f"{field} = {value!r} must be a finite number in [0, 1] (a discount "
                         "factor; nan and inf are refused)")
    return gamma


def threshold(value: Any, field: str, high: float) -> float:
    """A partition threshold: a number in [0, ``high``] (``inf`` allowed where ``high`` is)."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise StoreError(f"{field} must be a number in [0, {high}], got {value!r}") from None
    if math.isnan(x) or not 0.0 <= x <= high:
        raise StoreError(f"{field} = {value!r} must be a number in [0, {high}] (nan is refused)")
    return x


def json_text(value: Any, what: str) -> str:
    try:
        return json.dumps(value, sort_keys=True, separators=(",", ":"), allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise StoreError(f"the {what} must be JSON-serialisable (numbers, strings, lists, dicts; "
                         f"no NaN): {exc}") from exc

"""What every report file shares: strict JSON and folder names that any file system accepts.

Strict JSON (RFC 8259) has no ``NaN`` or ``Infinity``: a value that is not finite (an episode
count that was never reached, a mean of no runs) is written as ``null``, so ``summary.json``
files load in any strict parser (``jq``, JavaScript, ``json.loads(..., parse_constant=...)``).
numpy scalars and arrays become numbers and lists, paths strings.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["folder_name", "strict_json"]


def _plain(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Path):
        return str(value)
    return value


def strict_json(data: Any, *, indent: int | None = 2) -> str:
    """``data`` as strict JSON: non-finite floats as null, numpy values as plain numbers."""
    return json.dumps(_plain(data), indent=indent, allow_nan=False)


def folder_name(*parts: str) -> str:
    """``parts`` joined by ``_``, each run of characters other than letters, digits and ``._+-``
    replaced by ``-`` (``goal:x=9,y=5`` -> ``goal-x-9-y-5``): safe on every file system and in
    shells without quoting."""
    return "_".join(re.sub(r"[^A-Za-z0-9._+-]+", "-", p).strip("-") or "-" for p in parts)

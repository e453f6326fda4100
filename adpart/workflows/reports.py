"""What every report file shares: strict JSON and folder names that any file system accepts.

Strict JSON (RFC 8259) has no ``NaN`` or ``Infinity``: a value that is not finite (an episode
count that was never reached, a mean of no runs) is written as ``null``, so ``summary.json``
files load in any strict parser (``jq``, JavaScript, ``json.loads(..., parse_constant=...)``).
The conversion is the knowledge base's own (:func:`adpart.store.tables.strict`), so ``kb``
output and report files agree.
"""

from __future__ import annotations

import re

from adpart.store.tables import strict_json

__all__ = ["folder_name", "strict_json"]


def folder_name(*parts: str) -> str:
    """``parts`` joined by ``_``, each run of characters other than letters, digits and ``._+-``
    replaced by ``-`` (``goal:x=9,y=5`` -> ``goal-x-9-y-5``): safe on every file system and in
    shells without quoting."""
    return "_".join(re.sub(r"[^A-Za-z0-9._+-]+", "-", p).strip("-") or "-" for p in parts)

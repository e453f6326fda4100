"""The knowledge base's error: every store failure a user can meet is a :class:`StoreError`."""

from __future__ import annotations

from adpart.errors import AdpartError


class StoreError(AdpartError):
    """The knowledge base cannot do what was asked: damaged artifact, wrong schema, unwritable path.

    The message names the record or artifact concerned and the fix (``adpart kb check``,
    ``adpart kb upgrade``, another ``--kb`` location, ...). Database-driver errors are chained
    as ``__cause__`` so a bug report still carries them.
    """

"""Progress inside a long stage: the bar a command installs, and the stages that report to it.

A workflow that runs long (learning a task, learning options, a sweep's cells) reports
``update(done, total)`` through :func:`stage_progress`; what it draws is the command line's
business: ``adpart pipeline``, ``sweep`` and ``experiment`` install a bar factory with
:func:`progress_bars` (:func:`adpart.cli.common.progress_callback`, a bar with ETA on a
terminal, nothing when stderr is piped or ``--quiet``), and without one every stage is silent.
The factory lives in a context variable, so the stages find it without every function between
the command and the learner passing it on.
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Callable, Iterator

#: ``(total, label) -> (update(done, total), close())``: one bar per stage.
BarFactory = Callable[[int, str], tuple[Callable[[int, int], None], Callable[[], None]]]

_BARS: contextvars.ContextVar[BarFactory | None] = contextvars.ContextVar(
    "adpart_progress_bars", default=None)


@contextlib.contextmanager
def progress_bars(factory: BarFactory | None) -> Iterator[None]:
    """Within the block, every :func:`stage_progress` draws with ``factory`` (None: silent)."""
    token = _BARS.set(factory)
    try:
        yield
    finally:
        _BARS.reset(token)


@contextlib.contextmanager
def stage_progress(total: int, label: str) -> Iterator[Callable[[int, int], None] | None]:
    """The ``update(done, total)`` of one stage's bar, closed on leaving the block; None when no
    command installed bars (callers then pass no progress callback at all)."""
    factory = _BARS.get()
    if factory is None or total <= 0:
        yield None
        return
    update, close = factory(total, label)
    try:
        yield update
    finally:
        close()

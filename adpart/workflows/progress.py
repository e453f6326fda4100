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
import dataclasses
from collections.abc import Callable, Iterator
from typing import Any

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


@contextlib.contextmanager
def learning_progress(run: Any, label: str) -> Iterator[Any]:
    """``run`` (an :class:`adpart.learning.settings.Run`) whose ``progress`` hook draws a bar
    of its episodes for one learner call of a stage (an experiment that calls the learning
    cores itself, not through :mod:`adpart.workflows.learning`); ``run`` unchanged where it has
    a hook already or no command installed bars."""
    if run.progress is not None:
        yield run
        return
    with stage_progress(run.episodes, label) as bar:
        yield run if bar is None else dataclasses.replace(run, progress=bar)

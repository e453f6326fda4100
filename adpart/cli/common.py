"""Helpers shared by the CLI modules: error mapping, plugin loading with visible warnings, JSON."""

from __future__ import annotations

import json
import sys
import warnings
from collections.abc import Callable
from typing import Any

import click
import numpy as np

from adpart.errors import AdpartError
from adpart.plugins import PluginWarning, Registry, get_registry


class CLIError(click.ClickException):
    """One line on stderr (``Error: ...``) and exit status 2: bad input the user can fix."""

    exit_code = 2


class AdpartGroup(click.Group):
    """A click group that reports every :class:`AdpartError` as one line and exit status 2."""

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except AdpartError as exc:
            raise CLIError(str(exc)) from exc


def registry() -> Registry:
    """The plugin registry; loading problems are shown as ``Warning:`` lines on stderr."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", PluginWarning)
        reg = get_registry()
    for w in caught:
        if issubclass(w.category, PluginWarning):
            click.echo(f"Warning: {w.message}", err=True)
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return reg


def _default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def dumps(data: Any) -> str:
    return json.dumps(data, indent=2, default=_default)


def echo_json(data: Any) -> None:
    click.echo(dumps(data))


def progress_callback(
    enabled: bool, total: int, label: str
) -> tuple[Callable[[int, int], None], Callable[[], None]]:
    """A ``progress(done, total)`` callable drawing a bar on stderr, and a function to close it."""
    if not enabled or not sys.stderr.isatty():
        return (lambda done, total: None), (lambda: None)
    bar = click.progressbar(length=total, label=label, file=sys.stderr)
    bar.__enter__()
    state = {"done": 0}

    def update(done: int, _total: int) -> None:
        bar.update(done - state["done"])
        state["done"] = done

    return update, lambda: bar.__exit__(None, None, None)

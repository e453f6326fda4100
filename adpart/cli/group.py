"""The main command group: sub-commands imported on first use, errors as one line.

``adpart --help`` and ``adpart --version`` import only click and this module: each sub-command's
module (and with it numpy, the store, the plugins) is imported when that command runs or shows
its own help. The listing's one-line helps are kept here, next to the import paths, and a test
checks that they match the commands' own.
"""

from __future__ import annotations

import importlib
import traceback
from typing import Any

import click

from adpart.errors import AdpartError


class CLIError(click.ClickException):
    """One line on stderr (``Error: ...``) and exit status 2: bad input the user can fix."""

    exit_code = 2


#: ``ctx.meta`` key of the main group's ``--debug`` flag (tracebacks of one-line errors).
DEBUG = "adpart.debug"

#: Exit status after Ctrl-C: 128 + SIGINT, as shells report an interrupted command.
INTERRUPTED = 130


class LazyGroup(click.Group):
    """A group whose sub-commands are ``name -> (module:attribute, short help)``, loaded lazily.

    Every :class:`AdpartError` a command raises is reported as one line with exit status 2
    (after its traceback, chained causes included, when the group's ``--debug`` is on: a
    third-party plugin's :class:`~adpart.errors.PluginFailure` carries the plugin's own), and
    Ctrl-C ends the command with status 130 (not click's 1).
    """

    def __init__(self, *args: Any, lazy: dict[str, tuple[str, str]] | None = None,
                 **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.lazy = dict(lazy or {})

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted({*super().list_commands(ctx), *self.lazy})

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        if name in self.commands or name not in self.lazy:
            return super().get_command(ctx, name)
        module, _, attribute = self.lazy[name][0].partition(":")
        command = getattr(importlib.import_module(module), attribute)
        self.add_command(command, name)
        return command

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        limit = formatter.width - 6 - max(map(len, self.list_commands(ctx)), default=0)
        rows = [(name, click.Command(name, help=self.lazy[name][1]).get_short_help_str(limit)
                 if name in self.lazy and name not in self.commands
                 else self.commands[name].get_short_help_str(limit=limit))
                for name in self.list_commands(ctx)]
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except AdpartError as exc:
            if ctx.meta.get(DEBUG):
                click.echo("".join(traceback.format_exception(exc)).rstrip(), err=True)
            raise CLIError(str(exc)) from exc
        except KeyboardInterrupt:
            click.echo("Interrupted.", err=True)
            raise click.exceptions.Exit(INTERRUPTED) from None


def command_paths(group: click.Group) -> list[tuple[str, ...]]:
    """Every command and sub-command under ``group``, e.g. ``("kb", "ls")`` (each is imported:
    the help-import test and the start-up benchmark walk them)."""
    ctx = click.Context(group)
    found: list[tuple[str, ...]] = []

    def walk(sub: click.Group, path: tuple[str, ...]) -> None:
        for name in sub.list_commands(ctx):
            command = sub.get_command(ctx, name)
            found.append((*path, name))
            if isinstance(command, click.Group):
                walk(command, (*path, name))

    walk(group, ())
    return found

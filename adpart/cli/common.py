"""Helpers shared by the CLI modules: error mapping, plugin loading with visible warnings, JSON."""

from __future__ import annotations

import functools
import math
import sys
import warnings
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import click

from adpart.cli.group import CLIError
from adpart.errors import AdpartError
from adpart.params import Param, build_settings, settings_params
from adpart.plugins import PluginSpec, PluginWarning, Registry, get_registry
from adpart.plugins.manager import builtin_registry

if TYPE_CHECKING:
    from adpart.execution import Executor
    from adpart.workflows.progress import BarFactory


class FiniteFloat(click.ParamType):
    """A float option that must be finite (no ``nan``, ``inf``) and within ``[min, max]``.

    ``click.FloatRange`` lets ``nan`` through (every comparison with NaN is false); this type
    checks ``math.isfinite`` first, so ``--delta nan`` fails at parse time, before anything is
    computed or stored, with one line naming the option (``Error: --delta = nan ...``, exit 2).
    """

    name = "float"

    def __init__(self, min: float | None = None, max: float | None = None,
                 what: str = "") -> None:
        self.min, self.max, self.what = min, max, what

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> float:
        option = (param.opts[0] if param is not None and param.opts else "the value")
        what = f" ({self.what})" if self.what else ""
        try:
            out = float(value)
        except (TypeError, ValueError):
            raise CLIError(f"{option} = {value!r} is not a number{what}") from None
        if not math.isfinite(out):
            raise CLIError(f"{option} = {value} must be a finite number (nan and inf are "
                           f"refused){what}")
        if self.min is not None and self.max is not None:
            if not self.min <= out <= self.max:
                raise CLIError(f"{option} = {value} is outside [{self.min:g}, {self.max:g}]{what}")
        elif self.min is not None and out < self.min:
            raise CLIError(f"{option} = {value} must be >= {self.min:g}{what}")
        elif self.max is not None and out > self.max:
            raise CLIError(f"{option} = {value} must be <= {self.max:g}{what}")
        return out


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


def dumps(data: Any) -> str:
    """Strict JSON (non-finite numbers as null), as every ``--json`` and summary.json writes."""
    from adpart.workflows.reports import strict_json

    return strict_json(data)


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


def stage_bars(enabled: bool) -> BarFactory | None:
    """:func:`progress_callback` as the bar factory of the workflows' long stages
    (:func:`adpart.workflows.progress.progress_bars`): a bar with ETA per stage on a terminal;
    None (silent) when not ``enabled`` or when stderr is piped."""
    if not enabled or not sys.stderr.isatty():
        return None
    return lambda total, label: progress_callback(True, total, label)


def plugin_options_command(kind: str, chooser: str) -> type[click.Command]:
    """A click Command class whose options include every ``kind`` plugin's declared parameters.

    ``chooser`` is the command's option that names the plugin (``learner`` for ``--learner``).
    Every plugin's parameters are accepted, so a parameter of another plugin is refused naming
    the plugin chosen (:func:`split_plugin_options`); ``--help`` shows the chosen plugin's
    (``--learner NAME --help``; the option's default without it) with that plugin's defaults,
    and says how to see the others'. Values arrive in the callback as ``plugin_<name>`` keywords
    (None when not given).
    """

    class PluginOptionsCommand(click.Command):
        def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
            self._raw_args = list(args)  # read by get_params when --help is formatted
            return super().parse_args(ctx, args)

        def _chosen(self, params: list[click.Parameter]) -> str:
            option = next(p for p in params if p.name == chooser)
            raw = getattr(self, "_raw_args", [])
            for i, word in enumerate(raw):
                for flag in option.opts:
                    if word == flag and i + 1 < len(raw):
                        return raw[i + 1]
                    if word.startswith(flag + "="):
                        return word[len(flag) + 1:]
            return str(option.default)

        def _registry(self, ctx: click.Context, chosen: str) -> Registry:
            """The registry to read: for ``--help`` of a built-in plugin adpart's own plugins
            of ``kind`` (no third-party package imported), else every installed plugin."""
            raw = getattr(self, "_raw_args", [])
            words = raw[:raw.index("--")] if "--" in raw else raw
            if set(words) & set(self.get_help_option_names(ctx)):
                own = builtin_registry(kind)
                if chosen in own.names(kind):
                    return own
            return registry()

        def get_params(self, ctx: click.Context) -> list[click.Parameter]:
            params = super().get_params(ctx)
            chosen = self._chosen(params)
            return (params[:-1] + _plugin_options(self._registry(ctx, chosen), kind, chosen)
                    + params[-1:])  # keep --help last

        def format_epilog(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
            chosen = self._chosen(super().get_params(ctx))
            reg = self._registry(ctx, chosen)
            own = [f"--{p.name}" for p in reg.get(kind, chosen).params] if chosen in (
                reg.names(kind)) else []
            super().format_epilog(ctx, formatter)
            formatter.write_paragraph()
            formatter.write_text(
                f"{kind} {chosen!r} takes {', '.join(own) or 'no parameters'}. Another "
                f"{kind}'s parameters: --{chooser.replace('_', '-')} NAME --help (the installed "
                f"ones: adpart plugins --kind {kind}).")

    return PluginOptionsCommand


_METAVARS = {"int": "INTEGER", "float": "FLOAT", "bool": "BOOLEAN", "str": "TEXT"}


def _plugin_options(reg: Registry, kind: str, chosen: str) -> list[click.Option]:
    """One ``--<name>`` per parameter name declared by some ``kind`` plugin.

    The options of the ``chosen`` plugin are shown with its help, type and default; the others'
    are hidden but accepted, so that giving one is refused naming the plugin and the option.
    """
    declared: dict[str, list[tuple[str, Any]]] = {}
    for spec in reg.all(kind):
        for p in spec.params:
            declared.setdefault(p.name, []).append((spec.name, p))
    options = []
    for name, owners in declared.items():
        own = [p for plugin, p in owners if plugin == chosen]
        p = own[0] if own else owners[0][1]
        shown = p.none if p.default is None and p.none is not None else p.default
        options.append(click.Option(
            [f"--{name}", f"plugin_{name.replace('-', '_')}"], metavar=_setting_metavar(p),
            default=None, hidden=not own, help=f"{p.help} [default: {shown}]"))
    return options


def split_plugin_options(spec: PluginSpec, plugin_options: dict[str, Any]) -> dict[str, Any]:
    """The ``plugin_*`` values given on the command line, checked against ``spec``'s parameters."""
    given = {k.removeprefix("plugin_"): v for k, v in plugin_options.items() if v is not None}
    foreign = sorted(set(given) - {p.keyword for p in spec.params})
    if foreign:
        raise CLIError(
            f"--{foreign[0].replace('_', '-')} is not a parameter of {spec.kind} {spec.name!r}; "
            f"its parameters: {', '.join('--' + p.name for p in spec.params) or 'none'}"
        )
    return given


def kb_location_options(func):  # type: ignore[no-untyped-def]
    """``--kb`` and ``--kb-artifacts``, resolved lazily by the command (nothing created early)."""
    func = click.option(
        "--kb-artifacts",
        metavar="URI",
        help="Artifact root for a database URL (any pyarrow filesystem URI) [env "
        "ADPART_KB_ARTIFACTS, which a --kb directory ignores: it keeps its own artifacts/]",
    )(func)
    return click.option(
        "--kb",
        "kb_path",
        envvar="ADPART_KB",
        metavar="PATH|URL",
        help="Knowledge base directory or database URL [env ADPART_KB; default "
        "$ADPART_HOME/kb or ~/.local/share/adpart/kb]",
    )(func)


def executor_options(default: str = "local"):  # type: ignore[no-untyped-def]
    """Decorator adding ``--executor``, ``--executor-opt`` and ``--ray-address`` to a command."""

    def decorate(func):  # type: ignore[no-untyped-def]
        func = click.option(
            "--ray-address",
            envvar="RAY_ADDRESS",
            metavar="ADDRESS",
            help="Ray cluster to use with --executor ray: host:port or ray://host:port "
            "[env RAY_ADDRESS; default: start a local Ray].",
        )(func)
        func = click.option(
            "--executor-opt",
            "executor_opts",
            multiple=True,
            metavar="KEY=VALUE",
            help="A parameter of the executor plugin, e.g. workers=2 or max-retries=5 "
            "(repeatable; see `adpart plugins --kind executor`).",
        )(func)
        return click.option(
            "--executor",
            default=default,
            show_default=True,
            help="Executor plugin: local (process pool), ray (Ray cluster) or serial.",
        )(func)

    return decorate


def run_options():  # type: ignore[no-untyped-def]
    """Decorator adding ``--episodes``, ``--runs``, ``--seed`` and ``--eval-every``: the
    experiment's fields of :class:`adpart.learning.settings.Run` (their defaults, ranges and
    help declared there), each handed to the command as its own keyword."""
    from adpart.learning.settings import EXPERIMENT_FIELDS, Run, fresh_seed

    options = field_options(Run, EXPERIMENT_FIELDS)

    def decorate(func):  # type: ignore[no-untyped-def]
        @functools.wraps(func)
        def command(*args: Any, **kwargs: Any) -> Any:
            kwargs["seed"] = fresh_seed(kwargs["seed"])  # --seed fresh: drawn once, here
            return func(*args, **kwargs)

        return options(command)

    return decorate


def field_options(cls: type, names: tuple[str, ...]):  # type: ignore[no-untyped-def]
    """Decorator: an option per named field of the settings class ``cls`` (default, range,
    help from its declaration), each converted and checked and passed as the field's keyword."""
    params = settings_params(cls, only=names)

    def decorate(func):  # type: ignore[no-untyped-def]
        for p in reversed(params):
            func = _setting_option(p, p.keyword)(func)
        return func

    return decorate


def _setting_option(p: Param, dest: str):  # type: ignore[no-untyped-def]
    """The click option of one settings field's parameter, stored under ``dest``."""
    name = f"--{p.name}"
    if p.type == "bool":
        return click.option(f"{name}/--no-{p.name}", dest, default=p.default,
                            show_default=True, help=p.help)
    return click.option(name, dest, type=_SettingType(p, _setting_metavar(p)),
                        default=p.default,
                        show_default=True if p.default is not None else p.none, help=p.help)


def make_executor(
    name: str, opts: tuple[str, ...] = (), ray_address: str | None = None
) -> Executor:
    """The executor plugin ``name`` built from ``KEY=VALUE`` options and the Ray address."""
    spec = registry().get("executor", name)
    given: dict[str, Any] = {}
    for opt in opts:
        key, sep, value = opt.partition("=")
        if not sep or not key.strip():
            raise CLIError(f"--executor-opt expects KEY=VALUE, got {opt!r}")
        given[key.strip()] = value.strip()
    if ray_address:
        if "address" not in {p.name for p in spec.params}:
            raise CLIError(
                f"--ray-address applies to executors with an address (--executor ray); "
                f"executor {name!r} has none"
            )
        given["address"] = ray_address
    return spec.create(given)


class _SettingType(click.ParamType):
    """A settings field's value on the command line: converted and checked by its declaration
    (:meth:`adpart.params.Param.convert`), so the range and choices live in one place."""

    def __init__(self, param: Param, metavar: str) -> None:
        self.param, self.name = param, metavar

    def get_metavar(self, param: click.Parameter, ctx: click.Context | None = None) -> str:
        return self.name

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> Any:
        if not isinstance(value, str):
            return value
        if self.param.type == "float" and value != self.param.none:  # FiniteFloat's messages
            value = FiniteFloat(self.param.min, self.param.max).convert(value, param, ctx)
        try:
            return self.param.convert(value, "")
        except AdpartError as exc:
            raise CLIError(str(exc).removeprefix(": ")) from None


def _setting_metavar(p: Param) -> str:
    """``[a|b|auto]`` for choices, ``FLOAT|auto`` for a number that may be left to a rule."""
    if p.choices is not None:
        return "[" + "|".join((*p.choices, p.none) if p.none else p.choices) + "]"
    base = _METAVARS.get(p.type, "TEXT")
    return f"{base}|{p.none}" if p.none is not None else base


def settings_options(cls: type, keyword: str):  # type: ignore[no-untyped-def]
    """Decorator: one option per field of the settings class ``cls`` (its name, default, range
    and help from the field's declaration and docstring), handed to the command as one checked
    instance ``keyword=cls(...)``; a rule across fields that fails is one line naming them."""
    params = settings_params(cls)

    def decorate(func):  # type: ignore[no-untyped-def]
        @functools.wraps(func)
        def command(*args: Any, **kwargs: Any) -> Any:
            values = {p.keyword: kwargs.pop(f"{keyword}__{p.keyword}") for p in params}
            try:
                kwargs[keyword] = build_settings(cls, values)
            except AdpartError as exc:
                raise CLIError(str(exc)) from None
            return func(*args, **kwargs)

        for p in reversed(params):
            command = _setting_option(p, f"{keyword}__{p.keyword}")(command)
        return command

    return decorate


def key_values(pairs: tuple[str, ...], option: str) -> dict[str, str]:
    """``KEY=VALUE`` pairs of a repeatable option as a dict; a malformed one names ``option``."""
    out: dict[str, str] = {}
    for pair in pairs:
        key, eq, value = pair.partition("=")
        if not eq or not key:
            raise CLIError(f"{option} takes KEY=VALUE (e.g. {option} alpha=1); got {pair!r}")
        out[key.strip()] = value.strip()
    return out


def check_criterion(name: str, params: dict[str, Any], settings: Any) -> None:
    """Build the partition criterion now, so a bad name or value fails before any work."""
    from adpart.workflows.partitioning import build_criterion

    try:
        build_criterion(name, params, settings)
    except AdpartError as exc:
        raise CLIError(f"--criterion {name} / --criterion-opt: {exc}") from None

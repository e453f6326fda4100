"""Declared parameters: the one typed description of a tunable, shared by plugins and executors.

A :class:`Param` names a constructor keyword, its type, default, help line and bounds. The plugin
registry turns declared parameters into CLI options and validates user values with
:meth:`Param.convert`; the module imports nothing else of adpart but its error tree, so any layer
may declare parameters.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, fields
from typing import Any

from adpart.errors import AdpartError, PluginError

__all__ = ["PARAM_TYPES", "Param", "SettingField", "build_settings", "hook", "setting",
           "setting_fields", "settings", "settings_dict", "settings_params"]

#: The spelling of a parameter's type -> the Python type a value is converted to.
PARAM_TYPES: dict[str, type] = {"int": int, "float": float, "str": str, "bool": bool}


@dataclass(frozen=True)
class Param:
    """A declared plugin parameter, turned into a CLI option ``--<name>``.

    Attributes:
        name: the keyword passed to the implementation's constructor (``-`` in the CLI, ``_`` in
            Python: ``step-size`` is passed as ``step_size``).
        type: ``"int"``, ``"float"``, ``"str"`` or ``"bool"``.
        default: the value used when the option is not given.
        help: one line for ``--help``.
        choices: allowed values (strings), or None.
        min: smallest allowed value for numbers, or None.
        max: largest allowed value for numbers, or None.
        none: the word that means None (``auto``, ``none``), or None when every value is typed.
        check: an optional validator of the converted value (e.g. a schedule's spelling); it
            raises an :class:`AdpartError`, which is reported naming ``--<name>``.

    A float parameter must be finite: ``nan`` and ``inf`` are refused whatever ``min`` says
    (every comparison with NaN is false, so a bound alone lets it through).
    """

    name: str
    type: str
    default: Any
    help: str
    choices: tuple[str, ...] | None = None
    min: float | None = None
    max: float | None = None
    none: str | None = None
    check: Callable[[Any], Any] | None = field(default=None, compare=False, repr=False)

    @property
    def keyword(self) -> str:
        return self.name.replace("-", "_")

    def convert(self, value: Any, owner: str) -> Any:
        """Validate and convert a user value, raising PluginError naming the fix."""
        if self.type not in PARAM_TYPES:
            raise PluginError(f"{owner}: parameter {self.name!r} has unknown type {self.type!r}")
        target = PARAM_TYPES[self.type]
        if value is None or (self.none is not None and value == self.none):
            if self.none is None and self.default is not None:
                raise PluginError(f"{owner}: --{self.name} expects {self.type}, got None")
            return None  # a declared word for None, or a parameter whose default is None
        if self.type == "bool" and isinstance(value, str):
            lowered = value.lower()
            if lowered not in {"true", "false", "1", "0", "yes", "no"}:
                raise PluginError(f"{owner}: --{self.name} expects true or false, got {value!r}")
            value = lowered in {"true", "1", "yes"}
        try:
            out = target(value)
        except (TypeError, ValueError):
            raise PluginError(
                f"{owner}: --{self.name} expects {self.type}, got {value!r}"
            ) from None
        problem = value_problem(out, kind=self.type, low=self.min, high=self.max,
                                choices=self.choices)
        if problem is not None:  # the value as converted, but a non-finite one as given
            got = value if "finite" in problem else out
            raise PluginError(f"{owner}: --{self.name} {problem}; got {got!r}")
        if self.check is not None:
            try:
                self.check(out)
            except AdpartError as exc:
                raise PluginError(f"{owner}: --{self.name} {value!r}: {exc}") from None
        return out


def value_problem(value: Any, *, kind: str, low: float | None = None, high: float | None = None,
                  choices: Sequence[str] | None = None, finite: bool = True) -> str | None:
    """What is wrong with a value already of its ``kind`` (``"must be >= 0"``), or None: the one
    range and choice check of a plugin parameter and of a settings field."""
    if kind in ("int", "float"):
        if math.isnan(value) or (finite and math.isinf(value)):
            return "must be a finite number"
        if low is not None and value < low:
            return f"must be >= {low}"
        if high is not None and value > high:
            return f"must be <= {high}"
    if choices is not None and value not in choices:
        return f"must be one of {', '.join(choices)}"
    return None


# --------------------------------------------------------------------------------------------
# Settings as data: one frozen dataclass per algorithm, the single source of each default and
# check. Plugin parameters, click options and stored provenance are derived from it.
# --------------------------------------------------------------------------------------------

#: Metadata key of a settings field's declaration (see :func:`setting`).
_SETTING = "adpart.setting"


@dataclass(frozen=True)
class _Bounds:
    """How a settings field is checked: its kind, range, choices and the word that means None."""

    kind: str
    min: float | None = None
    max: float | None = None
    choices: tuple[str, ...] | None = None
    none: str | None = None
    check: Callable[[Any], Any] | None = None
    cli: bool = True
    finite: bool = True
    parse: Callable[[Any], Any] | None = None
    option: str | None = None


def setting(default: Any, *, kind: str | None = None, min: float | None = None,
            max: float | None = None, choices: Sequence[str] | None = None,
            none: str | None = None, check: Callable[[Any], Any] | None = None,
            cli: bool = True, finite: bool = True, parse: Callable[[Any], Any] | None = None,
            option: str | None = None) -> Any:
    """A field of a :func:`settings` class: its default and how a value is checked.

    The field's help is the string literal written right below it in the class body (its
    attribute docstring, which the API reference renders too); nothing else restates it.

    Args:
        default: the one default of the setting in the whole package.
        kind: ``"int"``, ``"float"``, ``"str"`` or ``"bool"`` (default: the default's type; give
            it when the default is None).
        min, max: closed bounds for numbers.
        choices: the allowed spellings of a string.
        none: the word that means None on the command line (e.g. ``"auto"``); a setting whose
            default is None needs one.
        check: a validator of the converted value, raising :class:`AdpartError` (e.g. a
            schedule's spelling).
        cli: False keeps the field out of the command line and the plugin parameters (a
            setting only Python callers give, such as an array).
        finite: False lets Python callers give ``inf`` (e.g. a threshold that never fires);
            the command line still takes finite numbers only.
        parse: turns a value into the object the algorithm reads (a schedule's spelling, a
            number or a schedule into a :class:`~adpart.learning.schedules.Schedule`); it
            raises :class:`AdpartError` on a bad value. The default and the command line keep
            the spelling (kind ``"str"``); Python callers may also give the object itself.
        option: the command-line spelling when it is not the field's name (``max-steps`` for
            ``max_steps_per_episode``).
    """
    if kind is None:
        if default is None:
            raise TypeError("a setting whose default is None needs kind=")
        kind = next(k for k, t in PARAM_TYPES.items() if isinstance(default, t)
                    and not (t is int and isinstance(default, bool)))
    if default is None and none is None and cli:
        raise TypeError("a setting whose default is None needs none= (its command-line word)")
    bounds = _Bounds(kind, min, max, tuple(choices) if choices is not None else None, none,
                     check if parse is None else parse, cli, finite, parse, option)
    return field(default=default, metadata={_SETTING: bounds})


#: Metadata key of a hook field (see :func:`hook`).
_HOOK = "adpart.hook"


def hook() -> Any:
    """A field of a :func:`settings` class that is no setting: a callback or an array only Python
    callers pass (a progress callback, reference values). It defaults to None, is not checked,
    not on the command line, not compared and not in the provenance record."""
    return field(default=None, compare=False, repr=False, metadata={_HOOK: True})


@dataclass(frozen=True)
class SettingField:
    """One field of a settings class as the derived interfaces see it."""

    name: str
    default: Any
    help: str
    bounds: _Bounds
    owner: str

    @property
    def option(self) -> str:
        """Its command-line spelling, ``--threshold-scale`` for ``threshold_scale``."""
        return "--" + (self.bounds.option or self.name.replace("_", "-"))

    def param(self) -> Param:
        """The plugin parameter of this field (its CLI option and conversion)."""
        b = self.bounds
        return Param(self.option[2:], b.kind, self.default, self.help,
                     choices=b.choices, min=b.min, max=b.max, none=b.none, check=b.check)

    def validate(self, value: Any) -> Any:
        """``value`` checked against the declaration; raises TaskError naming the field and its
        command-line option."""
        from adpart.errors import TaskError

        b = self.bounds
        given = value

        def fail(problem: str) -> TaskError:
            return TaskError(f"{self.owner}: {self.name} = {given!r}{problem} ({self.option})")

        if value is None:
            if self.default is None or b.none is not None:
                return None
            raise fail(f"; give a {b.kind}")
        if b.parse is not None:  # the spelling or the object itself, into the object
            try:
                return b.parse(value)
            except AdpartError as exc:
                raise fail(f": {exc}") from None
        if b.kind == "bool":
            if not isinstance(value, bool) and not _numpy_scalar(value, 'bool_'):
                raise fail(" must be true or false")
            return bool(value)
        if b.kind in ("int", "float"):
            ok = isinstance(value, (int, float)) and not isinstance(value, bool)
            ok = ok or _numpy_scalar(value, 'integer', 'floating')
            if not ok or (b.kind == "int" and int(value) != value):
                raise fail(f" must be {'an integer' if b.kind == 'int' else 'a number'}")
            value = int(value) if b.kind == "int" else float(value)
        elif not isinstance(value, str):
            raise fail(" must be a string")
        problem = value_problem(value, kind=b.kind, low=b.min, high=b.max, choices=b.choices,
                                finite=b.finite)
        if problem is not None:
            raise fail(f" {problem}")
        if b.check is not None:
            try:
                b.check(value)
            except AdpartError as exc:
                raise fail(f": {exc}") from None
        return value


def _numpy_scalar(value: Any, *kinds: str) -> bool:
    """Whether ``value`` is a numpy scalar of one of ``kinds`` (numpy imported only when asked)."""
    import numpy as np

    return isinstance(value, tuple(getattr(np, k) for k in kinds))


def _attribute_docstrings(cls: type) -> dict[str, str] | None:
    """``{field: the string literal right below it}`` read from ``cls``'s source (None where
    Python kept no source)."""
    import ast
    import inspect
    import textwrap

    try:
        source = textwrap.dedent(inspect.getsource(cls))
    except (OSError, TypeError):  # defined where no source is kept (exec, a bare REPL)
        return None
    body = ast.parse(source).body[0].body  # type: ignore[attr-defined]
    docs: dict[str, str] = {}
    for node, nxt in itertools.pairwise(body):
        if (isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name)
                and isinstance(nxt, ast.Expr) and isinstance(nxt.value, ast.Constant)
                and isinstance(nxt.value.value, str)):
            docs[node.target.id] = " ".join(inspect.cleandoc(nxt.value.value).split())
    return docs


def settings(cls: type) -> type:
    """Make ``cls`` a frozen, keyword-only settings dataclass, checked once when built.

    Every field is declared with :func:`setting` (or is itself a settings class, a group) and
    documented by the string below it. Building an instance converts and checks every field,
    then runs the class's ``check(self)`` for rules across fields; anything wrong raises
    :class:`~adpart.errors.TaskError` naming the field. Code below the boundary trusts it.
    """
    user_check = cls.__dict__.get("check")

    def __post_init__(self: Any) -> None:
        for sf in type(self).__settings_fields__:
            object.__setattr__(self, sf.name, sf.validate(getattr(self, sf.name)))
        if user_check is not None:
            user_check(self)

    cls.__post_init__ = __post_init__  # type: ignore[attr-defined]
    cls = dataclass(frozen=True, kw_only=True)(cls)
    docs = _attribute_docstrings(cls)
    own: list[SettingField] = []
    for f in fields(cls):
        if f.metadata.get(_HOOK):
            continue
        bounds = f.metadata.get(_SETTING)
        if bounds is None:
            if not (isinstance(f.default_factory, type)  # type: ignore[misc]
                    and hasattr(f.default_factory, "__settings_fields__")):
                raise TypeError(f"{cls.__name__}.{f.name}: declare it with setting(...), hook() "
                                "or as a group (field(default_factory=SomeSettings))")
            continue
        if docs is not None and f.name not in docs:
            raise TypeError(f"{cls.__name__}.{f.name} has no docstring (a string literal right "
                            "below the field): it is the option's help")
        help_text = docs[f.name] if docs is not None else f.name.replace("_", " ")
        own.append(SettingField(f.name, f.default, help_text, bounds, cls.__name__))
    cls.__settings_fields__ = tuple(own)  # type: ignore[attr-defined]
    return cls


def setting_fields(cls_or_obj: Any) -> tuple[SettingField, ...]:
    """Every leaf field of a settings class, its groups' fields included, in order."""
    cls = cls_or_obj if isinstance(cls_or_obj, type) else type(cls_or_obj)
    out: list[SettingField] = []
    own = {sf.name: sf for sf in cls.__settings_fields__}
    for f in fields(cls):
        if f.metadata.get(_HOOK):
            continue
        if f.name in own:
            out.append(own[f.name])
        else:
            out.extend(setting_fields(f.default_factory))  # type: ignore[arg-type]
    return tuple(out)


def _groups(cls: type) -> dict[str, type]:
    own = {sf.name for sf in cls.__settings_fields__}  # type: ignore[attr-defined]
    return {f.name: f.default_factory for f in fields(cls)  # type: ignore[misc]
            if f.name not in own and not f.metadata.get(_HOOK)}


def settings_params(cls: type, only: Sequence[str] | None = None) -> tuple[Param, ...]:
    """The plugin parameters (and so the CLI options) of a settings class, one per leaf field
    (those named in ``only``, in that order, when given)."""
    found = [sf for sf in setting_fields(cls) if sf.bounds.cli]
    if only is not None:
        by_name = {sf.name: sf for sf in found}
        found = [by_name[name] for name in only]
    names = [sf.name for sf in found]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise TypeError(f"{cls.__name__}: fields {twice} are declared in two groups")
    return tuple(sf.param() for sf in found)


def with_help(params: tuple[Param, ...], **helps: str) -> tuple[Param, ...]:
    """``params`` with the ``--help`` text of some replaced (by keyword), for a plugin whose
    shared settings field means more for it than the field's own docstring says (its default,
    range and checks stay the field's). A keyword that names no parameter is a TypeError."""
    unknown = sorted(set(helps) - {p.keyword for p in params})
    if unknown:
        raise TypeError(f"with_help: no parameter {unknown[0]!r} among "
                        f"{', '.join(p.keyword for p in params)}")
    return tuple(dataclasses.replace(p, help=helps[p.keyword]) if p.keyword in helps else p
                 for p in params)


def build_settings(cls: type, values: dict[str, Any] | None = None) -> Any:
    """An instance of settings class ``cls`` from flat leaf values (``name``, ``name-x`` or the
    field's option spelling); groups get the values of their own fields. Unknown names raise
    TaskError."""
    from adpart.errors import TaskError

    leaves = setting_fields(cls)
    spelled = {sf.option[2:].replace("-", "_"): sf.name for sf in leaves}  # max_steps -> field
    given = {spelled.get(k.replace("-", "_"), k.replace("-", "_")): v
             for k, v in (values or {}).items()}
    known = {sf.name for sf in leaves}
    unknown = sorted(set(given) - known)
    if unknown:
        raise TaskError(f"{cls.__name__} has no setting {unknown[0]!r}; its settings: "
                        f"{', '.join(sorted(known))}")
    return _build(cls, given)


def _build(cls: type, given: dict[str, Any]) -> Any:
    own = {sf.name for sf in cls.__settings_fields__}  # type: ignore[attr-defined]
    kwargs = {n: given[n] for n in own if n in given}
    for name, group in _groups(cls).items():
        kwargs[name] = _build(group, given)
    return cls(**kwargs)


def settings_dict(obj: Any) -> dict[str, Any]:
    """The provenance record of a settings instance: every leaf field by name, flat."""
    out: dict[str, Any] = {}
    cls = type(obj)
    own = {sf.name for sf in cls.__settings_fields__}
    for f in fields(cls):
        if f.metadata.get(_HOOK):
            continue
        value = getattr(obj, f.name)
        if f.name in own:
            out[f.name] = value.to_dict() if hasattr(value, "to_dict") else value
        else:
            out.update(settings_dict(value))
    return out

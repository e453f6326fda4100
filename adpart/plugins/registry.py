"""The typed registry of plugin implementations, filled by the registration hooks."""

from __future__ import annotations

import difflib
import math
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

from adpart.errors import AdpartError, UnknownNameError

#: kind -> the hook that fills it. The kind names are what ``adpart plugins --kind`` accepts.
KINDS: dict[str, str] = {
    "environment": "register_environments",
    "learner": "register_learners",
    "executor": "register_executors",
    "subgoal-detector": "register_subgoal_detectors",
    "partition-criterion": "register_partition_criteria",
    "hierarchy-estimator": "register_hierarchy_estimators",
}

_TYPES: dict[str, type] = {"int": int, "float": float, "str": str, "bool": bool}


class PluginWarning(UserWarning):
    """A plugin could not be loaded or registered; everything else keeps working."""


class PluginError(AdpartError, ValueError):
    """An implementation or its parameters are invalid."""


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
    check: Callable[[Any], Any] | None = field(default=None, compare=False, repr=False)

    @property
    def keyword(self) -> str:
        return self.name.replace("-", "_")

    def convert(self, value: Any, owner: str) -> Any:
        """Validate and convert a user value, raising PluginError naming the fix."""
        if self.type not in _TYPES:
            raise PluginError(f"{owner}: parameter {self.name!r} has unknown type {self.type!r}")
        target = _TYPES[self.type]
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
        if self.type == "float" and not math.isfinite(out):
            raise PluginError(
                f"{owner}: --{self.name} must be a finite number; got {value!r}"
            )
        if self.choices is not None and out not in self.choices:
            raise PluginError(
                f"{owner}: --{self.name} must be one of {', '.join(self.choices)}; got {out!r}"
            )
        if self.min is not None and out < self.min:
            raise PluginError(f"{owner}: --{self.name} must be >= {self.min}; got {out!r}")
        if self.check is not None:
            try:
                self.check(out)
            except AdpartError as exc:
                raise PluginError(f"{owner}: --{self.name} {value!r}: {exc}") from None
        return out


@dataclass(frozen=True)
class PluginSpec:
    """One registered implementation: its kind, name, class and the package that provided it."""

    kind: str
    name: str
    factory: type
    package: str
    version: str

    @property
    def description(self) -> str:
        return str(getattr(self.factory, "description", "") or "").strip()

    @property
    def params(self) -> tuple[Param, ...]:
        return tuple(getattr(self.factory, "params", ()))

    def resolve_params(self, given: dict[str, Any] | None = None) -> dict[str, Any]:
        """Defaults overlaid with ``given`` (names with ``-`` or ``_``), validated and converted."""
        given = {k.replace("_", "-"): v for k, v in (given or {}).items()}
        declared = {p.name: p for p in self.params}
        unknown = sorted(set(given) - set(declared))
        if unknown:
            known = ", ".join(f"--{n}" for n in declared) or "none"
            raise PluginError(
                f"{self.kind} {self.name!r} has no parameter --{unknown[0]}; "
                f"its parameters: {known}"
            )
        owner = f"{self.kind} {self.name!r}"
        return {
            p.keyword: p.convert(given[p.name], owner) if p.name in given else p.default
            for p in self.params
        }

    def create(self, given: dict[str, Any] | None = None) -> Any:
        return self.factory(**self.resolve_params(given))


@dataclass
class Registry:
    """All registered implementations, by kind and name."""

    specs: dict[str, dict[str, PluginSpec]] = field(
        default_factory=lambda: {kind: {} for kind in KINDS}
    )

    def add(self, spec: PluginSpec) -> None:
        if not spec.name or not isinstance(spec.name, str):
            warnings.warn(
                f"{spec.package}: a {spec.kind} class {spec.factory.__name__} has no name; ignored",
                PluginWarning,
                stacklevel=2,
            )
            return
        existing = self.specs[spec.kind].get(spec.name)
        if existing is not None:
            warnings.warn(
                f"two {spec.kind} plugins are named {spec.name!r}: one from package "
                f"{existing.package!r}, one from package {spec.package!r}; keeping the one from "
                f"{existing.package!r}. Rename one of them (or uninstall {spec.package!r}).",
                PluginWarning,
                stacklevel=2,
            )
            return
        self.specs[spec.kind][spec.name] = spec

    def get(self, kind: str, name: str) -> PluginSpec:
        if kind not in self.specs:
            raise UnknownNameError(f"unknown plugin kind {kind!r}; kinds: {', '.join(KINDS)}")
        try:
            return self.specs[kind][name]
        except KeyError:
            names = list(self.specs[kind])
            hint = difflib.get_close_matches(name, names, n=1)
            raise UnknownNameError(
                f"no {kind} named {name!r}; installed: {', '.join(names) or 'none'}"
                + (f". Did you mean {hint[0]!r}?" if hint else "")
            ) from None

    def names(self, kind: str) -> list[str]:
        return list(self.specs[kind])

    def all(self, kind: str | None = None) -> Iterator[PluginSpec]:
        for k in KINDS if kind is None else (kind,):
            yield from self.specs[k].values()


@dataclass
class Registrar:
    """The callable handed to a registration hook: ``register(cls, name=None)``."""

    registry: Registry
    kind: str
    package: str
    version: str

    def __call__(self, cls: type, name: str | None = None) -> None:
        self.registry.add(
            PluginSpec(self.kind, name or getattr(cls, "name", ""), cls, self.package, self.version)
        )


RegisterFn = Callable[[type], None]

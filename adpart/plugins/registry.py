"""The typed registry of plugin implementations, filled by the registration hooks."""

from __future__ import annotations

import difflib
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

from adpart.errors import PluginError, UnknownNameError
from adpart.params import Param

#: kind -> the hook that fills it. The kind names are what ``adpart plugins --kind`` accepts.
KINDS: dict[str, str] = {
    "environment": "register_environments",
    "learner": "register_learners",
    "executor": "register_executors",
    "subgoal-detector": "register_subgoal_detectors",
    "partition-criterion": "register_partition_criteria",
    "hierarchy-estimator": "register_hierarchy_estimators",
}



class PluginWarning(UserWarning):
    """A plugin could not be loaded or registered; everything else keeps working."""


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

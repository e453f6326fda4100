"""The typed registry of plugin implementations, filled by the registration hooks."""

from __future__ import annotations

import difflib
import functools
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

from adpart.errors import AdpartError, PluginError, PluginFailure, UnknownNameError
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


#: kind -> the methods of its contract (:mod:`adpart.plugins.contracts`) that adpart calls on an
#: instance: a third-party plugin's are guarded (:meth:`PluginSpec.create`).
CONTRACT_METHODS: dict[str, tuple[str, ...]] = {
    "environment": ("dynamics", "tasks", "task", "mdp"),
    "learner": ("learn",),
    "executor": ("map",),
    "subgoal-detector": ("detect",),
    "partition-criterion": ("refine",),
    "hierarchy-estimator": ("build",),
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
        """An instance built from the checked parameters.

        A third-party plugin's constructor and contract methods (:data:`CONTRACT_METHODS`) are
        guarded: an exception they raise that is not an :class:`~adpart.errors.AdpartError`
        becomes a :class:`~adpart.errors.PluginFailure` naming the plugin and its package, so
        the command line reports it in one line (exit status 2) instead of a traceback through
        adpart. adpart's own plugins are not wrapped: their bugs are adpart's, and show as such.
        """
        values = self.resolve_params(given)
        if self.package == "adpart":
            return self.factory(**values)
        instance = GuardedCall(self, "__init__", self.factory)(**values)
        for method in CONTRACT_METHODS.get(self.kind, ()):
            bound = getattr(instance, method, None)
            if callable(bound):
                try:
                    setattr(instance, method, GuardedCall(self, method, bound))
                except AttributeError:  # __slots__ or a read-only attribute: left unguarded
                    pass
        return instance

    @property
    def origin(self) -> str:
        """``kind 'name' (package P V)``: how messages name this plugin."""
        return f"{self.kind} {self.name!r} (package {self.package} {self.version})".rstrip()


class GuardedCall:
    """A plugin method that turns its unexpected exceptions into :class:`PluginFailure`.

    Picklable with its plugin (a process pool may carry an instance to a worker), and it keeps
    the wrapped method's signature (``inspect.signature`` follows ``__wrapped__``).
    """

    def __init__(self, spec: PluginSpec, method: str, func: Callable[..., Any]) -> None:
        self.spec, self.method = spec, method
        functools.update_wrapper(self, func, updated=())

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        try:
            return self.__wrapped__(*args, **kwargs)
        except AdpartError:
            raise
        except Exception as exc:
            what = "building it" if self.method == "__init__" else f"{self.method}()"
            raise PluginFailure(
                f"{self.spec.origin} failed in {what}: {type(exc).__name__}: {exc}. This is a "
                f"bug of the plugin, not of your input: report it to {self.spec.package}'s "
                f"authors or choose another {self.spec.kind} (adpart --debug shows the "
                "traceback)"
            ) from exc


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

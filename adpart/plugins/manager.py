"""Build the plugin manager and the registry from entry points (pluggy, group ``adpart``).

Each entry point is loaded on its own, so a package that fails to import, or whose hooks are
misspelled, costs a :class:`~adpart.plugins.registry.PluginWarning` naming the package - never the
whole program. ``ADPART_DISABLE_PLUGINS=name1,name2`` blocks entry points by name (tox's idea).
"""

from __future__ import annotations

import importlib
import importlib.metadata
import os
import warnings

import pluggy

from adpart.plugins import hookspecs
from adpart.plugins.registry import KINDS, PluginWarning, Registrar, Registry

ENTRY_POINT_GROUP = "adpart"

#: The built-in plugins: entry-point name -> module. They are registered through adpart's own
#: entry points; this table is the fallback for a source tree that was never installed.
BUILTIN_PLUGINS: dict[str, str] = {
    "environments": "adpart.plugins.builtin.environments",
    "learners": "adpart.plugins.builtin.learners",
    "maxq": "adpart.plugins.builtin.maxq",
    "hierarchical": "adpart.plugins.builtin.hierarchical",
    "executors": "adpart.plugins.builtin.executors",
    "criteria": "adpart.plugins.builtin.criteria",
    "detectors": "adpart.plugins.builtin.detectors",
    "estimators": "adpart.plugins.builtin.estimators",
    "simpleoptions": "adpart.plugins.builtin.simpleoptions_detector",
}


class PluginManager(pluggy.PluginManager):
    """A pluggy manager that remembers which distribution provided each plugin."""

    def __init__(self) -> None:
        super().__init__(hookspecs.PROJECT)
        self.add_hookspecs(hookspecs)
        self.sources: dict[str, tuple[str, str]] = {}

    def register_checked(self, plugin: object, name: str, package: str, version: str) -> bool:
        """Register ``plugin``; on an invalid or misspelled hook warn and leave it out."""
        try:
            self.register(plugin, name=name)
            self.check_pending()
        except pluggy.PluginValidationError as exc:
            if self.is_registered(plugin):
                self.unregister(plugin)
            warnings.warn(
                f"plugin package {package!r} (entry point {name!r}) is invalid and was skipped: "
                f"{exc}",
                PluginWarning,
                stacklevel=2,
            )
            return False
        self.sources[name] = (package, version)
        return True


def _blocked() -> set[str]:
    return {n.strip() for n in os.environ.get("ADPART_DISABLE_PLUGINS", "").split(",") if n.strip()}


def make_plugin_manager(*, load_entrypoints: bool = True) -> PluginManager:
    """A fresh manager with every installed ``adpart`` entry point and the built-ins registered."""
    pm = PluginManager()
    blocked = _blocked()
    adpart_version = _version("adpart")
    if load_entrypoints:
        seen: set[tuple[str, str]] = set()
        for dist in importlib.metadata.distributions():
            package = dist.metadata["name"] or "unknown"
            for ep in dist.entry_points:
                if ep.group != ENTRY_POINT_GROUP or (package, ep.name) in seen:
                    continue
                seen.add((package, ep.name))
                # another package's entry point may share a name with adpart's own ("learners"):
                # it is registered under "<package>:<name>", so it can never hide a built-in
                name = ep.name if package == "adpart" else f"{package}:{ep.name}"
                if {ep.name, name} & blocked or pm.has_plugin(name):
                    continue
                try:
                    plugin = ep.load()
                except Exception as exc:  # noqa: BLE001 (a broken plugin must not break adpart)
                    warnings.warn(
                        f"plugin package {package!r} failed to import (entry point {ep.name} = "
                        f"{ep.value}): {type(exc).__name__}: {exc}. It is skipped; everything "
                        f"else works. Fix or uninstall {package!r}, or set "
                        f"ADPART_DISABLE_PLUGINS={ep.name}.",
                        PluginWarning,
                        stacklevel=2,
                    )
                    continue
                pm.register_checked(plugin, name, package, dist.version or "")
    for name, module in BUILTIN_PLUGINS.items():
        if name not in blocked and not pm.has_plugin(name):
            pm.register_checked(importlib.import_module(module), name, "adpart", adpart_version)
    return pm


def _version(dist: str) -> str:
    try:
        return importlib.metadata.version(dist)
    except importlib.metadata.PackageNotFoundError:
        return "0+unknown"


def build_registry(pm: PluginManager, kinds: tuple[str, ...] | None = None) -> Registry:
    """Call every registration hook (of ``kinds``; default all), built-ins first, and collect
    what they register."""
    registry = Registry()
    for kind, hook_name in KINDS.items():
        if kinds is not None and kind not in kinds:
            continue
        impls = getattr(pm.hook, hook_name).get_hookimpls()
        impls.sort(key=lambda impl: pm.sources.get(impl.plugin_name, ("", ""))[0] != "adpart")
        for impl in impls:
            package, version = pm.sources.get(impl.plugin_name, (impl.plugin_name, ""))
            try:
                impl.function(register=Registrar(registry, kind, package, version))
            except Exception as exc:  # noqa: BLE001 (one failing hook must not break the others)
                warnings.warn(
                    f"plugin package {package!r} failed in {hook_name}: "
                    f"{type(exc).__name__}: {exc}; its {kind} plugins are skipped",
                    PluginWarning,
                    stacklevel=2,
                )
    return registry


_REGISTRY: Registry | None = None


def get_registry() -> Registry:
    """The process-wide registry, built on first use."""
    global _REGISTRY
    if _REGISTRY is None:
        _REGISTRY = build_registry(make_plugin_manager())
    return _REGISTRY


def reset_registry() -> None:
    """Forget the cached registry (tests; after installing a plugin at run time)."""
    global _REGISTRY
    _REGISTRY = None
    _BUILTIN.clear()


_BUILTIN: dict[str, Registry] = {}


def builtin_registry(kind: str) -> Registry:
    """adpart's own plugins of one ``kind``, without importing any other package's.

    What ``--help`` of a command shows for a built-in plugin: a built-in always keeps its name
    (:meth:`Registry.add` keeps the first of two, and built-ins come first), so its parameters
    are the same whatever else is installed, and the help need not import third-party plugins
    (nor the built-ins' implementations, which their modules import only when used).
    """
    if kind not in _BUILTIN:
        _BUILTIN[kind] = build_registry(make_plugin_manager(load_entrypoints=False), (kind,))
    return _BUILTIN[kind]

"""adpart's plugin system: pluggy hookspecs, the typed registry, and the built-in plugins.

Third-party packages extend adpart by exposing a module with ``@hookimpl`` functions under the
``adpart`` entry-point group; see ``docs/plugins.md``.
"""

from typing import TYPE_CHECKING

from adpart.lazy import lazy_exports

if TYPE_CHECKING:
    from adpart.plugins.hookspecs import hookimpl
    from adpart.plugins.manager import (
        build_registry,
        get_registry,
        make_plugin_manager,
        reset_registry,
    )
    from adpart.plugins.registry import (
        KINDS,
        Param,
        PluginError,
        PluginSpec,
        PluginWarning,
        Registry,
    )

lazy_exports(__name__, {
    "adpart.plugins.hookspecs": ("hookimpl",),
    "adpart.plugins.manager": (
        "build_registry", "get_registry", "make_plugin_manager", "reset_registry",
    ),
    "adpart.plugins.registry": (
        "KINDS", "Param", "PluginError", "PluginSpec", "PluginWarning", "Registry",
    ),
})

__all__ = [
    "KINDS",
    "Param",
    "PluginError",
    "PluginSpec",
    "PluginWarning",
    "Registry",
    "build_registry",
    "get_registry",
    "hookimpl",
    "make_plugin_manager",
    "reset_registry",
]

"""Package exports loaded on first use (PEP 562), so that importing a package costs nothing.

A package ``__init__`` lists its public names under ``if TYPE_CHECKING:`` (what type checkers
and the API reference read) and hands the same names to :func:`lazy_exports`:
``from adpart.learning import q_learning`` then imports :mod:`adpart.learning.qlearning` (and
numba) only when ``q_learning`` is asked for, and ``adpart learn --help`` never does.
``tests/test_lazy_exports.py`` checks that every package's table, its ``__all__`` and its
``TYPE_CHECKING`` imports name the same objects.
"""

from __future__ import annotations

import importlib
import sys
import types
from collections.abc import Iterable
from typing import Any


class LazyPackage(types.ModuleType):
    """A package module whose exports are imported on first access.

    When a submodule shares its name with an export (``adpart.partition.refine`` defines
    ``refine``), importing the submodule binds the export, not the submodule, to the package's
    name - what ``from adpart.partition.refine import refine`` in an eager ``__init__`` did.
    """

    _lazy_where: dict[str, str]

    def __getattr__(self, name: str) -> Any:
        module = self.__dict__.get("_lazy_where", {}).get(name)
        if module is None:
            raise AttributeError(f"module {self.__name__!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(module), name)
        super().__setattr__(name, value)
        return value

    def __setattr__(self, name: str, value: Any) -> None:
        if (isinstance(value, types.ModuleType)
                and value.__name__ == f"{self.__name__}.{name}"
                and self.__dict__.get("_lazy_where", {}).get(name) == value.__name__):
            value = getattr(value, name)
        super().__setattr__(name, value)

    def __dir__(self) -> list[str]:
        return sorted({*self.__dict__, *self.__dict__.get("_lazy_where", {})})


def lazy_exports(package: str, exports: dict[str, Iterable[str]]) -> None:
    """Make ``package`` export ``{submodule: names}``, each imported on first access.

    ``submodule`` is absolute (``"adpart.learning.curves"``); the object is then cached in the
    package's namespace, so later accesses are plain attribute lookups.
    """
    module = sys.modules[package]
    module.__dict__["_lazy_where"] = {
        name: source for source, names in exports.items() for name in names}
    module.__class__ = LazyPackage

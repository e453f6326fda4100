"""Declared parameters: the one typed description of a tunable, shared by plugins and executors.

A :class:`Param` names a constructor keyword, its type, default, help line and bounds. The plugin
registry turns declared parameters into CLI options and validates user values with
:meth:`Param.convert`; the module imports nothing else of adpart but its error tree, so any layer
may declare parameters.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from adpart.errors import AdpartError, PluginError

__all__ = ["PARAM_TYPES", "Param"]

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
        if self.type not in PARAM_TYPES:
            raise PluginError(f"{owner}: parameter {self.name!r} has unknown type {self.type!r}")
        target = PARAM_TYPES[self.type]
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

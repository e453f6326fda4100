"""Built-in subgoal detectors (section 4.1 and the literature), registered like any plugin."""

from __future__ import annotations

from adpart.plugins.hookspecs import hookimpl
from adpart.plugins.registry import Registrar


@hookimpl
def register_subgoal_detectors(register: Registrar) -> None:
    from adpart.subgoals.detectors import DETECTORS

    for cls in DETECTORS:
        register(cls)

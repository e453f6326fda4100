"""Lookup of environments by name: the built-in domains and ``gym:<id>`` Gymnasium environments.

Built-in domains are imported lazily (``"module:Class"``), so listing them costs nothing.
"""

from __future__ import annotations

import difflib
import importlib

from adpart.envs.base import Domain
from adpart.errors import UnknownNameError

#: name -> "module:Class" of every built-in domain.
BUILTIN_DOMAINS: dict[str, str] = {
    "two-rooms": "adpart.envs.domains.two_rooms:TwoRooms",
    "four-rooms": "adpart.envs.domains.four_rooms:FourRooms",
    "three-floor": "adpart.envs.domains.three_floor:ThreeFloor",
    "three-floor-arm": "adpart.envs.domains.three_floor:ThreeFloorArm",
    "parr-maze": "adpart.envs.domains.parr_maze:ParrMaze",
    "taxi": "adpart.envs.domains.taxi:Taxi",
    "taxi-fickle": "adpart.envs.domains.taxi:FickleTaxi",
    "urban": "adpart.envs.domains.urban:Urban",
}

GYM_PREFIX = "gym:"


def load_class(target: str) -> type:
    module, _, attr = target.partition(":")
    return getattr(importlib.import_module(module), attr)


def domain_names() -> list[str]:
    return list(BUILTIN_DOMAINS)


def get_domain(name: str) -> Domain:
    """The environment called ``name``: a built-in domain, or ``gym:<id>`` for Gymnasium."""
    if name.startswith(GYM_PREFIX):
        from adpart.envs.gym_adapter import GymDomain

        return GymDomain(name.removeprefix(GYM_PREFIX))
    if name not in BUILTIN_DOMAINS:
        hint = difflib.get_close_matches(name, list(BUILTIN_DOMAINS), n=1)
        raise UnknownNameError(
            f"unknown environment {name!r}; known: {', '.join(BUILTIN_DOMAINS)}"
            + (f". Did you mean {hint[0]!r}?" if hint else "")
            + ". Gymnasium environments are named gym:<id>, e.g. gym:Taxi-v4"
        )
    return load_class(BUILTIN_DOMAINS[name])()

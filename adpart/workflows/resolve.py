"""Resolve environment names through the plugin registry (or ``gym:<id>``, ``minigrid:<id>``)."""

from __future__ import annotations

from adpart.envs.base import Domain
from adpart.envs.registry import ADAPTER_PREFIXES, get_domain
from adpart.errors import UnknownNameError
from adpart.plugins import get_registry

#: What joins an environment's name and the runs whose experience estimates its dynamics.
EXPERIENCE_MARK = "@experience:"

#: Environments built in this process from other data (the estimated models), by name.
_BUILT: dict[str, Domain] = {}


def register_domain(name: str, domain: Domain) -> None:
    """Make ``name`` resolve to ``domain`` in this process (:mod:`adpart.workflows.experience`)."""
    _BUILT[name] = domain


def base_environment(name: str) -> str:
    """The environment a model estimated from experience is of (``name`` itself otherwise)."""
    return name.split(EXPERIENCE_MARK, 1)[0]


def resolve_domain(name: str) -> Domain:
    """A registered environment plugin by name, ``gym:<id>`` or ``minigrid:<id>`` through the
    Gymnasium or MiniGrid adapter, or a model estimated from experience that this process built."""
    if name in _BUILT:
        return _BUILT[name]
    if EXPERIENCE_MARK in name:
        raise UnknownNameError(
            f"{name!r} is {base_environment(name)!r} as estimated from the experience of "
            f"{name.split(EXPERIENCE_MARK, 1)[1]}; it is rebuilt from those runs by the pipeline "
            "that uses it (adpart pipeline --regime learned-model), not resolved by name")
    if name.startswith(ADAPTER_PREFIXES):
        return get_domain(name)
    try:
        spec = get_registry().get("environment", name)
    except UnknownNameError as exc:
        raise UnknownNameError(
            f"{exc}. Gymnasium environments are named gym:<id>, e.g. gym:Taxi-v4; MiniGrid "
            "layouts minigrid:<id>, e.g. minigrid:MiniGrid-FourRooms-v0"
        ) from None
    return spec.create()  # a third-party environment's own failures named (PluginFailure)

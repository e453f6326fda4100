"""Resolve environment names through the plugin registry (or ``gym:<id>``)."""

from __future__ import annotations

from adpart.envs.base import Domain
from adpart.envs.registry import GYM_PREFIX, get_domain
from adpart.errors import UnknownNameError
from adpart.plugins import get_registry


def resolve_domain(name: str) -> Domain:
    """A registered environment plugin by name, or ``gym:<id>`` through the Gymnasium adapter."""
    if name.startswith(GYM_PREFIX):
        return get_domain(name)
    try:
        spec = get_registry().get("environment", name)
    except UnknownNameError as exc:
        raise UnknownNameError(
            f"{exc}. Gymnasium environments are named gym:<id>, e.g. gym:Taxi-v4"
        ) from None
    return spec.factory()

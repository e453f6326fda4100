"""The installed package: adpart discovers the three plugins through their entry points."""

from __future__ import annotations

import importlib.metadata

import pytest
from adpart.plugins import get_registry
from adpart.testing import check_plugin

PLUGINS = [("environment", "three-rooms-line"), ("subgoal-detector", "doorways"),
           ("learner", "sarsa"), ("partition-criterion", "capped-blocks")]


def installed() -> bool:
    try:
        importlib.metadata.distribution("adpart-plugin-example")
    except importlib.metadata.PackageNotFoundError:
        return False
    return True


pytestmark = pytest.mark.skipif(
    not installed(), reason="adpart-plugin-example is not installed (pip install -e .)"
)


@pytest.mark.parametrize(("kind", "name"), PLUGINS)
def test_discovered_through_the_entry_point_and_conformant(kind, name):
    spec = get_registry().get(kind, name)
    assert spec.package == "adpart-plugin-example"
    check_plugin(spec)

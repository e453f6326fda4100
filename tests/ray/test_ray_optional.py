"""Ray stays optional: the plugin registers without it and using it names the install command."""

from __future__ import annotations

import sys

import pytest

import adpart.plugins.builtin.executors as executors_plugin
from adpart.execution.ray import ClusterError, RayExecutor, import_ray
from adpart.plugins import build_registry, make_plugin_manager


@pytest.fixture
def no_ray(monkeypatch):
    """Make ``import ray`` fail as if Ray were not installed."""
    monkeypatch.setitem(sys.modules, "ray", None)


def test_ray_plugin_registers_without_ray(no_ray):
    pm = make_plugin_manager(load_entrypoints=False)
    if not pm.has_plugin("executors"):
        pm.register_checked(executors_plugin, "executors", "adpart", "test")
    spec = build_registry(pm).get("executor", "ray")
    assert spec.factory is RayExecutor
    assert [p.name for p in spec.params] == ["address", "num-cpus", "max-retries",
                                            "retry-exceptions"]
    executor = spec.create({"address": "10.0.0.5:6379", "max-retries": "5"})
    assert (executor.address, executor.max_retries) == ("10.0.0.5:6379", 5)


def test_ray_executor_without_ray_names_the_extra(no_ray):
    with pytest.raises(ClusterError, match=r"pip install 'adpart\[ray\]'"):
        import_ray()
    with RayExecutor() as ex, pytest.raises(ClusterError, match=r"adpart\[ray\]"):
        ex.map(abs, [1, 2])


def test_ray_module_does_not_import_ray_at_import_time():
    code = ("import sys, adpart.plugins.builtin.executors, adpart.workflows.sweep, "
            "adpart.cli.sweep; assert 'ray' not in sys.modules")
    import subprocess

    subprocess.run([sys.executable, "-c", code], check=True)

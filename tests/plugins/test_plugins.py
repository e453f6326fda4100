"""The plugin manager and registry: built-ins, third-party entry points, failures, parameters."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from adpart.errors import UnknownNameError
from adpart.plugins import (
    KINDS,
    Param,
    PluginError,
    PluginWarning,
    build_registry,
    get_registry,
    hookimpl,
    make_plugin_manager,
)
from adpart.plugins.manager import BUILTIN_PLUGINS
from tests.plugins.conftest import FAKE_PLUGIN, install_fake_distribution

DOCS = Path(__file__).resolve().parents[2] / "docs" / "plugins.md"


def test_builtins_come_from_adpart_entry_points():
    pm = make_plugin_manager()
    for name in BUILTIN_PLUGINS:
        assert pm.sources[name][0] == "adpart"
    reg = build_registry(pm)
    assert {"local", "serial"} <= set(reg.names("executor"))
    assert "two-rooms" in reg.names("environment")
    assert reg.get("executor", "local").package == "adpart"


def test_every_hook_is_documented_and_every_kind_has_a_hook():
    text = DOCS.read_text()
    from adpart.plugins import hookspecs

    hooks = {n for n in dir(hookspecs) if n.startswith("register_")}
    assert hooks == set(KINDS.values())
    for hook in hooks:
        assert re.search(rf"^### {hook}\(register\)$", text, re.MULTILINE), f"{hook} undocumented"


def test_third_party_entry_point_is_discovered(plugin_site):
    install_fake_distribution(plugin_site, "fake-adpart-exec", "fake_adpart_exec", FAKE_PLUGIN)
    spec = get_registry().get("executor", "reversed-serial")
    assert spec.package == "fake-adpart-exec"
    assert spec.version == "0.1"
    with spec.create({"label": "y"}) as ex:
        assert ex.label == "y"
        assert ex.map(abs, [-1, -2, 3]) == [1, 2, 3]


def test_broken_plugin_warns_with_package_name_and_rest_keeps_working(plugin_site):
    install_fake_distribution(
        plugin_site, "fake-adpart-broken", "fake_adpart_broken", "import no_such_module_xyz\n"
    )
    with pytest.warns(
        PluginWarning, match=r"'fake-adpart-broken' failed to import.*no_such_module_xyz"
    ):
        reg = get_registry()
    assert "local" in reg.names("executor")


def test_an_entry_point_named_like_a_builtin_hides_nothing(plugin_site):
    source = FAKE_PLUGIN.replace('name = "reversed-serial"', 'name = "clashing-serial"')
    # the same entry-point name as adpart's own executors module
    root = install_fake_distribution(plugin_site, "fake-adpart-clash", "fake_adpart_clash", source)
    (next(root.glob("*.dist-info")) / "entry_points.txt").write_text(
        "[adpart]\nexecutors = fake_adpart_clash\n")
    reg = get_registry()
    assert {"local", "serial", "clashing-serial"} <= set(reg.names("executor"))
    assert reg.get("executor", "clashing-serial").package == "fake-adpart-clash"


def test_misspelled_hook_warns(plugin_site):
    source = (
        "from adpart.plugins import hookimpl\n"
        "@hookimpl\ndef register_lerners(register):\n    pass\n"
    )
    install_fake_distribution(plugin_site, "fake-adpart-typo", "fake_adpart_typo", source)
    with pytest.warns(PluginWarning, match=r"'fake-adpart-typo'.*register_lerners"):
        reg = get_registry()
    assert "serial" in reg.names("executor")


def test_duplicate_name_keeps_builtin_and_names_both_packages(plugin_site):
    source = FAKE_PLUGIN.replace('name = "reversed-serial"', 'name = "serial"')
    install_fake_distribution(plugin_site, "fake-adpart-dup", "fake_adpart_dup", source)
    with pytest.warns(PluginWarning, match=r"named 'serial'.*'adpart'.*'fake-adpart-dup'"):
        reg = get_registry()
    assert reg.get("executor", "serial").package == "adpart"


def test_failing_registration_hook_is_contained():
    class Exploding:
        @hookimpl
        def register_executors(self, register):
            raise RuntimeError("boom")

    pm = make_plugin_manager()
    pm.register_checked(Exploding(), "exploding", "exploding-pkg", "1.0")
    with pytest.warns(
        PluginWarning, match=r"'exploding-pkg' failed in register_executors: RuntimeError: boom"
    ):
        reg = build_registry(pm)
    assert "local" in reg.names("executor")


def test_disable_plugins_env_var(monkeypatch):
    monkeypatch.setenv("ADPART_DISABLE_PLUGINS", "executors,ray")
    reg = build_registry(make_plugin_manager())
    assert reg.names("executor") == []
    assert "two-rooms" in reg.names("environment")


def test_unknown_names_suggest_the_closest():
    reg = get_registry()
    with pytest.raises(UnknownNameError, match=r"no executor named 'locl'.*Did you mean 'local'"):
        reg.get("executor", "locl")
    with pytest.raises(UnknownNameError, match=r"unknown plugin kind"):
        reg.get("widget", "x")


def test_params_are_validated_and_converted():
    spec = get_registry().get("executor", "local")
    assert spec.resolve_params({}) == {"workers": 0}
    assert spec.resolve_params({"workers": "3"}) == {"workers": 3}
    with pytest.raises(PluginError, match=r"--workers expects int, got 'two'"):
        spec.resolve_params({"workers": "two"})
    with pytest.raises(PluginError, match=r"--workers must be >= 0"):
        spec.resolve_params({"workers": -1})
    with pytest.raises(PluginError, match=r"has no parameter --threads; its parameters: --workers"):
        spec.resolve_params({"threads": 2})
    choice = Param("mode", "str", "a", "mode", choices=("a", "b"))
    with pytest.raises(PluginError, match=r"must be one of a, b"):
        choice.convert("c", "x")
    flag = Param("on", "bool", False, "flag")
    assert flag.convert("yes", "x") is True
    with pytest.raises(PluginError, match=r"expects true or false"):
        flag.convert("maybe", "x")


def test_local_executor_returns_results_in_order():
    from adpart.execution import LocalExecutor

    with LocalExecutor(workers=2) as ex:
        assert ex.map(abs, [-5, 4, -3, 2, -1]) == [5, 4, 3, 2, 1]


def numba_threads_here(_: object) -> int:
    import numba

    return numba.get_num_threads()


def test_local_executor_workers_use_one_numba_thread():
    # The pool's workers already fill the cores; threaded kernels inside them would oversubscribe.
    from adpart.execution import LocalExecutor

    with LocalExecutor(workers=2) as ex:
        assert ex.map(numba_threads_here, range(4)) == [1, 1, 1, 1]



def test_documented_entry_points_and_builtins_are_the_installed_ones():
    # the entry-point table of docs/plugins.md is adpart's own (pyproject.toml), line for line
    text = DOCS.read_text()
    table = re.search(r"```toml\n\[project.entry-points.adpart\]\n(.*?)```", text, re.DOTALL)
    pyproject = (DOCS.parents[1] / "pyproject.toml").read_text()
    ours = re.search(r"^\[project.entry-points.adpart\]\n(.*?)(?:^\[|\Z)", pyproject,
                     re.MULTILINE | re.DOTALL)
    assert table.group(1).strip().split("\n") == ours.group(1).strip().split("\n")
    # every hook's "Built-ins:" list names exactly adpart's registered plugins of that kind
    reg = get_registry()
    for kind, hook in KINDS.items():
        section = re.search(rf"^### {hook}\(register\)$(.*?)(?=^### |\Z)", text,
                            re.MULTILINE | re.DOTALL).group(1)
        listed = re.search(r"Built-ins: (.*?)(?:\(see|;|\.\s)", " ".join(section.split()))
        assert listed, f"{hook}: no 'Built-ins:' list"
        names = re.findall(r"`([^`]+)`", listed.group(1))
        builtin = [s.name for s in reg.all(kind) if s.package == "adpart"]
        assert sorted(names) == sorted(builtin), hook

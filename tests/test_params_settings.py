"""The settings machinery (adpart.params): one declaration gives the check, the help, the plugin
parameters, the command-line options and the provenance."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import field

import click
import pytest
from click.testing import CliRunner
from hypothesis import given
from hypothesis import strategies as st

from adpart.cli.common import settings_options
from adpart.errors import PluginError, TaskError
from adpart.params import (
    build_settings,
    setting,
    setting_fields,
    settings,
    settings_dict,
    settings_params,
)


@settings
class Inner:
    """A group."""

    delta: float = setting(0.3, min=0.0, max=1.0)
    """delta of eq. 4.6, in [0, 1]."""

    epsilon: float | None = setting(None, kind="float", min=0.0, none="none")
    """epsilon of eq. 4.7; none: no reward split."""


@settings
class Outer:
    """Settings with a group and a rule across fields."""

    mode: str = setting("a", choices=("a", "b"))
    """the mode."""

    runs: int = setting(10, min=1)
    """independent runs."""

    cap: float = setting(math.inf, min=1.0, finite=False, cli=False)
    """a Python-only bound."""

    inner: Inner = field(default_factory=Inner)

    def check(self) -> None:
        if self.mode == "b" and self.inner.delta > 0.5:
            raise TaskError("mode b needs delta <= 0.5 (--delta)")


def test_help_is_the_fields_docstring_and_defaults_are_declared_once():
    fields = {sf.name: sf for sf in setting_fields(Outer)}
    assert list(fields) == ["mode", "runs", "cap", "delta", "epsilon"]
    assert fields["delta"].help == "delta of eq. 4.6, in [0, 1]."
    assert Outer().inner.delta == 0.3 and Outer().inner.epsilon is None
    params = {p.name: p for p in settings_params(Outer)}
    assert "cap" not in params  # cli=False
    assert params["delta"].default == 0.3 and params["delta"].max == 1.0
    assert params["epsilon"].none == "none" and params["mode"].choices == ("a", "b")


@pytest.mark.parametrize(("values", "needle"), [
    ({"delta": 2}, "delta = 2 must be <= 1.0 (--delta)"),
    ({"runs": 0}, "runs = 0 must be >= 1 (--runs)"),
    ({"runs": 2.5}, "runs = 2.5 must be an integer"),
    ({"mode": "c"}, "mode = 'c' must be one of a, b"),
    ({"delta": float("nan")}, "must be a finite number"),
    ({"runs": None}, "runs = None; give a int"),
    ({"mode": "b", "delta": 0.6}, "mode b needs delta <= 0.5"),
    ({"nope": 1}, "Outer has no setting 'nope'"),
])
def test_bad_values_name_the_field_and_the_option(values, needle):
    with pytest.raises(TaskError) as err:
        build_settings(Outer, values)
    assert needle in str(err.value)


def test_instances_are_frozen_checked_on_replace_and_recorded_flat():
    s = build_settings(Outer, {"delta": 0.4, "mode": "b", "cap": math.inf})
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.runs = 3  # type: ignore[misc]
    with pytest.raises(TaskError, match="must be >= 1"):
        dataclasses.replace(s, runs=0)
    assert settings_dict(s) == {"mode": "b", "runs": 10, "cap": math.inf, "delta": 0.4,
                                "epsilon": None}


def test_a_field_without_docstring_or_declaration_is_refused_when_the_class_is_made():
    with pytest.raises(TypeError, match="has no docstring"):
        @settings
        class NoHelp:
            x: int = setting(1)

    with pytest.raises(TypeError, match="declare it with setting"):
        @settings
        class Plain:
            x: int = 1
            """an x."""


@given(delta=st.floats(0.0, 1.0), runs=st.integers(1, 10**6), mode=st.sampled_from("ab"))
def test_a_value_given_on_the_command_line_builds_what_python_builds(delta, runs, mode):
    """Property: a plugin parameter's conversion of the printed value, then the settings
    class, equals the settings built from the value itself (or both refuse it)."""
    params = {p.name: p for p in settings_params(Outer)}
    given_values = {"delta": delta, "runs": runs, "mode": mode}
    converted = {k: params[k].convert(str(v), "test") for k, v in given_values.items()}
    try:
        direct = build_settings(Outer, given_values)
    except TaskError:
        with pytest.raises(TaskError):
            build_settings(Outer, converted)
        return
    assert build_settings(Outer, converted) == direct


def test_the_command_line_options_are_derived_typed_and_checked():
    @click.command()
    @settings_options(Outer, "outer")
    def command(outer: Outer) -> None:
        click.echo(repr(settings_dict(outer)))

    runner = CliRunner()
    help_text = runner.invoke(command, ["--help"]).output
    assert "--delta FLOAT" in help_text and "delta of eq. 4.6" in help_text
    assert "--epsilon FLOAT|none" in help_text and "--mode [a|b]" in help_text
    assert "--cap" not in help_text
    ok = runner.invoke(command, ["--delta", "0.2", "--epsilon", "none", "--mode", "b"])
    assert ok.exit_code == 0 and "'delta': 0.2" in ok.output and "'epsilon': None" in ok.output
    bad = runner.invoke(command, ["--delta", "nan"])
    assert bad.exit_code == 2 and "--delta = nan must be a finite number" in bad.output
    rule = runner.invoke(command, ["--mode", "b", "--delta", "0.9"])
    assert rule.exit_code == 2 and "mode b needs delta <= 0.5" in rule.output


def test_a_plugin_parameter_refuses_what_the_field_refuses():
    params = {p.name: p for p in settings_params(Outer)}
    with pytest.raises(PluginError, match=r"--delta must be <= 1\.0; got 1\.5"):
        params["delta"].convert("1.5", "x")
    assert params["epsilon"].convert("none", "x") is None


def test_a_class_defined_where_python_keeps_no_source_still_works():
    """``exec`` (or a bare REPL) keeps no source to read docstrings from: the field's name is
    its help, and everything else works."""
    namespace: dict = {}
    exec(compile("from adpart.params import setting, settings\n\n@settings\nclass S:\n"  # noqa: S102
                 "    max_size: int = setting(16, min=1)\n", "<no source>", "exec"), namespace)
    (param,) = settings_params(namespace["S"])
    assert param.help == "max size" and param.default == 16
    with pytest.raises(TaskError, match="must be >= 1"):
        build_settings(namespace["S"], {"max_size": 0})

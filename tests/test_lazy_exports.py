"""Every lazily exporting package (adpart/lazy.py): its table, its ``__all__`` and its
``TYPE_CHECKING`` imports (what the API reference reads) name the same objects, and each
name resolves to the object its submodule defines."""

from __future__ import annotations

import ast
import importlib
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "adpart"
LAZY = sorted(
    ".".join(p.relative_to(PACKAGE.parent).parent.parts)
    for p in PACKAGE.rglob("__init__.py") if "lazy_exports(__name__" in p.read_text())


def _type_checking_imports(package: str) -> dict[str, str]:
    """``name -> submodule`` of the imports under ``if TYPE_CHECKING:`` of ``package``."""
    path = PACKAGE.parent.joinpath(*package.split("."), "__init__.py")
    found = {}
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, ast.If) and getattr(node.test, "id", None) == "TYPE_CHECKING":
            for imp in node.body:
                assert isinstance(imp, ast.ImportFrom), ast.dump(imp)
                found.update({a.name: imp.module for a in imp.names})
    return found


def test_the_heavy_packages_export_lazily():
    assert {"adpart.learning", "adpart.store", "adpart.mdp", "adpart.partition",
            "adpart.options", "adpart.subgoals", "adpart.hierarchy", "adpart.workflows",
            "adpart.plugins"} <= set(LAZY)


@pytest.mark.parametrize("package", LAZY)
def test_table_all_and_type_checking_imports_agree(package):
    module = importlib.import_module(package)
    table = module.__dict__["_lazy_where"]
    assert table == _type_checking_imports(package)
    assert set(module.__all__) == set(table)
    for name, source in table.items():
        assert getattr(module, name) is getattr(importlib.import_module(source), name)
    assert set(table) <= set(dir(module))


def test_an_unknown_name_is_an_attribute_error():
    import adpart.learning

    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        adpart.learning.nope  # noqa: B018


def test_a_submodule_named_like_its_export_binds_the_export():
    """``adpart.partition.refine`` is a module and the function it defines; importing the
    module (as the partition code does) leaves the package's name bound to the function."""
    code = ("import adpart.partition.refine, adpart.partition as p, types; "
            "assert callable(p.refine) and not isinstance(p.refine, types.ModuleType)")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_importing_a_package_imports_none_of_its_submodules():
    code = ("import sys, adpart.learning, adpart.store, adpart.partition, adpart.subgoals; "
            "heavy = [m for m in ('numpy', 'numba', 'scipy', 'sqlalchemy', 'pyarrow') "
            "if m in sys.modules]; assert not heavy, heavy")
    subprocess.run([sys.executable, "-c", code], check=True)

"""The import rules of the package layout (DESIGN.md's layers), checked on the source tree.

Every ``import`` of an ``adpart`` module is read from the syntax tree - module level, inside
functions and under ``TYPE_CHECKING`` alike - and checked against :func:`allowed`: the numeric
cores import only the foundation and cores below them; the executors only the foundation; the
store the foundation and the cores; plugins and workflows anything but the experiments and the
CLI; the experiments anything but the store (they go through the workflows) and the CLI; the
conformance checks the cores, executors and plugin contracts. A new violation fails this test
with the file, the line and the rule it breaks.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "adpart"

FOUNDATION = {"errors", "params", "plotting"}
#: the numeric cores by rank: a core may import cores of a lower rank only
CORE_RANK = {"mdp": 1, "envs": 2, "subgoals": 3, "partition": 3, "options": 4, "learning": 5,
             "hierarchy": 6}
CORES = set(CORE_RANK)
UPPER = {"execution", "store", "plugins", "workflows", "experiments", "testing", "cli"}


def allowed(unit: str) -> set[str]:
    """The top-level units ``unit`` may import (besides itself)."""
    if unit in FOUNDATION:
        return FOUNDATION
    if unit == "__init__":  # the package's front door re-exports the MDP classes, lazily
        return FOUNDATION | {"mdp"}
    if unit in CORES:
        return FOUNDATION | {c for c, r in CORE_RANK.items() if r < CORE_RANK[unit]}
    if unit == "execution":
        return FOUNDATION
    if unit == "store":
        return FOUNDATION | CORES
    if unit in {"plugins", "workflows"}:
        return FOUNDATION | CORES | {"execution", "store", "plugins", "workflows"}
    if unit == "experiments":  # they reach the knowledge base through the workflows
        return FOUNDATION | CORES | {"execution", "plugins", "workflows"}
    if unit == "testing":  # the conformance checks know the cores, executors and contracts
        return FOUNDATION | CORES | {"execution", "plugins"}
    return FOUNDATION | CORES | UPPER


def _module_name(path: Path, root: Path) -> list[str]:
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    return parts[:-1] if parts[-1] == "__init__" else parts


def imports(path: Path, root: Path) -> list[tuple[int, str]]:
    """``(line, absolute module)`` of every adpart import in ``path`` (relative ones resolved)."""
    name = _module_name(path, root)
    package = name if path.name == "__init__.py" else name[:-1]
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            out.append((node.lineno, target))
    return [(line, t) for line, t in out if t.split(".")[0] == root.name]


def unit_of(module: list[str] | str) -> str:
    parts = module.split(".") if isinstance(module, str) else module
    return parts[1] if len(parts) > 1 else "__init__"


def violations(root: Path = PACKAGE) -> list[str]:
    """Every import in the tree under ``root`` that breaks :func:`allowed`, one line each."""
    found = []
    for path in sorted(root.rglob("*.py")):
        unit = unit_of(_module_name(path, root))
        for line, target in imports(path, root):
            dest = unit_of(target)
            if dest not in {unit, "__init__"} and dest not in allowed(unit):
                found.append(f"{path.relative_to(root.parent)}:{line}: {unit} imports {target}")
    return found


def test_the_package_keeps_its_layers():
    assert violations() == []


def test_every_top_level_unit_has_a_rule():
    units = {p.stem if p.is_file() else p.name for p in PACKAGE.iterdir()
             if (p.suffix == ".py") or (p.is_dir() and (p / "__init__.py").exists())}
    known = FOUNDATION | CORES | UPPER | {"__init__"}
    assert units <= known, sorted(units - known)


@pytest.mark.parametrize(("where", "source", "rule"), [
    ("mdp/model.py", "from adpart.plugins.registry import Param\n", "mdp imports adpart.plugins"),
    ("options/models.py", "from adpart.execution import (\n    Executor,\n)\n",
     "options imports adpart.execution"),
    ("partition/x.py", "from ..learning import curves\n", "partition imports adpart.learning"),
    ("subgoals/x.py", "import adpart.partition\n", "subgoals imports adpart.partition"),
    ("workflows/x.py", "from adpart.experiments.stats import compare\n",
     "workflows imports adpart.experiments"),
])
def test_a_broken_rule_is_reported_with_file_and_line(tmp_path, where, source, rule):
    root = tmp_path / "adpart"
    target = root / where
    target.parent.mkdir(parents=True)
    for d in (root, target.parent):
        (d / "__init__.py").write_text("")
    target.write_text("import numpy\n" + source)
    found = violations(root)
    assert len(found) == 1 and rule in found[0] and f"{where}:2:" in found[0]


def test_downward_imports_pass(tmp_path):
    root = tmp_path / "adpart"
    (root / "learning").mkdir(parents=True)
    (root / "__init__.py").write_text("")
    (root / "learning" / "__init__.py").write_text("from . import q\n")
    (root / "learning" / "q.py").write_text(
        "from adpart.mdp import model\nfrom adpart.errors import TaskError\n"
        "from .curves import c\n")
    assert violations(root) == []

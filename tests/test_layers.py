"""The import rules of the package layout (DESIGN.md's layers), checked on the source tree.

Every ``import`` of an ``adpart`` module is read from the syntax tree - module level, inside
functions and under ``TYPE_CHECKING`` alike - and checked against :data:`RULES`, which lists for
each top-level unit the units it may import. The rules are a strict order, without exceptions
(:func:`test_the_rules_only_run_downward`): the error tree at the bottom, ``params`` and
``plotting`` on it; the numeric cores by rank on those; the package's front door (``adpart``
itself: ``__version__`` and the lazy MDP re-exports) on ``mdp``; the executors on the
foundation alone; above the cores the store, the plugins (contracts and built-in
implementations, which also wrap the executors) and the conformance checks (which know the
plugin contracts); the workflows on the store and the plugins; the experiments on the workflows
but not the store; the CLI on everything. A new violation fails this test with the file, the
line and the rule it breaks.
"""

from __future__ import annotations

import ast
from graphlib import CycleError, TopologicalSorter
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "adpart"

FOUNDATION = {"errors", "lazy", "params", "plotting"}
#: the numeric cores by rank: a core may import cores of a lower rank only
CORE_RANK = {"mdp": 1, "envs": 2, "subgoals": 3, "partition": 3, "options": 4, "learning": 5,
             "hierarchy": 6}
CORES = set(CORE_RANK)
UPPER = {"execution", "store", "plugins", "workflows", "experiments", "testing", "cli"}
#: the package itself (``adpart/__init__.py``)
FRONT_DOOR = "__init__"
#: what everything above the cores may import
BASE = FOUNDATION | CORES | {FRONT_DOOR}

#: The units each top-level unit may import (besides itself).
RULES: dict[str, set[str]] = {
    "errors": set(),
    "lazy": set(),
    "params": {"errors"},
    "plotting": {"errors"},
    **{core: FOUNDATION | {c for c, r in CORE_RANK.items() if r < rank}
       for core, rank in CORE_RANK.items()},
    FRONT_DOOR: FOUNDATION | {"mdp"},
    "execution": FOUNDATION,  # an executor reaches a core only as a callable
    "store": BASE,  # the records it keeps, and __version__ for their provenance
    "plugins": BASE | {"execution"},  # never the workflows or the store
    "testing": BASE | {"execution", "plugins"},
    "workflows": BASE | {"execution", "store", "plugins"},
    "experiments": BASE | {"execution", "plugins", "workflows"},  # the store through workflows
    "cli": BASE | (UPPER - {"cli"}),
}
#: the units ``from adpart import x`` may name (any other ``x`` is a name of the front door)
UNITS = set(RULES) - {FRONT_DOOR}


def allowed(unit: str) -> set[str]:
    """The top-level units ``unit`` may import (besides itself)."""
    return RULES[unit]


def _module_name(path: Path, root: Path) -> list[str]:
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    return parts[:-1] if parts[-1] == "__init__" else parts


def imports(path: Path, root: Path) -> list[tuple[int, str]]:
    """``(line, absolute module)`` of every adpart import in ``path`` (relative ones resolved).

    ``from adpart import x`` imports the unit ``x`` when ``x`` names one, else a name of the
    front door (``adpart``).
    """
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
            if target == root.name:
                out += [(node.lineno, f"{target}.{a.name}" if a.name in UNITS else target)
                        for a in node.names]
            else:
                out.append((node.lineno, target))
    return [(line, t) for line, t in out if t.split(".")[0] == root.name]


def unit_of(module: list[str] | str) -> str:
    parts = module.split(".") if isinstance(module, str) else module
    return parts[1] if len(parts) > 1 else FRONT_DOOR


def violations(root: Path = PACKAGE) -> list[str]:
    """Every import in the tree under ``root`` that breaks :func:`allowed`, one line each."""
    found = []
    for path in sorted(root.rglob("*.py")):
        unit = unit_of(_module_name(path, root))
        for line, target in imports(path, root):
            dest = unit_of(target)
            if dest != unit and dest not in allowed(unit):
                found.append(f"{path.relative_to(root.parent)}:{line}: {unit} imports {target}")
    return found


def test_the_package_keeps_its_layers():
    assert violations() == []


def test_every_top_level_unit_has_a_rule():
    units = {p.stem if p.is_file() else p.name for p in PACKAGE.iterdir()
             if (p.suffix == ".py") or (p.is_dir() and (p / "__init__.py").exists())}
    assert units <= set(RULES), sorted(units - set(RULES))
    assert set(RULES) == FOUNDATION | CORES | UPPER | {FRONT_DOOR}


def test_the_rules_only_run_downward():
    """The rules order the units: no unit may import, even through others, one that may import
    it. Every rule names only known units."""
    for unit, below in RULES.items():
        assert unit not in below and below <= set(RULES), unit
    try:
        order = list(TopologicalSorter(RULES).static_order())
    except CycleError as exc:  # pragma: no cover - the message names the cycle
        pytest.fail(f"the layer rules have a cycle: {exc.args[1]}")
    assert order[0] == "errors" and order[-1] == "cli"
    # plugins sit below workflows; the store below the workflows but beside the plugins
    assert order.index("plugins") < order.index("workflows")
    assert "workflows" not in RULES["plugins"] and "store" not in RULES["plugins"]
    assert "store" not in RULES["experiments"]


@pytest.mark.parametrize(("where", "source", "rule"), [
    ("mdp/model.py", "from adpart.plugins.registry import Param\n", "mdp imports adpart.plugins"),
    ("options/models.py", "from adpart.execution import (\n    Executor,\n)\n",
     "options imports adpart.execution"),
    ("partition/x.py", "from ..learning import curves\n", "partition imports adpart.learning"),
    ("subgoals/x.py", "import adpart.partition\n", "subgoals imports adpart.partition"),
    ("workflows/x.py", "from adpart.experiments.stats import compare\n",
     "workflows imports adpart.experiments"),
    ("plugins/x.py", "from adpart.workflows.hierarchy import load_inputs\n",
     "plugins imports adpart.workflows.hierarchy"),
    ("plugins/builtin/x.py", "from adpart.store import KnowledgeBase\n",
     "plugins imports adpart.store"),
    ("plugins/x.py", "from ..workflows import hierarchy\n", "plugins imports adpart.workflows"),
    ("testing.py", "from adpart.workflows.hierarchy import build_hierarchy\n",
     "testing imports adpart.workflows.hierarchy"),
    ("experiments/x.py", "from adpart.store import KnowledgeBase\n",
     "experiments imports adpart.store"),
    ("mdp/x.py", "from adpart import __version__\n", "mdp imports adpart"),
    ("options/x.py", "from adpart import FiniteMDP\n", "options imports adpart"),
    ("envs/x.py", "from adpart import learning\n", "envs imports adpart.learning"),
    ("execution/x.py", "import adpart\n", "execution imports adpart"),
    ("errors.py", "from adpart.params import Param\n", "errors imports adpart.params"),
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


def test_imports_inside_functions_and_type_checking_count(tmp_path):
    root = tmp_path / "adpart"
    (root / "plugins").mkdir(parents=True)
    (root / "__init__.py").write_text("")
    (root / "plugins" / "__init__.py").write_text("")
    (root / "plugins" / "x.py").write_text(
        "from typing import TYPE_CHECKING\n"
        "if TYPE_CHECKING:\n    from adpart.store.kb import KnowledgeBase\n"
        "def build(inputs):\n    from adpart.workflows import hierarchy\n")
    assert violations(root) == [
        "adpart/plugins/x.py:3: plugins imports adpart.store.kb",
        "adpart/plugins/x.py:5: plugins imports adpart.workflows",
    ]


def test_the_store_and_the_cli_may_read_the_front_door(tmp_path):
    root = tmp_path / "adpart"
    for unit in ("store", "cli", "learning", "mdp"):
        (root / unit).mkdir(parents=True)
        (root / unit / "__init__.py").write_text("")
    (root / "__init__.py").write_text("def __getattr__(name):\n    from adpart.mdp import model\n")
    (root / "store" / "kb.py").write_text("from adpart import __version__\n")
    (root / "cli" / "x.py").write_text("from adpart import __version__\nfrom . import y\n")
    (root / "learning" / "x.py").write_text("from adpart import mdp\n")
    assert violations(root) == []

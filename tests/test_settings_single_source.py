"""One default and one check per setting: the settings dataclasses are their only declaration.

Every algorithm's settings are a :func:`adpart.params.settings` dataclass whose fields carry the
default, range and help. This test reads the package's syntax trees and reports every other
place that declares a default for a name one of those dataclasses owns:

* a function parameter with a literal default (``def f(delta=0.3)``; ``None``, which means "not
  given", is allowed);
* a plugin parameter spelled out (``Param("delta", "float", 0.3, ...)``);
* a command-line option with a default (``click.option("--delta", default=0.3)``).

Plugin parameters, options and provenance are derived from the dataclasses
(``settings_params``, ``settings_options``, ``settings_dict``), so none of those is needed.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "adpart"

#: Parameters that share a settings field's name but are another setting, with what they are.
#: Each entry must still match a declaration (a stale one fails the test).
OTHER_MEANINGS: dict[tuple[str, str], str] = {
    ("adpart/mdp/solvers.py", "epsilon"): "the solvers' stopping tolerance on ||V - V*||",
    ("adpart/options/subgoal_options.py", "epsilon"): "the pseudo-reward's small epsilon",
    ("adpart/experiments/sequential.py", "alpha"): "the sequential test's significance level",
    ("adpart/experiments/sequential.py", "seed"): "the permutation test's seed",
    ("adpart/experiments/stats.py", "seed"): "the bootstrap's seed",
    ("adpart/experiments/protocol.py", "seed"): "the bootstrap's seed",
    ("adpart/experiments/maxq.py", "seed"): "the bootstrap's seed",
    ("adpart/learning/comparison.py", "seed"): "the bootstrap's seed",
    ("adpart/learning/transfer_metrics.py", "seed"): "the stratified bootstrap's seed",
    ("adpart/learning/maxq/maxq_q.py", "seed"): "the Monte Carlo rollouts' seed",
    ("adpart/mdp/generate.py", "seed"): "the random MDP generator's seed",
    ("adpart/envs/gym_adapter.py", "seed"): "the Gymnasium environment's reset seed",
    ("adpart/envs/minigrid_adapter.py", "seed"): "the seed of the MiniGrid layout enumerated",
    ("adpart/cli/discover_cmd.py", "seed"): "the subgoal detector's sampling seed",
    ("adpart/workflows/discovery.py", "seed"): "the subgoal detector's sampling seed",
    ("adpart/testing.py", "seed"): "the conformance checks' fixed seed",
    ("adpart/testing.py", "runs"): "the conformance check's own two-run size",
    ("adpart/testing.py", "episodes"): "the conformance check's own three-episode size",
}


def _is_settings_class(node: ast.ClassDef) -> bool:
    return any(isinstance(d, ast.Name) and d.id == "settings" for d in node.decorator_list)


def settings_fields(root: Path = PACKAGE) -> dict[str, str]:
    """``{field name: "Class (file)"}`` of every field declared with ``setting(...)``."""
    owned: dict[str, str] = {}
    for path in sorted(root.rglob("*.py")):
        tree = ast.parse(path.read_text(), str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.ClassDef) and _is_settings_class(node):
                for item in node.body:
                    if (isinstance(item, ast.AnnAssign) and isinstance(item.target, ast.Name)
                            and isinstance(item.value, ast.Call)
                            and getattr(item.value.func, "id", "") == "setting"):
                        owned.setdefault(item.target.id,
                                         f"{node.name} ({path.relative_to(root.parent)})")
    return owned


def _instances(tree: ast.Module, classes: set[str]) -> set[str]:
    """Module-level names bound to an instance of a settings class (``X = Settings(...)``):
    such a default is checked by the class, and its values are stated at the call."""
    return {t.id for node in tree.body if isinstance(node, ast.Assign)
            and isinstance(node.value, ast.Call)
            and getattr(node.value.func, "id", None) in classes
            for t in node.targets if isinstance(t, ast.Name)}


def _literal(node: ast.expr | None, allowed: set[str]) -> bool:
    """A default that states a value (a constant other than None, or a name of a constant that
    is not a settings instance)."""
    if node is None:
        return False
    if isinstance(node, ast.Constant):
        return node.value is not None
    if isinstance(node, ast.UnaryOp) and isinstance(node.operand, ast.Constant):
        return True
    return isinstance(node, ast.Name) and node.id.isupper() and node.id not in allowed


def second_declarations(root: Path = PACKAGE,
                        other: dict[tuple[str, str], str] | None = None) -> list[str]:
    """Every default of an owned name declared outside its settings dataclass, one line each
    (but those ``other`` names as another setting), and every entry of ``other`` that matched
    nothing."""
    other = {} if other is None else other
    used: set[tuple[str, str]] = set()
    owned = settings_fields(root)
    classes = {owner.split(" ")[0] for owner in owned.values()}
    found = []
    for path in sorted(root.rglob("*.py")):
        where = path.relative_to(root.parent)
        tree = ast.parse(path.read_text(), str(path))
        allowed = _instances(tree, classes)

        def elsewhere(name: str, where: Path = where) -> bool:
            key = (where.as_posix(), name)
            if key in other:
                used.add(key)
                return True
            return False

        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                args = node.args
                positional = args.posonlyargs + args.args
                pairs = list(zip(positional[len(positional) - len(args.defaults):],
                                 args.defaults, strict=True))
                pairs += [(a, d) for a, d in zip(args.kwonlyargs, args.kw_defaults, strict=True)]
                for arg, default in pairs:
                    if (arg.arg in owned and _literal(default, allowed)
                            and not elsewhere(arg.arg)):
                        found.append(f"{where}:{node.lineno}: parameter {arg.arg} = "
                                     f"{ast.unparse(default)} (owned by {owned[arg.arg]})")
            elif isinstance(node, ast.Call):
                name = getattr(node.func, "id", None) or getattr(node.func, "attr", None)
                first = node.args[0] if node.args else None
                text = first.value if isinstance(first, ast.Constant) else None
                if not isinstance(text, str):
                    continue
                key = text.lstrip("-").replace("-", "_")
                if name == "Param" and key in owned and len(node.args) >= 3:
                    found.append(f"{where}:{node.lineno}: Param({text!r}, ..., "
                                 f"{ast.unparse(node.args[2])}) (owned by {owned[key]})")
                elif (name == "option" and text.startswith("--") and key in owned
                      and any(k.arg == "default" for k in node.keywords)
                      and not elsewhere(key)):
                    found.append(f"{where}:{node.lineno}: option {text} with a default "
                                 f"(owned by {owned[key]})")
    found += [f"{path}: no parameter {name} any more; drop it from OTHER_MEANINGS"
              for path, name in sorted(set(other) - used)]
    return found


def test_every_setting_has_one_default():
    found = second_declarations(other=OTHER_MEANINGS)
    assert not found, "\n".join(found)


def test_the_test_finds_a_second_default(tmp_path):
    root = tmp_path / "adpart"
    root.mkdir()
    (root / "core.py").write_text(
        "from adpart.params import setting, settings\n\n@settings\nclass S:\n"
        "    delta: float = setting(0.3, min=0.0)\n    '''delta of eq. 4.6.'''\n"
        "    epsilon: float = setting(0.1, min=0.0)\n    '''exploration.'''\n")
    (root / "use.py").write_text(
        "import click\nfrom adpart.params import Param\n\n"
        "def refine(p, *, delta=0.0, other=1, epsilon=1e-6):\n    pass\n\n"
        "P = Param('delta', 'float', 0.3, 'help')\n"
        "opt = click.option('--delta', default=0.3)\n")
    found = second_declarations(root, {("adpart/use.py", "other"): "unused",
                                       ("adpart/use.py", "epsilon"): "another epsilon"})
    assert len(found) == 4, found
    assert "use.py:4: parameter delta = 0.0" in found[0]
    assert "Param('delta'" in found[1] and "option --delta" in found[2]
    assert "no parameter other any more" in found[3]

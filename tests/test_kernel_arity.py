"""No numba-compiled function of the package takes more than :data:`MAX_PARAMETERS` parameters.

A kernel with dozens of positional parameters is read and called by position only: one argument
added or moved in the wrong place shifts every later one, and numba types the call without
complaint. The kernels take their arrays grouped by role in tuples instead. This test reads the
package's syntax trees (nothing is imported or compiled) and finds every function that numba
compiles: decorated with ``compiled``, ``njit``, ``jit``, ``numba.njit`` / ``numba.jit`` (called
with options or not, or a module-level name bound to such a call), or passed to
``njit_lazily(...)``.
"""

from __future__ import annotations

import ast
from pathlib import Path

import adpart

MAX_PARAMETERS = 20
PACKAGE = Path(adpart.__file__).parent

#: Names whose call or use as a decorator means numba compiles the function.
JIT_NAMES = {"compiled", "njit", "jit", "numba.njit", "numba.jit"}


def dotted(node: ast.AST) -> str | None:
    """``a.b.c`` for a name or attribute chain, else ``None``."""
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        base = dotted(node.value)
        return None if base is None else f"{base}.{node.attr}"
    return None


def is_jit(node: ast.AST, aliases: set[str]) -> bool:
    """Whether ``node`` (a decorator or a callee) is numba's jit, with or without options."""
    if isinstance(node, ast.Call):
        node = node.func
    name = dotted(node)
    return name is not None and (name in JIT_NAMES or name in aliases)


def n_parameters(fn: ast.FunctionDef) -> int:
    args = fn.args
    return (len(args.posonlyargs) + len(args.args) + len(args.kwonlyargs)
            + (args.vararg is not None) + (args.kwarg is not None))


def compiled_functions(tree: ast.Module) -> list[ast.FunctionDef]:
    """The functions of one module that numba compiles."""
    aliases = {  # jit = numba.njit(cache=True, ...)
        target.id
        for node in ast.walk(tree) if isinstance(node, ast.Assign) and is_jit(node.value, set())
        for target in node.targets if isinstance(target, ast.Name)
    }
    functions = [node for node in ast.walk(tree) if isinstance(node, ast.FunctionDef)]
    by_name = {fn.name: fn for fn in functions}
    found = {id(fn): fn for fn in functions
             if any(is_jit(d, aliases) for d in fn.decorator_list)}
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call) or not node.args:
            continue
        callee = dotted(node.func)
        lazily = callee is not None and callee.split(".")[-1] == "njit_lazily"
        if lazily or is_jit(node.func, aliases):  # njit_lazily(fn), numba.njit(...)(fn)
            arg = node.args[0]
            if isinstance(arg, ast.Name) and arg.id in by_name:
                found[id(by_name[arg.id])] = by_name[arg.id]
    return list(found.values())


def all_compiled() -> list[tuple[str, ast.FunctionDef]]:
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        tree = ast.parse(path.read_text(), filename=str(path))
        rel = path.relative_to(PACKAGE.parent)
        out.extend((f"{rel}:{fn.lineno}", fn) for fn in compiled_functions(tree))
    return out


def test_the_scan_finds_the_kernels():
    # the scan must see the kernels it guards, or the bound below checks nothing
    names = {(where.split(":")[0], fn.name) for where, fn in all_compiled()}
    for expected in [("adpart/learning/_smdp_kernels.py", "lockstep"),
                     ("adpart/learning/_kernels.py", "lockstep"),
                     ("adpart/learning/_rmax.py", "sweep"),
                     ("adpart/mdp/_sampling.py", "successor"),
                     ("adpart/mdp/_kernels.py", "bellman_backup"),
                     ("adpart/partition/_kernels.py", "delta_worklist"),
                     ("adpart/subgoals/_walkers.py", "expected_arrivals")]:
        assert expected in names


def test_no_compiled_function_takes_more_than_twenty_parameters():
    offenders = [f"{where} {fn.name}: {n_parameters(fn)} parameters"
                 for where, fn in all_compiled() if n_parameters(fn) > MAX_PARAMETERS]
    assert not offenders, (
        f"numba-compiled functions with more than {MAX_PARAMETERS} parameters (group the "
        "arguments by role in tuples):\n" + "\n".join(offenders))


def test_the_learners_take_their_model_inputs_settings_and_run_only():
    """Issue 35's bound: the learners take the task, their model inputs, one settings object
    and the run settings. ``hierarchical_learning(mdp, options, partition, settings, run,
    models, belief)`` has seven: its inputs are the options, the layer, their exact models
    (for scoring) and the model it may read in the learned-model regime (issue 37); the others
    take at most six."""
    import inspect

    from adpart.learning.hierarchical import hierarchical_learning
    from adpart.learning.maxq.maxq_q import maxq_q
    from adpart.learning.model_based import known_dynamics_learning
    from adpart.learning.qlearning import q_learning
    from adpart.learning.smdp_q import smdp_q_learning

    for learner in (smdp_q_learning, q_learning, maxq_q, known_dynamics_learning):
        assert len(inspect.signature(learner).parameters) <= 6, learner.__name__
    assert list(inspect.signature(hierarchical_learning).parameters) == [
        "mdp", "options", "partition", "settings", "run", "models", "belief"]

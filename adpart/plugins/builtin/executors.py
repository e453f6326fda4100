"""Built-in executors: ``serial`` (in-process), ``local`` (a process pool) and ``ray``.

Registering ``ray`` imports only :mod:`adpart.execution.ray`, which imports Ray lazily, so it is
listed by ``adpart plugins`` whether or not Ray is installed; using it without Ray raises an error
naming ``pip install 'adpart[ray]'``.
"""

from __future__ import annotations

from adpart.plugins.hookspecs import hookimpl
from adpart.plugins.registry import Registrar


@hookimpl
def register_executors(register: Registrar) -> None:
    # imported here: a command's --help reads the registry of another kind, not these
    from adpart.execution import LocalExecutor, SerialExecutor
    from adpart.execution.ray import RayExecutor

    register(LocalExecutor)
    register(SerialExecutor)
    register(RayExecutor)

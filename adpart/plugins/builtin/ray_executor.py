"""Built-in ``ray`` executor (extra ``adpart[ray]``), registered through its own entry point.

Registering imports only :mod:`adpart.execution_ray`, which imports Ray lazily, so ``ray`` is
listed by ``adpart plugins`` whether or not Ray is installed; using it without Ray raises an
error naming ``pip install 'adpart[ray]'``.
"""

from __future__ import annotations

from adpart.execution_ray import RayExecutor
from adpart.plugins.hookspecs import hookimpl
from adpart.plugins.registry import Registrar


@hookimpl
def register_executors(register: Registrar) -> None:
    register(RayExecutor)

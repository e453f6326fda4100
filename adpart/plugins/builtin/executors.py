"""Built-in executors: ``serial`` (in-process) and ``local`` (a process pool)."""

from __future__ import annotations

from adpart.execution import LocalExecutor, SerialExecutor
from adpart.plugins.hookspecs import hookimpl
from adpart.plugins.registry import Registrar


@hookimpl
def register_executors(register: Registrar) -> None:
    register(LocalExecutor)
    register(SerialExecutor)

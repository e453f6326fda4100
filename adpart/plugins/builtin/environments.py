"""Built-in environments: the domains of the dissertation and the classic benchmarks."""

from __future__ import annotations

from adpart.plugins.hookspecs import hookimpl
from adpart.plugins.registry import Registrar


@hookimpl
def register_environments(register: Registrar) -> None:
    from adpart.envs.registry import BUILTIN_DOMAINS, load_class  # numpy, scipy: only when used

    for name, target in BUILTIN_DOMAINS.items():
        register(load_class(target), name=name)

"""adpart: state and action hierarchies for RL by action-dependent partitioning.

``adpart.FiniteMDP`` and ``adpart.SMDPModel`` are loaded on first use, so that importing the
package (``adpart --version``, ``adpart --help``) does not load numpy.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version
from typing import Any

try:
    __version__ = version("adpart")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0+unknown"

__all__ = ["FiniteMDP", "SMDPModel", "__version__"]


def __getattr__(name: str) -> Any:
    if name in {"FiniteMDP", "SMDPModel"}:
        from adpart.mdp import model

        return getattr(model, name)
    raise AttributeError(f"module 'adpart' has no attribute {name!r}")

"""adpart: state and action hierarchies for RL by action-dependent partitioning."""

from importlib.metadata import PackageNotFoundError, version

from adpart.mdp.model import FiniteMDP, SMDPModel

try:
    __version__ = version("adpart")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0+unknown"

__all__ = ["FiniteMDP", "SMDPModel", "__version__"]

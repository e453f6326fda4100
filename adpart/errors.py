"""The adpart error tree.

Every error a user can cause derives from :class:`AdpartError`, so callers (the CLI above all)
can turn exactly these into one-line messages and let genuine bugs surface as tracebacks.
"""

from __future__ import annotations


class AdpartError(Exception):
    """Base class of every error adpart raises on purpose."""


class ModelError(AdpartError, ValueError):
    """A finite MDP or SMDP model violates its contract (shapes, probabilities, rewards)."""


class MapError(AdpartError, ValueError):
    """A grid map is malformed: unknown character, no free cell, unreachable goal, ragged rows."""


class TaskError(AdpartError, ValueError):
    """A task specification does not fit its environment."""


class UnknownNameError(AdpartError, KeyError):
    """A name (environment, task, plugin) is not known; the message suggests the closest one."""

    def __str__(self) -> str:  # KeyError quotes its argument; we want the plain message
        return str(self.args[0]) if self.args else ""


class PluginError(AdpartError, ValueError):
    """An implementation or its parameters are invalid."""


class PluginFailure(PluginError):
    """A third-party plugin's own code raised an exception adpart did not expect (a bug of that
    plugin, not of adpart or of the user's input).

    The message names the plugin, its kind, its package and version, the method and the
    exception, in one line; the original exception is the ``__cause__`` (``adpart --debug``
    prints its traceback). Raised by the guard :meth:`adpart.plugins.PluginSpec.create` puts
    around a third-party plugin's constructor and contract methods.
    """

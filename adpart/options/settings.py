"""Where an option to a subgoal may start: the settings of :mod:`adpart.options.subgoal_options`.

Kept apart from the option code (numpy, scipy) so that the command line builds its options
(``--initiation``, ``--radius``) without importing it.
"""

from __future__ import annotations

from adpart.params import setting, settings

__all__ = ["INITIATION_CHOICES", "InitiationSettings"]

#: Where an option to a subgoal may start (:class:`InitiationSettings`' ``initiation``).
INITIATION_CHOICES = ("local", "basin", "reachable")


@settings
class InitiationSettings:
    """Where an option to a subgoal may start (:mod:`adpart.options.subgoal_options`;
    docs/options.md)."""

    initiation: str = setting("local", choices=INITIATION_CHOICES)
    """where an option to a subgoal may start: its basin within --radius steps (local), its
    basin (basin), or wherever the subgoal is reachable (reachable)."""

    radius: float = setting(30.0, min=1.0, finite=False)
    """steps of a local initiation set (>= 1; inf is the basin)."""
